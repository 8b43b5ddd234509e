//! Simulated drives with odometry error. A robot believes it reaches the
//! commanded pose exactly; in truth the distance is scaled and noisy and
//! the heading drifts, so dead reckoning accumulates error (which CPS fixes
//! and ICP can correct).

use cps::wrap_angle;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::{SimWorld, rng, stream};
use crate::devices::{Drive, Odometry, PlanarPose, Tilt};
use crate::error::{Result, ScannerError};

/// Moves shorter than this (a micrometre; the drive protocol carries
/// nanometres) are a robot told to stay where it is.
const STAY_M: f64 = 1e-6;

/// The odometry error model of a drive. Per move of length d (m): true
/// distance d·(1 + `scale_error`) + N(0, `sigma_distance_m_per_sqrt_m`²·d);
/// heading error `heading_drift_rad_per_m`·d + N(0,
/// `sigma_heading_rad_per_sqrt_m`²·d), half of it applied to the direction of
/// travel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryError {
    /// Systematic distance scale error (0.01 = 1 % long).
    pub scale_error: f64,
    /// Random distance error, m/√m.
    pub sigma_distance_m_per_sqrt_m: f64,
    /// Systematic heading drift, rad/m.
    pub heading_drift_rad_per_m: f64,
    /// Random heading error, rad/√m.
    pub sigma_heading_rad_per_sqrt_m: f64,
    /// 1σ of the parent's roll and pitch at a stop (uneven floor), rad.
    pub terrain_tilt_sigma_rad: f64,
}

impl Default for OdometryError {
    /// 0.5 % scale, 5 mm/√m, 1 mrad/m drift, 1 mrad/√m heading noise and
    /// 0.1° terrain tilt.
    fn default() -> Self {
        Self {
            scale_error: 0.005,
            sigma_distance_m_per_sqrt_m: 0.005,
            heading_drift_rad_per_m: 1e-3,
            sigma_heading_rad_per_sqrt_m: 1e-3,
            terrain_tilt_sigma_rad: 0.1f64.to_radians(),
        }
    }
}

/// Which robot a drive moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Robot {
    /// The parent (total station, scanner).
    Parent,
    /// Child `j` (prism).
    Child(usize),
}

/// A simulated drive.
#[derive(Debug, Clone)]
pub struct SimDrive {
    world: SimWorld,
    robot: Robot,
    error: OdometryError,
    believed: PlanarPose,
    true_pose: PlanarPose,
    name: String,
    pub(super) rng: ChaCha8Rng,
}

impl SimDrive {
    /// A drive for `robot`, which believes it starts at `start` and truly
    /// stands at its position in the world's truth with heading
    /// `start.heading_rad`.
    pub fn new(world: SimWorld, robot: Robot, start: PlanarPose, error: OdometryError, seed: u64) -> Result<Self> {
        let truth = world.truth();
        let (x, y) = match robot {
            Robot::Parent => (truth.parent.position.x, truth.parent.position.y),
            Robot::Child(j) => {
                let c = truth
                    .children
                    .get(j)
                    .ok_or(cps::CpsError::UnknownChild { child: j, team: truth.children.len() })?;
                (c.x, c.y)
            }
        };
        let heading = if robot == Robot::Parent { truth.parent.heading_rad } else { start.heading_rad };
        let (name, s) = match robot {
            Robot::Parent => ("simulated parent drive".to_string(), stream::PARENT_DRIVE),
            Robot::Child(j) => (format!("simulated drive of child {j}"), stream::CHILD_DRIVE + j as u64),
        };
        Ok(Self {
            world,
            robot,
            error,
            believed: start,
            true_pose: PlanarPose { x_m: x, y_m: y, heading_rad: heading },
            name,
            rng: rng(seed, s),
        })
    }

    /// The robot's true planar pose.
    pub fn true_pose(&self) -> PlanarPose {
        self.true_pose
    }

    /// Where the robot believes it is (its last commanded pose).
    pub fn believed_pose(&self) -> PlanarPose {
        self.believed
    }

    /// Puts the drive back into a recorded state: the pose it believed and
    /// its true pose (the world's truth is restored separately with
    /// [`SimWorld::set_truth`]).
    pub fn restore(&mut self, believed: PlanarPose, true_pose: PlanarPose) {
        self.believed = believed;
        self.true_pose = true_pose;
    }

    /// The robot learns where it is (from the CPS): it now believes
    /// `believed`, and its next move starts from there. With
    /// `keep_heading_error = false` it also learns its true heading (a child
    /// whose heading the total station's tracking holds).
    pub fn relocalise(&mut self, believed: PlanarPose, keep_heading_error: bool) {
        self.believed = believed;
        if !keep_heading_error {
            self.believed.heading_rad = self.true_pose.heading_rad;
        }
    }
}

impl Drive for SimDrive {
    fn name(&self) -> &str {
        &self.name
    }

    fn move_to(&mut self, target: &PlanarPose) -> Result<Odometry> {
        if ![target.x_m, target.y_m, target.heading_rad].iter().all(|v| v.is_finite()) {
            return Err(ScannerError::Device {
                device: self.name.clone(),
                message: format!("target pose {target:?} is not finite"),
            });
        }
        let e = self.error;
        let (dx, dy) = (target.x_m - self.believed.x_m, target.y_m - self.believed.y_m);
        let d = dx.hypot(dy);
        // The move in the robot's believed body frame.
        let (s, c) = self.believed.heading_rad.sin_cos();
        let (fwd, left) = (c * dx + s * dy, -s * dx + c * dy);
        let mut n = || -> f64 { self.rng.sample(StandardNormal) };
        let heading_error = e.heading_drift_rad_per_m * d + e.sigma_heading_rad_per_sqrt_m * d.sqrt() * n();
        // A move shorter than the wire's rounding (a robot told to stay
        // where it is) draws no distance noise, on any backend.
        let scale =
            if d > STAY_M { 1.0 + e.scale_error + e.sigma_distance_m_per_sqrt_m * d.sqrt() * n() / d } else { 1.0 };
        let travel_heading = self.true_pose.heading_rad + heading_error / 2.0;
        let (ts, tc) = travel_heading.sin_cos();
        self.true_pose.x_m += scale * (tc * fwd - ts * left);
        self.true_pose.y_m += scale * (ts * fwd + tc * left);
        self.true_pose.heading_rad =
            wrap_angle(self.true_pose.heading_rad + (target.heading_rad - self.believed.heading_rad) + heading_error);
        let tilt = Tilt { roll_rad: e.terrain_tilt_sigma_rad * n(), pitch_rad: e.terrain_tilt_sigma_rad * n() };
        self.believed = *target;
        let p = self.true_pose;
        let mut truth = self.world.lock();
        match self.robot {
            Robot::Parent => {
                truth.parent.position.x = p.x_m;
                truth.parent.position.y = p.y_m;
                truth.parent.heading_rad = p.heading_rad;
                truth.tilt = tilt;
            }
            Robot::Child(j) => {
                if let Some(c) = truth.children.get_mut(j) {
                    c.x = p.x_m;
                    c.y = p.y_m;
                }
            }
        }
        Ok(Odometry { pose: *target, distance_m: d })
    }
}

#[cfg(test)]
mod tests {
    use cps::ParentPose;
    use cps::geom::builtin;
    use nalgebra::Point3;

    use super::*;

    fn world() -> SimWorld {
        SimWorld::new(
            builtin("corridor").expect("corridor"),
            ParentPose::new(1.0, 0.0, 0.5, 0.0),
            vec![Point3::new(1.0, 0.5, 0.3)],
        )
    }

    #[test]
    fn perfect_odometry_reaches_the_target() {
        let w = world();
        let none = OdometryError {
            scale_error: 0.0,
            sigma_distance_m_per_sqrt_m: 0.0,
            heading_drift_rad_per_m: 0.0,
            sigma_heading_rad_per_sqrt_m: 0.0,
            terrain_tilt_sigma_rad: 0.0,
        };
        let start = PlanarPose { x_m: 1.0, y_m: 0.0, heading_rad: 0.0 };
        let mut d = SimDrive::new(w.clone(), Robot::Parent, start, none, 1).expect("drive");
        let target = PlanarPose { x_m: 5.0, y_m: 0.3, heading_rad: 0.2 };
        let odo = d.move_to(&target).expect("move");
        assert_eq!(odo.pose, target);
        let t = w.truth().parent;
        assert!(
            (t.position.x - 5.0).abs() < 1e-12
                && (t.position.y - 0.3).abs() < 1e-12
                && (t.heading_rad - 0.2).abs() < 1e-12
        );
        assert_eq!(t.position.z, 0.5, "height is kept");
    }

    /// A systematic scale error and heading drift give the expected end
    /// pose after driving 20 × 2 m straight: distance 40·(1+s), heading
    /// 40·drift, and the lateral offset of a constant-curvature path.
    #[test]
    fn systematic_errors_accumulate_as_derived() {
        let w = world();
        let (scale, drift) = (0.01, 2e-3);
        let err = OdometryError {
            scale_error: scale,
            sigma_distance_m_per_sqrt_m: 0.0,
            heading_drift_rad_per_m: drift,
            sigma_heading_rad_per_sqrt_m: 0.0,
            terrain_tilt_sigma_rad: 0.0,
        };
        let mut d =
            SimDrive::new(w.clone(), Robot::Child(0), PlanarPose { x_m: 1.0, y_m: 0.5, heading_rad: 0.0 }, err, 1)
                .expect("drive");
        for k in 1..=20 {
            d.move_to(&PlanarPose { x_m: 1.0 + 2.0 * k as f64, y_m: 0.5, heading_rad: 0.0 }).expect("move");
        }
        let t = d.true_pose();
        assert!((t.heading_rad - 40.0 * drift).abs() < 1e-12);
        // Step k travels 2(1+s) m at heading (k − ½)·2·drift.
        let (mut x, mut y) = (1.0, 0.5);
        for k in 1..=20 {
            let h = (k as f64 - 0.5) * 2.0 * drift;
            x += 2.0 * (1.0 + scale) * h.cos();
            y += 2.0 * (1.0 + scale) * h.sin();
        }
        assert!((t.x_m - x).abs() < 1e-9 && (t.y_m - y).abs() < 1e-9);
        let c = w.truth().children[0];
        assert_eq!((c.x, c.y), (t.x_m, t.y_m));
        assert!(y - 0.5 > 0.7, "40 m with 2 mrad/m drifts sideways by ~0.8 m: {y}");
    }
}
