//! The records every document shares: a position, a pose, an error
//! ellipse, an ICP link, and matrices as rows.

use nalgebra::{DMatrix, Matrix2, SMatrix};
use serde::{Deserialize, Serialize};

/// A position: x, y, z, metres (the shape of every position in every
/// document; a pose adds `heading_rad`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Position {
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// z, metres.
    pub z_m: f64,
}

impl From<&nalgebra::Point3<f64>> for Position {
    fn from(p: &nalgebra::Point3<f64>) -> Self {
        Self { x_m: p.x, y_m: p.y, z_m: p.z }
    }
}

/// A pose: x, y, z (m) and heading (rad).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Pose {
    /// x, metres.
    pub x_m: f64,
    /// y, metres.
    pub y_m: f64,
    /// z, metres.
    pub z_m: f64,
    /// Heading, radians.
    pub heading_rad: f64,
}

impl From<&cps::ParentPose> for Pose {
    fn from(p: &cps::ParentPose) -> Self {
        Self { x_m: p.position.x, y_m: p.position.y, z_m: p.position.z, heading_rad: p.heading_rad }
    }
}

impl From<&Pose> for cps::ParentPose {
    fn from(p: &Pose) -> Self {
        cps::ParentPose::new(p.x_m, p.y_m, p.z_m, p.heading_rad)
    }
}

/// A horizontal error ellipse, metres, orientation counter-clockwise from +x.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Ellipse {
    /// Semi-major axis.
    pub semi_major_m: f64,
    /// Semi-minor axis.
    pub semi_minor_m: f64,
    /// Direction of the major axis, radians.
    pub orientation_rad: f64,
}

impl From<cps::ErrorEllipse> for Ellipse {
    fn from(e: cps::ErrorEllipse) -> Self {
        Self { semi_major_m: e.semi_major_m, semi_minor_m: e.semi_minor_m, orientation_rad: e.orientation_rad }
    }
}

impl Ellipse {
    /// The 95 % ellipse of a covariance's (x, y) block.
    pub fn of_95(cov: &Matrix2<f64>) -> Self {
        cps::ErrorEllipse::from_covariance(cov).scaled(cps::CHI2_2D_95_SQRT).into()
    }
}

/// One ICP match of a fusion (`report.json`'s `fusion.links`) or of
/// `match` (`poses.json`'s `links`): a scan against its partners.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Link {
    /// The matched (source) scan: its station in a run, its index into
    /// `scans` in `match`.
    pub source: usize,
    /// The scans it was matched against (stations, or indices).
    pub targets: Vec<usize>,
    /// Correspondences at the start of the match (`match`'s graph mode).
    #[serde(default)]
    pub overlap: Option<usize>,
    /// Correspondences within the gate at the end, when ICP ran.
    pub correspondences: Option<usize>,
    /// RMS residual, metres, when ICP ran.
    pub rmse_m: Option<f64>,
    /// Whether ICP converged.
    pub converged: bool,
    /// ICP iterations of the match (0 when it did not run).
    #[serde(default)]
    pub iterations: usize,
    /// Whether the match is used.
    pub accepted: bool,
    /// Why not, when rejected.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The directions this match could not see, held where the start put
    /// them: unit vectors in the order (ω_x, ω_y, ω_z, x, y, z) of the
    /// covariances, in the world's axes, a motion of the source scan about
    /// its partner's origin; empty when it saw everything (or did not
    /// test: a run's `direct` and `cps-icp`).
    #[serde(default)]
    pub degenerate_directions: Vec<[f64; 6]>,
    /// For a link that disagrees with the others (`match`'s graph mode):
    /// the shortest cycle of used links it closes — rejected (`reason`),
    /// or accepted when no other cycle can tell which of the cycle's links
    /// is wrong and the cycle does not miss grossly (over 5° or 5 % of the
    /// scan's radius): the variance factor then carries the miss.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cycle: Option<Cycle>,
}

/// A cycle of used links that a link disagreeing with the others closes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Cycle {
    /// The scans from the link's target round to its source along used
    /// links (indices into `scans`); the link closes the cycle.
    pub scans: Vec<usize>,
    /// How far the path and the link disagree: the turn, degrees.
    pub angle_deg: f64,
    /// … and how far that moves the source's points (their centroid's
    /// displacement), metres.
    pub translation_m: f64,
}

/// A 4×4 matrix, row-major.
pub type Matrix4Rows = [[f64; 4]; 4];

/// A fixed-size matrix as rows.
pub fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> [[f64; C]; R] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

/// A matrix of any size as rows.
pub fn nested(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// Rows as a 4×4 matrix.
pub fn matrix4(r: &Matrix4Rows) -> nalgebra::Matrix4<f64> {
    nalgebra::Matrix4::from_fn(|i, j| r[i][j])
}

/// Unit twists ξ = (ω, v) as rows.
pub fn directions(d: &[nalgebra::Vector6<f64>]) -> Vec<[f64; 6]> {
    d.iter().map(|v| std::array::from_fn(|i| v[i])).collect()
}
