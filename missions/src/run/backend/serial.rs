//! The real instruments on serial ports (`[backend] kind = "serial"`), or
//! their emulators: GeoCOM total station, NMEA tilt sensor, SICK LMS-2xx,
//! the scan head and the drives over the robot link.

use std::time::Duration;

use anyhow::{Result, bail};
use planner::Dance;
use scanner::PlanarPose;
use scanner::serial::Port;
use scanner::serial::geocom::{GeoCom, GeoComConfig};
use scanner::serial::nmea::NmeaTilt;
use scanner::serial::robot::{RobotLink, SerialDrive, SerialHead};
use scanner::serial::sick::{Lms, LmsSettings};

use super::faults::Faults;
use super::team::{Devices, Kept, Team, TeamDrive};
use crate::mission::{Mission, SerialPorts};

/// Opens every port of `ports` and sets the instruments up (the LMS rate
/// and configuration, the GeoCOM link); the drives are told where `dance`
/// starts.
pub fn team(mission: &Mission, dance: &Dance, ports: &SerialPorts) -> Result<Team> {
    let resolution_cdeg = match mission.scan.resolution {
        scanner::sim::LmsResolution::One => 100,
        scanner::sim::LmsResolution::Half => 50,
        scanner::sim::LmsResolution::Quarter => {
            bail!("[scan] resolution_deg = 0.25: the LMS-2xx scans 180° at 1° or 0.5° only; choose 1 or 0.5")
        }
    };
    let total_station = match &ports.total_station {
        Some(path) => {
            let config = GeoComConfig {
                reply_timeout: Duration::from_secs_f64(ports.total_station_timeout_s),
                ..GeoComConfig::default()
            };
            Some(GeoCom::open(path, ports.total_station_baud, config)?)
        }
        None => None,
    };
    let period = Duration::from_secs_f64(1.0 / ports.tilt_rate_hz);
    let tilt = NmeaTilt::open(&ports.tilt, ports.tilt_baud, period)?;
    let settings = LmsSettings {
        baud: ports.scanner_baud,
        resolution_cdeg,
        continuous: ports.scanner_continuous,
        ..LmsSettings::default()
    };
    let lms = Lms::open(&ports.scanner, settings)?;
    let link = |kind: &str, path: &str, timeout_s: f64| -> Result<RobotLink> {
        let port = Port::open(kind, path, ports.robot_baud)?;
        Ok(RobotLink::new(port, Duration::from_secs_f64(timeout_s), 3))
    };
    let head = SerialHead::new(link("scan head", &ports.head, 30.0)?, mission.scan.head);
    let mut drives: Vec<Box<dyn TeamDrive>> = Vec::with_capacity(ports.drives.len());
    for (k, path) in ports.drives.iter().enumerate() {
        let kind = if k == 0 { "parent drive".to_string() } else { format!("drive of {}", mission.children[k - 1]) };
        drives.push(Box::new(SerialDrive::new(link(&kind, path, ports.move_timeout_s)?)));
    }
    let start = PlanarPose::from(&dance.station_pose(0));
    // The parent learns where the dance starts (its own heading too).
    if let Some(parent) = drives.first_mut() {
        parent.relocalise(&start, false)?;
    }
    let devices = Devices {
        total_station: total_station.map(|t| Box::new(t) as _),
        tilt: Box::new(tilt),
        range_finder: Box::new(lms),
        head: Box::new(head),
        drives,
        body_from_head: mission.scan.body_from_head(),
    };
    Ok(Team::new(devices, mission.scene().clone(), start, None, Faults::default()))
}

impl Kept for GeoCom {}
impl Kept for NmeaTilt {}
impl Kept for Lms {}
impl Kept for SerialDrive {}

impl TeamDrive for SerialDrive {
    fn relocalise(&mut self, pose: &PlanarPose, keep_heading: bool) -> scanner::Result<()> {
        SerialDrive::relocalise(self, pose, keep_heading)
    }
}
