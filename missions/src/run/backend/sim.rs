//! The simulated backend: one [`SimWorld`] and every device in it, seeded,
//! with checkpoints (a journaled run resumes bit for bit) and injected
//! faults (retries and clean stops can be exercised).

use anyhow::Result;
use nalgebra::{Isometry3, Point3};
use planner::Dance;
use scanner::PlanarPose;
use scanner::sim::{
    LmsConfig, LmsRangeMode, NoiseStream, Robot, SimDrive, SimHead, SimLms, SimTilt, SimTotalStation, SimWorld,
};

use super::faults::{Fault, Faults};
use super::team::{Devices, Kept, Team, TeamDrive};
use crate::mission::Mission;

/// The simulated world and its devices, apart: for the team, and for the
/// emulators that serve them on ports.
#[derive(Debug)]
pub struct SimParts {
    /// The shared world.
    pub world: SimWorld,
    /// The parent's drive.
    pub parent: SimDrive,
    /// The children's drives.
    pub children: Vec<SimDrive>,
    /// The total station (none without children).
    pub total_station: Option<SimTotalStation>,
    /// The tilt sensor.
    pub tilt: SimTilt,
    /// The laser scanner.
    pub lms: SimLms,
    /// The scan head.
    pub head: SimHead,
    /// The scan head's mount on the body.
    pub body_from_head: Isometry3<f64>,
}

/// The world standing where `dance` starts — the parent truly at station
/// 0, the children at their first formation points — and its devices.
pub fn parts(mission: &Mission, dance: &Dance) -> Result<SimParts> {
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
    let lms_config = LmsConfig { resolution: mission.scan.resolution, mode: LmsRangeMode::Mm32, sigma_range_m: 0.005 };
    Ok(SimParts {
        total_station: mission.total_station.clone().map(|i| SimTotalStation::new(world.clone(), i, seed)),
        tilt: SimTilt::new(world.clone(), scanner::sim::TILT_SIGMA_RAD, seed),
        lms: SimLms::new(world.clone(), lms_config, mission.scan.head, body_from_head, seed),
        head: SimHead::new(world.clone(), mission.scan.head),
        world,
        parent,
        children,
        body_from_head,
    })
}

/// The simulated team of `mission` standing where `dance` starts, with
/// `faults` injected.
pub fn team(mission: &Mission, dance: &Dance, faults: Vec<Fault>) -> Result<Team> {
    let p = parts(mission, dance)?;
    let start = p.parent.believed_pose();
    let drives: Vec<Box<dyn TeamDrive>> =
        std::iter::once(p.parent).chain(p.children).map(|d| Box::new(d) as Box<dyn TeamDrive>).collect();
    let devices = Devices {
        total_station: p.total_station.map(|t| Box::new(t) as _),
        tilt: Box::new(p.tilt),
        range_finder: Box::new(p.lms),
        head: Box::new(p.head),
        drives,
        body_from_head: p.body_from_head,
    };
    Ok(Team::new(devices, mission.scene().clone(), start, Some(p.world), Faults::new(faults)))
}

macro_rules! kept {
    ($($device:ty),*) => {$(
        impl Kept for $device {
            fn noise(&self) -> Option<u128> {
                Some(self.noise_position())
            }
            fn set_noise(&mut self, words: u128) {
                self.set_noise_position(words);
            }
        }
    )*};
}
kept!(SimTotalStation, SimTilt, SimLms, SimDrive);

impl TeamDrive for SimDrive {
    fn relocalise(&mut self, pose: &PlanarPose, keep_heading: bool) -> scanner::Result<()> {
        SimDrive::relocalise(self, *pose, keep_heading);
        Ok(())
    }

    fn poses(&self) -> Option<(PlanarPose, PlanarPose)> {
        Some((self.believed_pose(), self.true_pose()))
    }

    fn restore(&mut self, believed: PlanarPose, truth: PlanarPose) {
        SimDrive::restore(self, believed, truth);
    }
}
