//! The team a mission runs on ([`Team`]): the simulated one ([`SimTeam`]:
//! one [`SimWorld`] and every device in it, with checkpoints, so a journaled
//! run resumes bit for bit, and injected faults, so retries and clean stops
//! can be exercised), or the real instruments over serial ports
//! ([`SerialTeam`], `[backend] kind = "serial"`).

use std::str::FromStr;

use std::time::Duration;

use anyhow::{Context, Result, bail};
use cps::ParentPose;
use nalgebra::{Isometry3, Point3};
use planner::Dance;
use scanner::sim::{
    LmsConfig, LmsRangeMode, NoiseStream, Robot, SimDrive, SimHead, SimLms, SimTilt, SimTotalStation, SimWorld, Truth,
};
use scanner::{
    Drive, Odometry, PlanarPose, Scan, ScannerError, Target, Tilt, TiltSensor, TotalStation, TsMeasurement, scan_3d,
};

use scanner::serial::Port;
use scanner::serial::geocom::{GeoCom, GeoComConfig};
use scanner::serial::nmea::NmeaTilt;
use scanner::serial::robot::{RobotLink, SerialDrive, SerialHead};
use scanner::serial::sick::{Lms, LmsSettings};

use crate::mission::{Mission, SerialPorts};
use crate::run::journal::{Checkpoint, DriveState, NoiseState, TruthRecord};

/// A device of the team, as named in faults and retry messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceKind {
    /// Any robot's drive.
    Drive,
    /// The parent's total station.
    TotalStation,
    /// The tilt sensor.
    Tilt,
    /// The laser scanner (one whole 3D scan is one command).
    Scanner,
}

impl DeviceKind {
    /// The name used on the command line and in the journal.
    pub fn name(self) -> &'static str {
        match self {
            DeviceKind::Drive => "drive",
            DeviceKind::TotalStation => "total-station",
            DeviceKind::Tilt => "tilt",
            DeviceKind::Scanner => "scanner",
        }
    }
}

/// A fault injected into a simulated device (`--sim-fault`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    /// The device.
    pub device: DeviceKind,
    /// When it fails.
    pub rule: FaultRule,
}

/// When an injected fault strikes, counting the device's commands from 1
/// (each retry is a command) — or, for a blunder, the total station's
/// measurements from 1 (children and control alike).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultRule {
    /// Every command after the n-th fails: the device stopped answering.
    After(usize),
    /// Every k-th command fails once (a retry then succeeds).
    Every(usize),
    /// The n-th distance measured is off by this many metres.
    Blunder(usize, f64),
    /// The n-th horizontal angle measured is off by this many radians.
    BlunderAngle(usize, f64),
}

impl FromStr for Fault {
    type Err = String;

    /// `DEVICE:after=N` or `DEVICE:every=K`, DEVICE one of `drive`,
    /// `total-station`, `tilt`, `scanner`; `total-station:blunder=N:D`
    /// (metres) or `total-station:blunder-angle=N:ARCSEC`.
    fn from_str(s: &str) -> Result<Self, String> {
        let expected = "expected DEVICE:after=N or DEVICE:every=K with DEVICE drive, total-station, tilt or scanner, \
                        or total-station:blunder=N:METRES or total-station:blunder-angle=N:ARCSEC";
        let (device, rule) = s.split_once(':').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
        let device = [DeviceKind::Drive, DeviceKind::TotalStation, DeviceKind::Tilt, DeviceKind::Scanner]
            .into_iter()
            .find(|d| d.name() == device)
            .ok_or_else(|| format!("fault \"{s}\": unknown device \"{device}\"; {expected}"))?;
        let (kind, n) = rule.split_once('=').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
        if let Some(blunder) = ["blunder", "blunder-angle"].into_iter().find(|b| *b == kind) {
            if device != DeviceKind::TotalStation {
                return Err(format!("fault \"{s}\": blunders are the total station's; {expected}"));
            }
            let (n, d) = n.split_once(':').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
            let n: usize = n
                .parse()
                .ok()
                .filter(|n| *n >= 1)
                .ok_or_else(|| format!("fault \"{s}\": \"{n}\" is not a measurement number ≥ 1; {expected}"))?;
            let d: f64 = d
                .parse()
                .ok()
                .filter(|d: &f64| d.is_finite() && d.abs() < 1e6)
                .ok_or_else(|| format!("fault \"{s}\": \"{d}\" is not a finite size below 1e6; {expected}"))?;
            let rule = if blunder == "blunder" {
                FaultRule::Blunder(n, d)
            } else {
                FaultRule::BlunderAngle(n, d * cps::RAD_PER_ARCSEC)
            };
            return Ok(Fault { device, rule });
        }
        let n: usize = n.parse().map_err(|_| format!("fault \"{s}\": \"{n}\" is not a whole number; {expected}"))?;
        let rule = match (kind, n) {
            ("after", n) => FaultRule::After(n),
            ("every", k) if k >= 2 => FaultRule::Every(k),
            ("every", _) => return Err(format!("fault \"{s}\": every=K needs K ≥ 2 (K = 1 is after=0)")),
            _ => return Err(format!("fault \"{s}\": unknown rule \"{kind}\"; {expected}")),
        };
        Ok(Fault { device, rule })
    }
}

/// The simulated team: the world and every device in it.
#[derive(Debug)]
pub struct SimTeam {
    world: SimWorld,
    parent: SimDrive,
    children: Vec<SimDrive>,
    total_station: Option<SimTotalStation>,
    tilt: SimTilt,
    lms: SimLms,
    head: SimHead,
    body_from_head: Isometry3<f64>,
    faults: Vec<Fault>,
    commands: [usize; 4],
    /// The total station's measurements so far (blunders count them).
    measurements: usize,
}

/// The simulated team taken apart ([`SimTeam::into_parts`]).
#[derive(Debug)]
pub struct SimParts {
    /// The shared world.
    pub world: SimWorld,
    /// The parent's drive.
    pub parent: SimDrive,
    /// The children's drives.
    pub children: Vec<SimDrive>,
    /// The tilt sensor.
    pub tilt: SimTilt,
    /// The laser scanner.
    pub lms: SimLms,
    /// The scan head.
    pub head: SimHead,
}

impl SimTeam {
    /// The team standing where `dance` starts: the parent truly at station
    /// 0, the children at their first formation points.
    pub fn new(mission: &Mission, dance: &Dance, faults: Vec<Fault>) -> Result<Self> {
        let seed = mission.backend.seed;
        let start = dance.station_pose(0);
        let first = dance.cycles.first().map(|c| c.children.clone()).unwrap_or_default();
        let world = SimWorld::new(mission.scene().clone(), start, first.clone());
        let centring = mission.total_station.as_ref().map_or(0.0, |i| i.centring_target_m);
        let given: Vec<(Point3<f64>, nalgebra::Matrix3<f64>)> =
            mission.control.iter().map(|c| (c.position_m, c.covariance)).collect();
        world.set_control(scanner::sim::control_prisms(&given, centring, seed));
        let odometry = mission.backend.odometry;
        let parent = SimDrive::new(world.clone(), Robot::Parent, PlanarPose::from(&start), odometry, seed)?;
        let children = first
            .iter()
            .enumerate()
            .map(|(j, p)| {
                let at = PlanarPose { x_m: p.x, y_m: p.y, heading_rad: 0.0 };
                SimDrive::new(world.clone(), Robot::Child(j), at, odometry, seed)
            })
            .collect::<scanner::Result<Vec<_>>>()?;
        let body_from_head = mission.scan.body_from_head();
        let lms_config =
            LmsConfig { resolution: mission.scan.resolution, mode: LmsRangeMode::Mm32, sigma_range_m: 0.005 };
        Ok(Self {
            total_station: mission.total_station.clone().map(|i| SimTotalStation::new(world.clone(), i, seed)),
            tilt: SimTilt::new(world.clone(), scanner::sim::TILT_SIGMA_RAD, seed),
            lms: SimLms::new(world.clone(), lms_config, mission.scan.head, body_from_head, seed),
            head: SimHead::new(world.clone(), mission.scan.head),
            world,
            parent,
            children,
            body_from_head,
            faults,
            commands: [0; 4],
            measurements: 0,
        })
    }

    /// The world and the devices, for emulators that serve them on ports.
    pub fn into_parts(self) -> SimParts {
        SimParts {
            world: self.world,
            parent: self.parent,
            children: self.children,
            tilt: self.tilt,
            lms: self.lms,
            head: self.head,
        }
    }

    /// The true state of the team.
    pub fn truth(&self) -> Truth {
        self.world.truth()
    }

    /// The parent learns its pose from a CPS fix: its next drive starts from
    /// there (the robot navigates by its estimate, so the odometry error
    /// does not pile up over the mission).
    pub fn relocalise_parent(&mut self, pose: &ParentPose) {
        self.parent.relocalise(PlanarPose::from(pose), true);
    }

    /// A child learns its position from its placement measurement (and its
    /// heading from the total station's tracking).
    pub fn relocalise_child(&mut self, j: usize, at: &nalgebra::Point3<f64>) {
        if let Some(c) = self.children.get_mut(j) {
            c.relocalise(PlanarPose { x_m: at.x, y_m: at.y, heading_rad: 0.0 }, false);
        }
    }

    /// Where the parent's drive believes it stands (its odometry).
    pub fn parent_believed(&self) -> PlanarPose {
        self.parent.believed_pose()
    }

    /// The scene the team stands in.
    pub fn scene(&self) -> &cps::geom::Scene {
        self.world.scene()
    }

    /// The scan head's mount on the body.
    pub fn body_from_head(&self) -> Isometry3<f64> {
        self.body_from_head
    }

    /// Counts a command to `device` and fails it when an injected fault says so.
    fn command(&mut self, device: DeviceKind, name: &str) -> scanner::Result<()> {
        let n = &mut self.commands[device as usize];
        *n += 1;
        let strikes = self.faults.iter().any(|f| {
            f.device == device
                && match f.rule {
                    FaultRule::After(k) => *n > k,
                    FaultRule::Every(k) => n.is_multiple_of(k),
                    FaultRule::Blunder(..) | FaultRule::BlunderAngle(..) => false,
                }
        });
        if strikes {
            return Err(ScannerError::Device {
                device: name.to_string(),
                message: format!("no answer to command {n} (injected fault)"),
            });
        }
        Ok(())
    }

    /// Drives `robot` to `goal`.
    pub fn drive(&mut self, robot: Robot, goal: &PlanarPose) -> scanner::Result<Odometry> {
        let team = self.children.len();
        let name = match robot {
            Robot::Parent => self.parent.name().to_string(),
            Robot::Child(j) => {
                self.children.get(j).ok_or(cps::CpsError::UnknownChild { child: j, team })?.name().to_string()
            }
        };
        self.command(DeviceKind::Drive, &name)?;
        match robot {
            Robot::Parent => self.parent.move_to(goal),
            Robot::Child(j) => self.children[j].move_to(goal),
        }
    }

    /// Measures a prism with the total station; a planted blunder
    /// (`--sim-fault total-station:blunder…`) strikes its measurement.
    pub fn measure(&mut self, target: &Target) -> scanner::Result<TsMeasurement> {
        self.command(DeviceKind::TotalStation, "simulated total station")?;
        let mut m = match &mut self.total_station {
            Some(ts) => ts.measure(target)?,
            None => {
                return Err(ScannerError::Device {
                    device: "total station".into(),
                    message: "the team has no total station (no children)".into(),
                });
            }
        };
        self.measurements += 1;
        for f in &self.faults {
            match f.rule {
                FaultRule::Blunder(n, d) if n == self.measurements => m.slope_raw_m += d,
                FaultRule::BlunderAngle(n, a) if n == self.measurements => {
                    m.hz_rad = (m.hz_rad + a).rem_euclid(std::f64::consts::TAU);
                }
                _ => {}
            }
        }
        Ok(m)
    }

    /// Reads the tilt sensor.
    pub fn tilt(&mut self) -> scanner::Result<Tilt> {
        self.command(DeviceKind::Tilt, "simulated tilt sensor")?;
        self.tilt.read()
    }

    /// Takes a 3D scan of `slices` slices, reporting progress per slice.
    pub fn scan(&mut self, slices: usize, progress: &mut dyn FnMut(usize, usize)) -> scanner::Result<Scan> {
        self.command(DeviceKind::Scanner, "simulated LMS-2xx")?;
        scan_3d(&mut self.head, &mut self.lms, slices, &self.body_from_head, progress)
    }

    /// The whole simulated state: the truth, each drive's believed and true
    /// pose, and every device's noise position.
    pub fn checkpoint(&self) -> Checkpoint {
        let pose = |q: PlanarPose| [q.x_m, q.y_m, q.heading_rad];
        let drives = std::iter::once(&self.parent)
            .chain(&self.children)
            .map(|d| DriveState {
                believed: pose(d.believed_pose()),
                truth: Some(pose(d.true_pose())),
                noise: Some(d.noise_position().to_string()),
            })
            .collect();
        Checkpoint {
            drives,
            noise: Some(NoiseState {
                total_station: self.total_station.as_ref().map(|t| t.noise_position().to_string()),
                tilt: self.tilt.noise_position().to_string(),
                scanner: self.lms.noise_position().to_string(),
                measurements: Some(self.measurements),
            }),
            truth: Some(truth_record(&self.world.truth())),
        }
    }

    /// Puts the world and every device back into a [`SimTeam::checkpoint`].
    pub fn restore(&mut self, c: &Checkpoint) -> Result<()> {
        let t = c.truth.as_ref().context("checkpoint without the simulator's truth")?;
        if t.children.len() != self.children.len() {
            bail!("checkpoint truth.children: {} positions for {} children", t.children.len(), self.children.len());
        }
        let p = t.parent;
        self.world.set_truth(Truth {
            // The control prisms never move.
            control: self.world.truth().control,
            parent: ParentPose::new(p[0], p[1], p[2], p[3]),
            tilt: Tilt { roll_rad: t.tilt[0], pitch_rad: t.tilt[1] },
            children: t.children.iter().map(|x| Point3::new(x[0], x[1], x[2])).collect(),
            head_angle_rad: t.head_rad,
        });
        if c.drives.len() != 1 + self.children.len() {
            bail!("checkpoint drives: {} states for {} robots", c.drives.len(), 1 + self.children.len());
        }
        let pose = |q: [f64; 3]| PlanarPose { x_m: q[0], y_m: q[1], heading_rad: q[2] };
        for (d, saved) in std::iter::once(&mut self.parent).chain(&mut self.children).zip(&c.drives) {
            let truth = saved.truth.context("checkpoint drives: a drive without its true pose")?;
            d.restore(pose(saved.believed), pose(truth));
            d.set_noise_position(noise_position(saved.noise.as_deref(), "drives.noise")?);
        }
        let n = c.noise.as_ref().context("checkpoint without the noise streams")?;
        if let Some(ts) = &mut self.total_station {
            ts.set_noise_position(noise_position(n.total_station.as_deref(), "noise.total_station")?);
        }
        self.tilt.set_noise_position(noise_position(Some(&n.tilt), "noise.tilt")?);
        // Journals of version 1 did not count; they knew no blunders.
        self.measurements = n.measurements.unwrap_or(0);
        self.lms.set_noise_position(noise_position(Some(&n.scanner), "noise.scanner")?);
        Ok(())
    }
}

/// The devices a mission commands.
#[derive(Debug)]
pub enum Team {
    /// The simulator.
    Sim(Box<SimTeam>),
    /// Real instruments (or their emulators) over serial ports.
    Serial(Box<SerialTeam>),
}

impl Team {
    /// The mission's backend, standing where `dance` starts; `faults` are
    /// for the simulator only.
    pub fn new(mission: &Mission, dance: &Dance, faults: Vec<Fault>) -> Result<Self> {
        match &mission.backend.serial {
            None => Ok(Team::Sim(Box::new(SimTeam::new(mission, dance, faults)?))),
            Some(_) if !faults.is_empty() => {
                bail!("--sim-fault injects faults into the simulator; this mission runs on serial ports")
            }
            Some(ports) => Ok(Team::Serial(Box::new(SerialTeam::connect(mission, dance, ports)?))),
        }
    }

    /// The true state of the team (simulator only).
    pub fn truth(&self) -> Option<Truth> {
        match self {
            Team::Sim(t) => Some(t.truth()),
            Team::Serial(_) => None,
        }
    }

    /// The parent learns its pose from a CPS fix.
    pub fn relocalise_parent(&mut self, pose: &ParentPose) -> Result<()> {
        match self {
            Team::Sim(t) => t.relocalise_parent(pose),
            Team::Serial(t) => t.relocalise(0, PlanarPose::from(pose), true)?,
        }
        Ok(())
    }

    /// Child `j` learns its position from its placement measurement.
    pub fn relocalise_child(&mut self, j: usize, at: &Point3<f64>) -> Result<()> {
        match self {
            Team::Sim(t) => t.relocalise_child(j, at),
            Team::Serial(t) => t.relocalise(1 + j, PlanarPose { x_m: at.x, y_m: at.y, heading_rad: 0.0 }, false)?,
        }
        Ok(())
    }

    /// Where the parent's drive believes it stands (its odometry).
    pub fn parent_believed(&self) -> PlanarPose {
        match self {
            Team::Sim(t) => t.parent_believed(),
            Team::Serial(t) => t.parent_believed,
        }
    }

    /// The scene (the site model the plan was checked against).
    pub fn scene(&self) -> &cps::geom::Scene {
        match self {
            Team::Sim(t) => t.scene(),
            Team::Serial(t) => &t.scene,
        }
    }

    /// Drives `robot` to `goal`.
    pub fn drive(&mut self, robot: Robot, goal: &PlanarPose) -> scanner::Result<Odometry> {
        match self {
            Team::Sim(t) => t.drive(robot, goal),
            Team::Serial(t) => t.drive(robot, goal),
        }
    }

    /// Measures a child with the total station.
    pub fn measure(&mut self, target: &Target) -> scanner::Result<TsMeasurement> {
        match self {
            Team::Sim(t) => t.measure(target),
            Team::Serial(t) => match &mut t.total_station {
                Some(ts) => ts.measure(target),
                None => Err(ScannerError::Device {
                    device: "total station".into(),
                    message: "the team has no total station (no children)".into(),
                }),
            },
        }
    }

    /// Reads the tilt sensor.
    pub fn tilt(&mut self) -> scanner::Result<Tilt> {
        match self {
            Team::Sim(t) => t.tilt(),
            Team::Serial(t) => t.tilt.read(),
        }
    }

    /// Takes a 3D scan of `slices` slices, reporting progress per slice.
    pub fn scan(&mut self, slices: usize, progress: &mut dyn FnMut(usize, usize)) -> scanner::Result<Scan> {
        match self {
            Team::Sim(t) => t.scan(slices, progress),
            Team::Serial(t) => scan_3d(&mut t.head, &mut t.lms, slices, &t.body_from_head, progress),
        }
    }

    /// The team's state for the journal: the simulator's whole state, or on
    /// serial ports the parent's odometry (`drives[0].believed`, as in the
    /// simulator's checkpoint).
    pub fn checkpoint(&self) -> Checkpoint {
        match self {
            Team::Sim(t) => t.checkpoint(),
            Team::Serial(t) => {
                let b = t.parent_believed;
                Checkpoint {
                    drives: vec![DriveState { believed: [b.x_m, b.y_m, b.heading_rad], truth: None, noise: None }],
                    noise: None,
                    truth: None,
                }
            }
        }
    }

    /// Puts the team back into a checkpoint: the simulator, or on serial
    /// ports the parent's odometry (the robots are where the replayed
    /// journal left them).
    pub fn restore(&mut self, c: &Checkpoint) -> Result<()> {
        match self {
            Team::Sim(t) => t.restore(c),
            Team::Serial(t) => {
                t.parent_believed =
                    c.parent_believed().context("checkpoint: expected drives[0].believed = [x, y, heading]")?;
                Ok(())
            }
        }
    }
}

/// The real instruments on their serial ports.
#[derive(Debug)]
pub struct SerialTeam {
    scene: std::sync::Arc<cps::geom::Scene>,
    total_station: Option<GeoCom>,
    tilt: NmeaTilt,
    lms: Lms,
    head: SerialHead,
    /// The parent's drive first, then the children's.
    drives: Vec<SerialDrive>,
    body_from_head: Isometry3<f64>,
    parent_believed: PlanarPose,
}

impl SerialTeam {
    /// Opens every port of `ports` and sets the instruments up (the LMS
    /// rate and configuration, the GeoCOM link); the drives are told where
    /// the dance starts.
    pub fn connect(mission: &Mission, dance: &Dance, ports: &SerialPorts) -> Result<Self> {
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
        let mut drives = Vec::with_capacity(ports.drives.len());
        for (k, path) in ports.drives.iter().enumerate() {
            let kind =
                if k == 0 { "parent drive".to_string() } else { format!("drive of {}", mission.children[k - 1]) };
            drives.push(SerialDrive::new(link(&kind, path, ports.move_timeout_s)?));
        }
        let start = PlanarPose::from(&dance.station_pose(0));
        let mut team = Self {
            scene: mission.scene().clone(),
            total_station,
            tilt,
            lms,
            head,
            drives,
            body_from_head: mission.scan.body_from_head(),
            parent_believed: start,
        };
        team.relocalise(0, start, false)?;
        Ok(team)
    }

    fn relocalise(&mut self, k: usize, pose: PlanarPose, keep_heading: bool) -> scanner::Result<()> {
        if k == 0 {
            self.parent_believed = pose;
        }
        match self.drives.get_mut(k) {
            Some(d) => d.relocalise(&pose, keep_heading),
            None => Ok(()),
        }
    }

    fn drive(&mut self, robot: Robot, goal: &PlanarPose) -> scanner::Result<Odometry> {
        let k = match robot {
            Robot::Parent => 0,
            Robot::Child(j) => 1 + j,
        };
        let team = self.drives.len() - 1;
        let drive = self.drives.get_mut(k).ok_or(cps::CpsError::UnknownChild { child: k.saturating_sub(1), team })?;
        let odometry = drive.move_to(goal)?;
        if k == 0 {
            self.parent_believed = odometry.pose;
        }
        Ok(odometry)
    }
}

/// The team's truth as journaled (`parent` [x, y, z, heading], `tilt`
/// [roll, pitch], `children` [[x, y, z]…], `head_rad`): in checkpoints and
/// the emulator's truth log.
pub fn truth_record(t: &Truth) -> TruthRecord {
    let p = &t.parent;
    TruthRecord {
        parent: [p.position.x, p.position.y, p.position.z, p.heading_rad],
        tilt: [t.tilt.roll_rad, t.tilt.pitch_rad],
        children: t.children.iter().map(|c| [c.x, c.y, c.z]).collect(),
        head_rad: t.head_angle_rad,
    }
}

/// A noise position from its decimal string.
fn noise_position(v: Option<&str>, what: &str) -> Result<u128> {
    v.and_then(|s| s.parse().ok())
        .with_context(|| format!("checkpoint {what} = {v:?}: expected a decimal noise position"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_parse_and_reject_nonsense() {
        assert_eq!(
            "total-station:after=12".parse::<Fault>(),
            Ok(Fault { device: DeviceKind::TotalStation, rule: FaultRule::After(12) })
        );
        assert_eq!(
            "scanner:every=2".parse::<Fault>(),
            Ok(Fault { device: DeviceKind::Scanner, rule: FaultRule::Every(2) })
        );
        for bad in ["laser:after=1", "tilt", "tilt:every=1", "drive:after=x", "drive:sometimes=3"] {
            let e = bad.parse::<Fault>().expect_err(bad);
            assert!(e.contains(bad), "{e}");
        }
    }
}
