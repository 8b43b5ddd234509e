//! Simulated devices behind the same traits as the real drivers. They share
//! one [`SimWorld`]: the scene and the true state of the team (parent pose
//! and tilt, prism positions, head angle). Drives change the truth; the
//! total station, the laser scanner and the tilt sensor measure it with
//! seeded noise (ChaCha8, one stream per device: the same seed gives the same
//! bytes).

mod drive;
mod lms;
mod total_station;

use std::sync::{Arc, Mutex, MutexGuard};

use cps::ParentPose;
use cps::geom::Scene;
use nalgebra::Point3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub use drive::{OdometryError, Robot, SimDrive};
pub use lms::{LmsConfig, LmsRangeMode, LmsResolution, SimLms};
pub use total_station::SimTotalStation;

/// The simulated tilt sensor's standard deviation in roll and pitch, 0.01°.
pub const TILT_SIGMA_RAD: f64 = 0.01 * std::f64::consts::PI / 180.0;

use crate::devices::{HeadKind, ScanHead, Tilt, TiltSensor};
use crate::error::{Result, ScannerError};

/// The true state of the simulated team.
#[derive(Debug, Clone, PartialEq)]
pub struct Truth {
    /// The parent's true pose (total-station centre and heading).
    pub parent: ParentPose,
    /// The parent body's true roll and pitch.
    pub tilt: Tilt,
    /// True prism centres of the children, world frame.
    pub children: Vec<Point3<f64>>,
    /// True centres of the control prisms (each off its monument by its
    /// centring), world frame; they never move.
    pub control: Vec<Point3<f64>>,
    /// The scan head's true angle, radians.
    pub head_angle_rad: f64,
}

/// The scene and the team's truth, shared by all simulated devices.
#[derive(Debug, Clone)]
pub struct SimWorld {
    scene: Arc<Scene>,
    truth: Arc<Mutex<Truth>>,
}

impl SimWorld {
    /// A world with the team standing at the given true positions, level.
    /// The scene may be shared (`Arc<Scene>`) with whoever built it.
    pub fn new(scene: impl Into<Arc<Scene>>, parent: ParentPose, children: Vec<Point3<f64>>) -> Self {
        let truth = Truth { parent, tilt: Tilt::default(), children, control: Vec::new(), head_angle_rad: 0.0 };
        Self { scene: scene.into(), truth: Arc::new(Mutex::new(truth)) }
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// A copy of the current truth.
    pub fn truth(&self) -> Truth {
        self.lock().clone()
    }

    /// Sets up the control prisms at their true positions.
    pub fn set_control(&self, control: Vec<Point3<f64>>) {
        self.lock().control = control;
    }

    /// Overwrites the truth (used when resuming a journaled run).
    pub fn set_truth(&self, truth: Truth) {
        *self.lock() = truth;
    }

    fn lock(&self) -> MutexGuard<'_, Truth> {
        // A panic elsewhere cannot leave `Truth` half-written (it is plain
        // data), so a poisoned lock is still usable.
        self.truth.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// Stream numbers of the devices, so each has its own noise sequence.
pub(crate) mod stream {
    pub const TOTAL_STATION: u64 = 1;
    pub const LMS: u64 = 2;
    pub const TILT: u64 = 3;
    pub const CONTROL: u64 = 5;
    pub const PARENT_DRIVE: u64 = 4;
    pub const CHILD_DRIVE: u64 = 16;
}

/// A simulated device's position in its noise stream. A journaled run
/// records it after every reading so that `--resume` continues with exactly
/// the noise an uninterrupted run would have drawn.
pub trait NoiseStream {
    /// The number of 32-bit words drawn from the stream so far.
    fn noise_position(&self) -> u128;
    /// Continues the stream at `words` drawn words.
    fn set_noise_position(&mut self, words: u128);
}

macro_rules! noise_stream {
    ($($device:ty),*) => {$(
        impl NoiseStream for $device {
            fn noise_position(&self) -> u128 {
                self.rng.get_word_pos()
            }
            fn set_noise_position(&mut self, words: u128) {
                self.rng.set_word_pos(words);
            }
        }
    )*};
}
noise_stream!(SimTilt, SimDrive, SimLms, SimTotalStation);

/// Where the control prisms truly stand: each off its given coordinates by
/// a draw of their covariance (`given`: position, covariance x, y, z) and,
/// horizontally, of the prism's centring `centring_m` (1σ per axis) —
/// seeded, on a stream of its own, so that every other device's noise is
/// the same with or without control.
pub fn control_prisms(given: &[(Point3<f64>, nalgebra::Matrix3<f64>)], centring_m: f64, seed: u64) -> Vec<Point3<f64>> {
    use rand_distr::{Distribution, StandardNormal};
    let mut r = rng(seed, stream::CONTROL);
    given
        .iter()
        .map(|(p, cov)| {
            let c2 = centring_m * centring_m;
            let cov = cov + nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(c2, c2, 0.0));
            let eig = nalgebra::SymmetricEigen::new(cov);
            let z = nalgebra::Vector3::from_fn(|i, _| {
                let n: f64 = StandardNormal.sample(&mut r);
                eig.eigenvalues[i].max(0.0).sqrt() * n
            });
            p + eig.eigenvectors * z
        })
        .collect()
}

pub(crate) fn rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}

/// A simulated scan head: sets the true head angle exactly.
#[derive(Debug, Clone)]
pub struct SimHead {
    world: SimWorld,
    kind: HeadKind,
}

impl SimHead {
    /// A head of the given kind in `world`.
    pub fn new(world: SimWorld, kind: HeadKind) -> Self {
        Self { world, kind }
    }
}

impl ScanHead for SimHead {
    fn kind(&self) -> HeadKind {
        self.kind
    }

    fn move_to(&mut self, angle_rad: f64) -> Result<f64> {
        // NaN fails both range tests.
        let (ok, expected) = match self.kind {
            HeadKind::RotatingTable => ((0.0..std::f64::consts::TAU).contains(&angle_rad), "0 ≤ angle < 2π"),
            HeadKind::PitchingMount => (angle_rad.abs() <= 60f64.to_radians() + 1e-9, "|angle| ≤ 60°"),
        };
        if !ok {
            return Err(ScannerError::OutOfRange {
                device: format!("simulated {:?}", self.kind),
                what: "head angle (rad)".into(),
                value: angle_rad,
                expected: expected.into(),
            });
        }
        self.world.lock().head_angle_rad = angle_rad;
        Ok(angle_rad)
    }
}

/// A simulated two-axis inclinometer with white noise.
#[derive(Debug, Clone)]
pub struct SimTilt {
    world: SimWorld,
    sigma_rad: f64,
    rng: ChaCha8Rng,
}

impl SimTilt {
    /// A tilt sensor with 1σ noise `sigma_rad` per axis.
    pub fn new(world: SimWorld, sigma_rad: f64, seed: u64) -> Self {
        Self { world, sigma_rad, rng: rng(seed, stream::TILT) }
    }
}

impl TiltSensor for SimTilt {
    fn name(&self) -> &str {
        "simulated tilt sensor"
    }

    fn read(&mut self) -> Result<Tilt> {
        use rand::Rng;
        let t = self.world.lock().tilt;
        let mut n = || self.sigma_rad * self.rng.sample::<f64, _>(rand_distr::StandardNormal);
        Ok(Tilt { roll_rad: t.roll_rad + n(), pitch_rad: t.pitch_rad + n() })
    }
}
