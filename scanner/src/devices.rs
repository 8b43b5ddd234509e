//! The instrument traits shared by the simulator and the serial drivers, and
//! the data they return. Angles follow each instrument's own convention at
//! this boundary; conversions to the CPS model's convention are explicit
//! methods.

use cps::{Instrument, ParentPose, Reading, wrap_angle};
use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::error::Result;

/// The status a total station reports with a measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TsStatus {
    /// Measured normally.
    Ok,
    /// Measured, but the instrument flags reduced accuracy (e.g. the
    /// compensator near its limit).
    ReducedAccuracy,
}

/// A target to measure: the child's index and the predicted pointing, which
/// a real instrument uses to search for the prism.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// The prism.
    pub prism: Prism,
    /// Predicted reading in the CPS convention.
    pub predicted: Reading,
}

/// Which prism a measurement aims at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Prism {
    /// A child's (team order).
    Child(usize),
    /// A control point's (mission order).
    Control(usize),
}

impl std::fmt::Display for Prism {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Prism::Child(j) => write!(f, "child {j}"),
            Prism::Control(k) => write!(f, "control point {k}"),
        }
    }
}

/// One total-station measurement in the instrument's convention.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TsMeasurement {
    /// Slope distance as the instrument reports it (before the prism
    /// constant), metres.
    pub slope_raw_m: f64,
    /// Horizontal angle Hz, radians, **clockwise** from the instrument's zero
    /// direction (the robot's heading), in [0, 2π).
    pub hz_rad: f64,
    /// Vertical angle V, radians, the **zenith angle** (0 = straight up).
    pub v_rad: f64,
    /// Status flag.
    pub status: TsStatus,
}

impl TsMeasurement {
    /// The reading in the CPS convention: slope corrected by the prism
    /// constant, azimuth φ = −Hz (counter-clockwise), elevation ψ = π/2 − V.
    pub fn to_reading(&self, instrument: &Instrument) -> Reading {
        Reading {
            slope_m: instrument.corrected_slope_m(self.slope_raw_m),
            azimuth_rad: wrap_angle(-self.hz_rad),
            elevation_rad: std::f64::consts::FRAC_PI_2 - self.v_rad,
        }
    }

    /// The instrument measurement that corresponds to a CPS reading (the
    /// inverse of [`TsMeasurement::to_reading`]).
    pub fn from_reading(reading: &Reading, instrument: &Instrument) -> Self {
        Self {
            slope_raw_m: reading.slope_m - instrument.prism_constant_m,
            hz_rad: (-reading.azimuth_rad).rem_euclid(std::f64::consts::TAU),
            v_rad: std::f64::consts::FRAC_PI_2 - reading.elevation_rad,
            status: TsStatus::Ok,
        }
    }
}

/// A total station with automatic target recognition.
pub trait TotalStation {
    /// The device's name for messages.
    fn name(&self) -> &str;
    /// Aims at the target and measures it.
    fn measure(&mut self, target: &Target) -> Result<TsMeasurement>;
}

/// One 2D scan ("slice") of a single-plane range finder, in the LMS-2xx
/// convention: value i is at angle `start_rad + i · step_rad` in the
/// scanner's plane, counter-clockwise from the scanner's right (x) towards
/// its front (y); values ≥ `max_valid` are the protocol's no-return codes.
#[derive(Debug, Clone, PartialEq)]
pub struct Slice {
    /// Angle of value 0, radians.
    pub start_rad: f64,
    /// Angle between values, radians.
    pub step_rad: f64,
    /// Raw values in counts.
    pub values: Vec<u16>,
    /// Metres per count (0.001 in mm mode, 0.01 in cm mode).
    pub metres_per_count: f64,
    /// First value that is not a distance (e.g. 0x1FF7 in the 8 m mode).
    pub max_valid: u16,
}

impl Slice {
    /// Range of value `i`, metres, or `None` for a no-return code.
    pub fn range_m(&self, i: usize) -> Option<f64> {
        let v = *self.values.get(i)?;
        (v < self.max_valid).then(|| f64::from(v) * self.metres_per_count)
    }

    /// Beam angle of value `i`, radians.
    pub fn angle_rad(&self, i: usize) -> f64 {
        self.start_rad + i as f64 * self.step_rad
    }
}

/// A single-plane laser range finder (SICK LMS-2xx and alike).
pub trait RangeFinder2D {
    /// The device's name for messages.
    fn name(&self) -> &str;
    /// Takes one slice.
    fn scan(&mut self) -> Result<Slice>;
}

/// How the 2D scanner is turned to sweep 3D.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeadKind {
    /// CPS-V: the scan plane is vertical (beam 0 points down, beam 90° points
    /// horizontally along the table's zero direction, 180° up) and the table
    /// turns it about the vertical axis through 360°.
    RotatingTable,
    /// AIS 3D: the scan plane is horizontal (beam 0 right, 90° forward,
    /// 180° left) and the mount pitches it about the left (y) axis, positive
    /// up, over ±60°.
    PitchingMount,
}

impl HeadKind {
    /// The head angles of a full 3D scan with `slices` slices: 360°/n steps
    /// for the rotating table, n evenly spaced angles over −60°…+60° for the
    /// pitching mount.
    pub fn slice_angles(&self, slices: usize) -> Vec<f64> {
        match self {
            HeadKind::RotatingTable => (0..slices).map(|i| i as f64 * std::f64::consts::TAU / slices as f64).collect(),
            HeadKind::PitchingMount => {
                let span = 120f64.to_radians();
                let n = slices.max(2);
                (0..slices).map(|i| -span / 2.0 + i as f64 * span / (n - 1) as f64).collect()
            }
        }
    }

    /// `head_from_scanner` at head angle `angle_rad`.
    pub fn head_from_scanner(&self, angle_rad: f64) -> Isometry3<f64> {
        let mount = match self {
            // x_s → −z (down), y_s → +x (forward), z_s → −y.
            HeadKind::RotatingTable => Rotation3::from_basis_unchecked(&[-Vector3::z(), Vector3::x(), -Vector3::y()]),
            // x_s → −y (right), y_s → +x (forward), z_s → +z.
            HeadKind::PitchingMount => Rotation3::from_basis_unchecked(&[-Vector3::y(), Vector3::x(), Vector3::z()]),
        };
        let turn = match self {
            HeadKind::RotatingTable => Rotation3::from_axis_angle(&Vector3::z_axis(), angle_rad),
            // Pitch up: rotate about +y by −angle so that +x rises.
            HeadKind::PitchingMount => Rotation3::from_axis_angle(&Vector3::y_axis(), -angle_rad),
        };
        Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_rotation_matrix(&(turn * mount)))
    }
}

/// The mechanism that turns the 2D scanner.
pub trait ScanHead {
    /// Which mechanism it is.
    fn kind(&self) -> HeadKind;
    /// Turns to `angle_rad` and returns the angle actually reached.
    fn move_to(&mut self, angle_rad: f64) -> Result<f64>;
}

/// Roll and pitch of the parent's body from its tilt sensor, radians.
/// `world_from_body = T(x) · Rz(θ) · Ry(pitch) · Rx(roll)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Tilt {
    /// Roll about the body's forward (x) axis, radians.
    pub roll_rad: f64,
    /// Pitch about the body's left (y) axis, radians (positive: nose down,
    /// right-handed about +y).
    pub pitch_rad: f64,
}

impl Tilt {
    /// `world_from_body` for a CPS pose (position, heading) and this tilt.
    pub fn world_from_body(&self, pose: &ParentPose) -> Isometry3<f64> {
        let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), pose.heading_rad)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), self.pitch_rad)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.roll_rad);
        Isometry3::from_parts(Translation3::from(pose.position.coords), r)
    }
}

/// A two-axis inclinometer.
pub trait TiltSensor {
    /// The device's name for messages.
    fn name(&self) -> &str;
    /// Reads roll and pitch.
    fn read(&mut self) -> Result<Tilt>;
}

/// A planar pose a robot drives to: x, y (m) in the world frame and heading
/// (rad, counter-clockwise from +x).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarPose {
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// Heading, radians.
    pub heading_rad: f64,
}

impl From<&ParentPose> for PlanarPose {
    /// The horizontal part of a CPS pose: x, y and heading.
    fn from(p: &ParentPose) -> Self {
        Self { x_m: p.position.x, y_m: p.position.y, heading_rad: p.heading_rad }
    }
}

/// What a drive reports after a move: the pose it believes it reached by
/// dead reckoning and the distance it travelled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Odometry {
    /// Dead-reckoned pose.
    pub pose: PlanarPose,
    /// Distance driven, metres.
    pub distance_m: f64,
}

/// A robot's drive.
pub trait Drive {
    /// The device's name for messages.
    fn name(&self) -> &str;
    /// Drives to `target` (as the robot believes its position) and reports
    /// odometry.
    fn move_to(&mut self, target: &PlanarPose) -> Result<Odometry>;
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    #[test]
    fn measurement_reading_round_trip() {
        let inst = Instrument { prism_constant_m: -0.0344, ..Instrument::default() };
        let r = Reading { slope_m: 12.5, azimuth_rad: 0.7, elevation_rad: -0.1 };
        let m = TsMeasurement::from_reading(&r, &inst);
        assert!((m.hz_rad - (std::f64::consts::TAU - 0.7)).abs() < 1e-12, "clockwise Hz");
        assert!((m.v_rad - (std::f64::consts::FRAC_PI_2 + 0.1)).abs() < 1e-12, "zenith angle");
        let back = m.to_reading(&inst);
        assert!((back.to_vector() - r.to_vector()).norm() < 1e-12);
    }

    /// Beam 0 down, beam 90° forward, beam 180° up for the rotating table at
    /// table angle 0; at 90° the forward beam points left.
    #[test]
    fn head_frames() {
        let beam = |deg: f64| Point3::new(deg.to_radians().cos(), deg.to_radians().sin(), 0.0);
        let t0 = HeadKind::RotatingTable.head_from_scanner(0.0);
        assert!((t0 * beam(0.0) - Point3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        assert!((t0 * beam(90.0) - Point3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
        assert!((t0 * beam(180.0) - Point3::new(0.0, 0.0, 1.0)).norm() < 1e-12);
        let t90 = HeadKind::RotatingTable.head_from_scanner(std::f64::consts::FRAC_PI_2);
        assert!((t90 * beam(90.0) - Point3::new(0.0, 1.0, 0.0)).norm() < 1e-12);
        let p = HeadKind::PitchingMount.head_from_scanner(30f64.to_radians());
        let fwd = p * beam(90.0);
        assert!((fwd - Point3::new(30f64.to_radians().cos(), 0.0, 30f64.to_radians().sin())).norm() < 1e-12, "{fwd}");
        assert!((p * beam(0.0) - Point3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
        assert_eq!(HeadKind::PitchingMount.slice_angles(3), vec![-60f64.to_radians(), 0.0, 60f64.to_radians()]);
    }

    #[test]
    fn tilt_frame_order() {
        let pose = ParentPose::new(1.0, 2.0, 3.0, std::f64::consts::FRAC_PI_2);
        let t = Tilt { roll_rad: 0.0, pitch_rad: 0.1 };
        // Pitch about +y tips the body's forward axis down, then the heading turns it to +y.
        let fwd = t.world_from_body(&pose) * Point3::new(1.0, 0.0, 0.0);
        assert!((fwd - Point3::new(1.0, 2.0 + 0.1f64.cos(), 3.0 - 0.1f64.sin())).norm() < 1e-12, "{fwd}");
    }
}
