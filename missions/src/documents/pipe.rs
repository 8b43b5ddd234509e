//! The pipe inspection as reported (`report.json`'s and `fusion.json`'s
//! `pipe`).

use serde::{Deserialize, Serialize};

/// A tube: its axis ends and radius, metres, world frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TubeReport {
    /// One end of the axis.
    pub axis_from_m: [f64; 3],
    /// The other end.
    pub axis_to_m: [f64; 3],
    /// The radius.
    pub radius_m: f64,
}

/// Distribution of the deviations, metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct DeviationStats {
    /// Points mapped.
    pub points: usize,
    /// Mean deviation.
    pub mean_m: f64,
    /// RMS deviation.
    pub rms_m: f64,
    /// Smallest (most inside).
    pub min_m: Option<f64>,
    /// 1st percentile.
    pub p01_m: Option<f64>,
    /// 99th percentile.
    pub p99_m: Option<f64>,
    /// Largest (most outside).
    pub max_m: Option<f64>,
    /// Points beyond the threshold either way.
    pub beyond_threshold: usize,
}

/// One anomaly as reported.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct AnomalyReport {
    /// `intrusion` or `bulge`.
    pub kind: String,
    /// Its points.
    pub points: usize,
    /// Their centroid.
    pub centroid_m: [f64; 3],
    /// Where it starts along the fitted axis from its `from` end.
    pub axial_from_m: f64,
    /// Where it ends.
    pub axial_to_m: f64,
    /// Its clock position, "hh:mm".
    pub clock: String,
    /// The same as an hour in (0, 12].
    pub clock_hour: f64,
    /// Bounding box corner.
    pub bounds_min_m: [f64; 3],
    /// Opposite corner.
    pub bounds_max_m: [f64; 3],
    /// The box's size.
    pub size_m: [f64; 3],
    /// Depth: the 95th percentile of its points' |deviation|.
    pub depth_m: f64,
    /// The largest |deviation|.
    pub max_deviation_m: f64,
}

/// The pipe inspection as reported (`report.json`'s and `fusion.json`'s
/// `pipe`): the fitted tube and its anomalies, or why there is no fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum PipeReport {
    /// The fit and the deviation map.
    Fitted(Box<PipeFitted>),
    /// The fit failed: why.
    Failed {
        /// The reason.
        error: String,
    },
}

/// A fitted pipe's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PipeFitted {
    /// The nominal tube.
    pub nominal: TubeReport,
    /// The fitted tube.
    pub fitted: TubeReport,
    /// Fitted minus nominal radius.
    pub radius_change_m: f64,
    /// Angle between the axes, degrees.
    pub axis_tilt_deg: f64,
    /// Fit iterations.
    pub iterations: usize,
    /// Whether the fit converged.
    pub converged: bool,
    /// Points within the gate.
    pub inliers: usize,
    /// RMS of their radial residuals.
    pub rmse_m: f64,
    /// The gate.
    pub gate_m: f64,
    /// `[pipe] threshold_m`.
    pub threshold_m: f64,
    /// `[pipe] link_m`.
    pub link_m: f64,
    /// `[pipe] min_points`.
    pub min_points: usize,
    /// The deviations' distribution.
    pub deviations: DeviationStats,
    /// The deviation map's file.
    pub deviation_file: String,
    /// The anomalies, largest first.
    pub anomalies: Vec<AnomalyReport>,
}
