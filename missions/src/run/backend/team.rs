//! The one team a mission commands, over `scanner`'s device traits: a
//! total station, a tilt sensor, a 2D range finder on a scan head, and a
//! drive for every robot — whichever backend made them — with the
//! simulator's extras beside them (the world's truth, the noise streams a
//! journal checkpoint keeps, injected faults).

use std::fmt::Debug;
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use cps::ParentPose;
use nalgebra::{Isometry3, Point3};
use scanner::sim::{Robot, SimWorld, Truth};
use scanner::{
    Drive, Odometry, PlanarPose, RangeFinder2D, Scan, ScanHead, ScannerError, Target, Tilt, TiltSensor, TotalStation,
    TsMeasurement, scan_3d,
};

use super::faults::{DeviceKind, Faults};
use crate::journal::{Checkpoint, DriveState, NoiseState, TruthRecord};

/// What a journal checkpoint keeps of a device to resume it bit for bit:
/// a simulated device's noise position; a real instrument keeps nothing.
pub trait Kept {
    /// Where its noise stream stands, if it has one.
    fn noise(&self) -> Option<u128> {
        None
    }
    /// Continues its noise stream at `words` drawn words.
    fn set_noise(&mut self, _words: u128) {}
}

/// A total station of a team.
pub trait TeamTotalStation: TotalStation + Kept + Debug {}
impl<T: TotalStation + Kept + Debug> TeamTotalStation for T {}

/// A tilt sensor of a team.
pub trait TeamTilt: TiltSensor + Kept + Debug {}
impl<T: TiltSensor + Kept + Debug> TeamTilt for T {}

/// A 2D range finder of a team.
pub trait TeamRangeFinder: RangeFinder2D + Kept + Debug {}
impl<T: RangeFinder2D + Kept + Debug> TeamRangeFinder for T {}

/// A scan head of a team.
pub trait TeamHead: ScanHead + Debug {}
impl<T: ScanHead + Debug> TeamHead for T {}

/// A robot's drive in a team: it drives, and it is told where the CPS
/// puts it.
pub trait TeamDrive: Drive + Kept + Debug {
    /// The robot now believes it stands at `pose`; with `keep_heading` it
    /// keeps its own heading (a child's heading is the total station's
    /// tracking's).
    fn relocalise(&mut self, pose: &PlanarPose, keep_heading: bool) -> scanner::Result<()>;
    /// The pose it believes and its true pose, where a simulator knows them.
    fn poses(&self) -> Option<(PlanarPose, PlanarPose)> {
        None
    }
    /// Puts a simulated drive back into a recorded believed and true pose.
    fn restore(&mut self, _believed: PlanarPose, _truth: PlanarPose) {}
}

/// The devices of a team, as a backend makes them.
#[derive(Debug)]
pub struct Devices {
    /// The parent's total station (none for a robot alone).
    pub total_station: Option<Box<dyn TeamTotalStation>>,
    /// The parent's tilt sensor.
    pub tilt: Box<dyn TeamTilt>,
    /// The parent's 2D laser scanner.
    pub range_finder: Box<dyn TeamRangeFinder>,
    /// The head that turns it.
    pub head: Box<dyn TeamHead>,
    /// The parent's drive, then each child's.
    pub drives: Vec<Box<dyn TeamDrive>>,
    /// The scan head's mount on the body.
    pub body_from_head: Isometry3<f64>,
}

/// The devices a mission commands.
#[derive(Debug)]
pub struct Team {
    devices: Devices,
    /// The site model the plan is checked against (the simulator's world).
    scene: Arc<cps::geom::Scene>,
    /// Where the parent's drive believes it stands (its odometry).
    parent_believed: PlanarPose,
    /// The simulator's world: the truth and what a checkpoint restores.
    world: Option<SimWorld>,
    faults: Faults,
}

impl Team {
    /// A team of `devices` in `scene`, the parent believing it stands at
    /// `start`; `world` when simulated, with `faults` injected.
    pub fn new(
        devices: Devices,
        scene: Arc<cps::geom::Scene>,
        start: PlanarPose,
        world: Option<SimWorld>,
        faults: Faults,
    ) -> Self {
        Self { devices, scene, parent_believed: start, world, faults }
    }

    /// The true state of the team (simulator only).
    pub fn truth(&self) -> Option<Truth> {
        self.world.as_ref().map(SimWorld::truth)
    }

    /// The parent learns its pose from a CPS fix: its next drive starts
    /// from there (the robot navigates by its estimate, so the odometry
    /// error does not pile up over the mission); it keeps its own heading
    /// error.
    pub fn relocalise_parent(&mut self, pose: &ParentPose) -> Result<()> {
        let pose = PlanarPose::from(pose);
        self.parent_believed = pose;
        if let Some(d) = self.devices.drives.first_mut() {
            d.relocalise(&pose, true)?;
        }
        Ok(())
    }

    /// Child `j` learns its position from its placement measurement (and
    /// its heading from the total station's tracking).
    pub fn relocalise_child(&mut self, j: usize, at: &Point3<f64>) -> Result<()> {
        if let Some(d) = self.devices.drives.get_mut(1 + j) {
            d.relocalise(&PlanarPose { x_m: at.x, y_m: at.y, heading_rad: 0.0 }, false)?;
        }
        Ok(())
    }

    /// Where the parent's drive believes it stands (its odometry).
    pub fn parent_believed(&self) -> PlanarPose {
        self.parent_believed
    }

    /// The scene (the site model the plan was checked against).
    pub fn scene(&self) -> &cps::geom::Scene {
        &self.scene
    }

    /// Drives `robot` to `goal`.
    pub fn drive(&mut self, robot: Robot, goal: &PlanarPose) -> scanner::Result<Odometry> {
        let k = match robot {
            Robot::Parent => 0,
            Robot::Child(j) => 1 + j,
        };
        let team = self.devices.drives.len().saturating_sub(1);
        let drive =
            self.devices.drives.get_mut(k).ok_or(cps::CpsError::UnknownChild { child: k.saturating_sub(1), team })?;
        self.faults.command(DeviceKind::Drive, drive.name())?;
        let odometry = drive.move_to(goal)?;
        if k == 0 {
            self.parent_believed = odometry.pose;
        }
        Ok(odometry)
    }

    /// Measures a prism with the total station; a planted blunder
    /// (`--sim-fault total-station:blunder…`) strikes its measurement.
    pub fn measure(&mut self, target: &Target) -> scanner::Result<TsMeasurement> {
        let name = self.devices.total_station.as_ref().map_or("total station", |t| t.name());
        self.faults.command(DeviceKind::TotalStation, name)?;
        let Some(ts) = &mut self.devices.total_station else {
            return Err(ScannerError::Device {
                device: "total station".into(),
                message: "the team has no total station (no children)".into(),
            });
        };
        let mut m = ts.measure(target)?;
        self.faults.measured(&mut m);
        Ok(m)
    }

    /// Reads the tilt sensor.
    pub fn tilt(&mut self) -> scanner::Result<Tilt> {
        self.faults.command(DeviceKind::Tilt, self.devices.tilt.name())?;
        self.devices.tilt.read()
    }

    /// Takes a 3D scan of `slices` slices, reporting progress per slice.
    pub fn scan(&mut self, slices: usize, progress: &mut dyn FnMut(usize, usize)) -> scanner::Result<Scan> {
        let d = &mut self.devices;
        self.faults.command(DeviceKind::Scanner, d.range_finder.name())?;
        scan_3d(d.head.as_mut(), d.range_finder.as_mut(), slices, &d.body_from_head, progress)
    }

    /// The team's state for the journal: on the simulator its whole state
    /// (the truth, each drive's believed and true pose, every device's
    /// noise position); else the parent's odometry (`drives[0].believed`,
    /// as in the simulator's).
    pub fn checkpoint(&self) -> Checkpoint {
        let pose = |q: PlanarPose| [q.x_m, q.y_m, q.heading_rad];
        let Some(world) = &self.world else {
            let drives = vec![DriveState { believed: pose(self.parent_believed), truth: None, noise: None }];
            return Checkpoint { drives, noise: None, truth: None };
        };
        let d = &self.devices;
        let noise = |k: &dyn Kept| k.noise().map(|n| n.to_string()).unwrap_or_default();
        let drives = d
            .drives
            .iter()
            .map(|drive| {
                let poses = drive.poses();
                DriveState {
                    believed: pose(poses.map_or(self.parent_believed, |(believed, _)| believed)),
                    truth: poses.map(|(_, truth)| pose(truth)),
                    noise: drive.noise().map(|n| n.to_string()),
                }
            })
            .collect();
        Checkpoint {
            drives,
            noise: Some(NoiseState {
                total_station: d.total_station.as_ref().and_then(|t| t.noise()).map(|n| n.to_string()),
                tilt: noise(d.tilt.as_ref()),
                scanner: noise(d.range_finder.as_ref()),
                measurements: Some(self.faults.measurements),
            }),
            truth: Some(truth_record(&world.truth())),
        }
    }

    /// Puts the team back into a checkpoint: the simulator's whole state,
    /// or the parent's odometry (real robots are where the replayed journal
    /// left them).
    pub fn restore(&mut self, c: &Checkpoint) -> Result<()> {
        let Some(world) = &self.world else {
            self.parent_believed =
                c.parent_believed().context("checkpoint: expected drives[0].believed = [x, y, heading]")?;
            return Ok(());
        };
        let d = &mut self.devices;
        let t = c.truth.as_ref().context("checkpoint without the simulator's truth")?;
        let children = d.drives.len().saturating_sub(1);
        if t.children.len() != children {
            bail!("checkpoint truth.children: {} positions for {children} children", t.children.len());
        }
        let p = t.parent;
        world.set_truth(Truth {
            // The control prisms never move.
            control: world.truth().control,
            parent: ParentPose::new(p[0], p[1], p[2], p[3]),
            tilt: Tilt { roll_rad: t.tilt[0], pitch_rad: t.tilt[1] },
            children: t.children.iter().map(|x| Point3::new(x[0], x[1], x[2])).collect(),
            head_angle_rad: t.head_rad,
        });
        if c.drives.len() != d.drives.len() {
            bail!("checkpoint drives: {} states for {} robots", c.drives.len(), d.drives.len());
        }
        let pose = |q: [f64; 3]| PlanarPose { x_m: q[0], y_m: q[1], heading_rad: q[2] };
        for (drive, saved) in d.drives.iter_mut().zip(&c.drives) {
            let truth = saved.truth.context("checkpoint drives: a drive without its true pose")?;
            drive.restore(pose(saved.believed), pose(truth));
            drive.set_noise(noise_position(saved.noise.as_deref(), "drives.noise")?);
        }
        if let Some(parent) = c.drives.first() {
            self.parent_believed = pose(parent.believed);
        }
        let n = c.noise.as_ref().context("checkpoint without the noise streams")?;
        if let Some(ts) = &mut d.total_station {
            ts.set_noise(noise_position(n.total_station.as_deref(), "noise.total_station")?);
        }
        d.tilt.set_noise(noise_position(Some(&n.tilt), "noise.tilt")?);
        // Journals of version 1 did not count; they knew no blunders.
        self.faults.measurements = n.measurements.unwrap_or(0);
        d.range_finder.set_noise(noise_position(Some(&n.scanner), "noise.scanner")?);
        Ok(())
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
