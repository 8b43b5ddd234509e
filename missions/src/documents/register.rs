//! `register --json`: one pairwise registration.

use serde::Serialize;

use super::Document;

/// `register --json`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct RegisterReport {
    /// The source scan's pose in the target's frame, 4×4 row-major.
    pub target_from_source: [[f64; 4]; 4],
    /// Whether ICP converged.
    pub converged: bool,
    /// ICP iterations.
    pub iterations: usize,
    /// Correspondences within the gate at the end.
    pub inliers: usize,
    /// Their RMS residual, metres.
    pub rmse_m: f64,
    /// Wall-clock time, seconds.
    pub seconds: f64,
    /// 6×6, order (ωx, ωy, ωz, vx, vy, vz), radians and metres, left
    /// perturbation in the target frame.
    pub covariance: Vec<[f64; 6]>,
}

impl Document for RegisterReport {
    const NAME: &'static str = "register";
    const VERSION: u32 = 1;
}
