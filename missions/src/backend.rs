//! The simulated team a mission runs on: one [`SimWorld`] and every device
//! in it, with checkpoints (so a journaled run resumes bit for bit) and
//! injected faults (so retries and clean stops can be exercised).

use std::str::FromStr;

use anyhow::{Context, Result};
use cps::ParentPose;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use planner::Dance;
use scanner::sim::{
    LmsConfig, LmsRangeMode, NoiseStream, Robot, SimDrive, SimHead, SimLms, SimTilt, SimTotalStation, SimWorld, Truth,
};
use scanner::{
    Drive, Odometry, PlanarPose, Scan, ScannerError, Target, Tilt, TiltSensor, TotalStation, TsMeasurement, scan_3d,
};
use serde_json::{Value, json};

use crate::mission::Mission;

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
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fault {
    /// The device.
    pub device: DeviceKind,
    /// When it fails.
    pub rule: FaultRule,
}

/// When an injected fault strikes, counting the device's commands from 1
/// (each retry is a command).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultRule {
    /// Every command after the n-th fails: the device stopped answering.
    After(usize),
    /// Every k-th command fails once (a retry then succeeds).
    Every(usize),
}

impl FromStr for Fault {
    type Err = String;

    /// `DEVICE:after=N` or `DEVICE:every=K`, DEVICE one of `drive`,
    /// `total-station`, `tilt`, `scanner`.
    fn from_str(s: &str) -> Result<Self, String> {
        let expected = "expected DEVICE:after=N or DEVICE:every=K with DEVICE drive, total-station, tilt or scanner";
        let (device, rule) = s.split_once(':').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
        let device = [DeviceKind::Drive, DeviceKind::TotalStation, DeviceKind::Tilt, DeviceKind::Scanner]
            .into_iter()
            .find(|d| d.name() == device)
            .ok_or_else(|| format!("fault \"{s}\": unknown device \"{device}\"; {expected}"))?;
        let (kind, n) = rule.split_once('=').ok_or_else(|| format!("fault \"{s}\": {expected}"))?;
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
}

impl SimTeam {
    /// The team standing where `dance` starts: the parent truly at station
    /// 0, the children at their first formation points.
    pub fn new(mission: &Mission, dance: &Dance, faults: Vec<Fault>) -> Result<Self> {
        let seed = mission.backend.seed;
        let scene = mission.scene()?;
        let start = dance.station_pose(0);
        let first = dance.cycles.first().map(|c| c.children.clone()).unwrap_or_default();
        let world = SimWorld::new(scene, start, first.clone());
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
        let body_from_head =
            Isometry3::from_parts(Translation3::from(mission.scan.body_from_head_m), UnitQuaternion::identity());
        let lms_config =
            LmsConfig { resolution: mission.scan.resolution, mode: LmsRangeMode::Mm32, sigma_range_m: 0.005 };
        Ok(Self {
            total_station: mission.total_station.clone().map(|i| SimTotalStation::new(world.clone(), i, seed)),
            tilt: SimTilt::new(world.clone(), 0.01f64.to_radians(), seed),
            lms: SimLms::new(world.clone(), lms_config, mission.scan.head, body_from_head, seed),
            head: SimHead::new(world.clone(), mission.scan.head),
            world,
            parent,
            children,
            body_from_head,
            faults,
            commands: [0; 4],
        })
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

    /// Measures a child with the total station.
    pub fn measure(&mut self, target: &Target) -> scanner::Result<TsMeasurement> {
        self.command(DeviceKind::TotalStation, "simulated total station")?;
        match &mut self.total_station {
            Some(ts) => ts.measure(target),
            None => Err(ScannerError::Device {
                device: "total station".into(),
                message: "the team has no total station (no children)".into(),
            }),
        }
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

    /// The whole simulated state as JSON: the truth, each drive's believed
    /// and true pose, and every device's noise position.
    pub fn checkpoint(&self) -> Value {
        let t = self.world.truth();
        let p = &t.parent;
        let pose = |q: PlanarPose| [q.x_m, q.y_m, q.heading_rad];
        let drives: Vec<Value> = std::iter::once(&self.parent)
            .chain(&self.children)
            .map(|d| {
                json!({"believed": pose(d.believed_pose()), "true": pose(d.true_pose()),
                "noise": words(d.noise_position())})
            })
            .collect();
        json!({
            "truth": {
                "parent": [p.position.x, p.position.y, p.position.z, p.heading_rad],
                "tilt": [t.tilt.roll_rad, t.tilt.pitch_rad],
                "children": t.children.iter().map(|c| [c.x, c.y, c.z]).collect::<Vec<_>>(),
                "head_rad": t.head_angle_rad,
            },
            "drives": drives,
            "noise": {
                "total_station": self.total_station.as_ref().map(|t| words(t.noise_position())),
                "tilt": words(self.tilt.noise_position()),
                "scanner": words(self.lms.noise_position()),
            },
        })
    }

    /// Puts the world and every device back into a [`SimTeam::checkpoint`].
    pub fn restore(&mut self, c: &Value) -> Result<()> {
        let f = |v: &Value, what: &str| v.as_f64().with_context(|| format!("checkpoint {what}: expected a number"));
        let arr = |v: &Value, n: usize, what: &str| -> Result<Vec<f64>> {
            let a = v
                .as_array()
                .filter(|a| a.len() == n)
                .with_context(|| format!("checkpoint {what}: expected {n} numbers"))?;
            a.iter().map(|x| f(x, what)).collect()
        };
        let t = &c["truth"];
        let p = arr(&t["parent"], 4, "truth.parent")?;
        let tilt = arr(&t["tilt"], 2, "truth.tilt")?;
        let children = t["children"]
            .as_array()
            .filter(|a| a.len() == self.children.len())
            .context("checkpoint truth.children: one position per child expected")?
            .iter()
            .map(|x| arr(x, 3, "truth.children").map(|v| Point3::new(v[0], v[1], v[2])))
            .collect::<Result<Vec<_>>>()?;
        self.world.set_truth(Truth {
            parent: ParentPose::new(p[0], p[1], p[2], p[3]),
            tilt: Tilt { roll_rad: tilt[0], pitch_rad: tilt[1] },
            children,
            head_angle_rad: f(&t["head_rad"], "truth.head_rad")?,
        });
        let drives = c["drives"]
            .as_array()
            .filter(|a| a.len() == 1 + self.children.len())
            .context("checkpoint drives: one per robot expected")?;
        for (d, saved) in std::iter::once(&mut self.parent).chain(&mut self.children).zip(drives) {
            let pose =
                |v: &Value, what| arr(v, 3, what).map(|q| PlanarPose { x_m: q[0], y_m: q[1], heading_rad: q[2] });
            d.restore(pose(&saved["believed"], "drives.believed")?, pose(&saved["true"], "drives.true")?);
            d.set_noise_position(from_words(&saved["noise"])?);
        }
        let n = &c["noise"];
        if let Some(ts) = &mut self.total_station {
            ts.set_noise_position(from_words(&n["total_station"])?);
        }
        self.tilt.set_noise_position(from_words(&n["tilt"])?);
        self.lms.set_noise_position(from_words(&n["scanner"])?);
        Ok(())
    }
}

/// A noise position as a JSON string (a u128 does not fit a JSON number
/// every reader accepts).
fn words(n: u128) -> Value {
    json!(n.to_string())
}

fn from_words(v: &Value) -> Result<u128> {
    v.as_str()
        .and_then(|s| s.parse().ok())
        .with_context(|| format!("checkpoint noise position {v}: expected a decimal string"))
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
