//! `report.json` ([`RunReport`]) with its `fusion` ([`FusionReport`], also
//! `fusion/<mode>/fusion.json` of `fuse`).

use serde::{Deserialize, Serialize};

use super::Document;
use super::adjustment::AdjustmentOutcome;
use super::pipe::PipeReport;
use super::records::{Link, Matrix4Rows, Pose};

/// `report.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct RunReport {
    /// `[mission] name`.
    pub mission: String,
    /// The simulator's seed.
    pub seed: u64,
    /// `sim` or `serial`.
    pub backend: String,
    /// The scene's name.
    pub scene: String,
    /// The coordinate reference system of every coordinate here and of
    /// the cloud files (`[site]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crs: Option<CrsReport>,
    /// Every station, start included.
    pub stations: Vec<StationReport>,
    /// The last station's figures.
    #[serde(rename = "final")]
    pub final_: FinalReport,
    /// How the scans were fused.
    pub fusion: FusionReport,
    /// The pipe inspection, with `[pipe]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pipe: Option<PipeReport>,
    /// Whether the acceptance held.
    pub accepted: bool,
    /// Where the wall time went, seconds.
    pub timings: Timings,
    /// The network adjustment of the journal's readings (with a total
    /// station): the same object as `adjust --json`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adjustment: Option<AdjustmentOutcome>,
    /// Every reading measured again because it failed a fix's field test
    /// or lay grossly off its formation point (issue 34, S7), in order. The
    /// superseded readings stay in the journal.
    #[serde(default)]
    pub remeasured: Vec<Remeasured>,
}

/// A reading measured again (`remeasured[]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Remeasured {
    /// Dance cycle (0: at the start).
    pub cycle: usize,
    /// The point: a child's name or `control point "NAME"`.
    pub point: String,
    /// The attempt taken: 1 for the first re-measurement.
    pub attempt: u32,
    /// Why, in words.
    pub why: String,
}

/// A coordinate reference system in a report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct CrsReport {
    /// `EPSG:NNNN`, the WKT's name or the local frame's.
    pub name: String,
    /// The EPSG code, if it has one.
    pub epsg: Option<u16>,
    /// Whether it is a local engineering frame (not georeferenced).
    pub local: bool,
    /// OGC WKT 1, as the LAS and E57 files carry it.
    pub wkt: String,
}

impl CrsReport {
    /// The report of `crs`.
    pub fn new(crs: &scanner::io::Crs) -> Self {
        Self { name: crs.name.clone(), epsg: crs.epsg, local: crs.is_local(), wkt: crs.wkt.clone() }
    }
}

/// One station in `report.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct StationReport {
    /// Station index (0 = start).
    pub index: usize,
    /// The estimate.
    pub pose: Pose,
    /// Its 4×4 covariance (x, y, z, θ), m², m·rad, rad².
    pub covariance: Matrix4Rows,
    /// The prediction's.
    pub predicted_covariance: Matrix4Rows,
    /// The simulator's truth.
    pub truth: Option<Pose>,
    /// Horizontal error against the truth, metres.
    pub error_m: Option<f64>,
    /// The scan taken here.
    pub scan: Option<String>,
}

/// `report.json`'s `final`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FinalReport {
    /// Path length (the true path on the simulator, the estimated one on
    /// serial ports), metres.
    pub distance_m: f64,
    /// The last station's σx² + σy², m².
    pub sigma_xy2_m2: f64,
    /// Its horizontal error against the truth, metres.
    pub error_xy_m: Option<f64>,
    /// Deprecated: the same as `error_drift_percent` (`predict` used the
    /// name for a predicted σ).
    #[schemars(extend("deprecated" = true))]
    pub drift_percent: Option<f64>,
    /// That error in % of the distance.
    #[serde(default)]
    pub error_drift_percent: Option<f64>,
}

/// Where the wall time went, seconds (positioning is the rest of `wall_s`).
#[derive(Debug, Default, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Timings {
    /// The whole run.
    pub wall_s: f64,
    /// Simulating the 3D scans.
    pub scan_s: f64,
    /// Writing `scans/`.
    pub scan_files_s: f64,
    /// Fusion of the scans.
    pub fusion_s: f64,
    /// Writing the merged cloud files.
    pub cloud_files_s: f64,
    /// Recording `mission.rrd` (on the mission's thread; scans are thinned
    /// and logged on a worker, waited for at the end).
    pub recording_s: f64,
    /// The pipe inspection (fit, deviation map, anomalies) and its file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pipe_s: Option<f64>,
}

/// How the scans were fused: per scan the fused pose, its RMSE and (on the
/// simulator) the errors of it and of the direct fusion; their RMS.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FusionReport {
    /// `direct`, `icp` or `cps-icp`.
    pub mode: String,
    /// ICP runs.
    pub matches: usize,
    /// False when `icp`'s simultaneous pass abandoned a queue at `[fusion]
    /// max_matches_per_scan` with its scans still moving (true in the other
    /// modes, and in reports written before the key).
    #[serde(default = "yes")]
    pub settled: bool,
    /// Every scan.
    pub scans: Vec<FusedScanReport>,
    /// RMS horizontal error of the fused poses (simulator).
    pub rms_error_xy_m: Option<f64>,
    /// … of the direct fusion's.
    pub direct_rms_error_xy_m: Option<f64>,
    /// Wall time, seconds (`fuse` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
    /// The pipe inspection of the re-fused cloud (`fuse` with `[pipe]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pipe: Option<PipeReport>,
    /// The last round's ICP matches, used or rejected (empty for `direct`).
    #[serde(default)]
    pub links: Vec<Link>,
}

/// One scan in a [`FusionReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FusedScanReport {
    /// The parent station.
    pub station: usize,
    /// Its file, relative to the run directory.
    pub file: String,
    /// The fused body pose (heading = yaw).
    pub pose: Pose,
    /// RMSE of its last ICP match.
    pub rmse_m: Option<f64>,
    /// The fused 6-DoF pose: `world_from_body`, 4×4 row-major (metres).
    #[serde(default)]
    pub world_from_body: [[f64; 4]; 4],
    /// Roll, pitch and yaw of the fused pose (x-y-z Euler angles, yaw =
    /// `pose.heading_rad`), radians.
    #[serde(default)]
    pub roll_pitch_yaw_rad: [f64; 3],
    /// The fused pose's 6×6 covariance, order (ω_x, ω_y, ω_z, x, y, z) —
    /// rotation (rad) then translation (m), left perturbation, world frame,
    /// as `register`'s — where the fusion estimates one: `cps-icp`'s;
    /// `icp`'s last match (its partners held) with odometry's step (0.1 m,
    /// 1°) along what it cannot see, zero for the first scan.
    #[serde(default)]
    pub covariance: Option<[[f64; 6]; 6]>,
    /// `icp` with `[fusion] degeneracy_ratio`: the directions the scan's
    /// last match could not see, left where odometry put it (unit vectors,
    /// order of the covariance, world frame); empty otherwise.
    #[serde(default)]
    pub degenerate_directions: Vec<[f64; 6]>,
    /// Horizontal error of the fused pose (simulator).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_xy_m: Option<f64>,
    /// … of the direct fusion's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direct_error_xy_m: Option<f64>,
    /// Heading error of the fused pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_heading_rad: Option<f64>,
    /// … of the direct fusion's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direct_error_heading_rad: Option<f64>,
}

impl Document for RunReport {
    const NAME: &'static str = "report";
    const VERSION: u32 = 1;
}

impl Document for FusionReport {
    const NAME: &'static str = "fusion";
    const VERSION: u32 = 1;
}

/// `true`: serde's default for [`FusionReport::settled`].
fn yes() -> bool {
    true
}
