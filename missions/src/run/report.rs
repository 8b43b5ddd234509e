//! The reports a run writes, typed: `report.json` ([`RunReport`]) with its
//! `fusion` ([`FusionReport`], also `fusion/<mode>/fusion.json` of `fuse`)
//! and `pipe`, and `stations.csv`.

use std::path::Path;

use anyhow::{Context, Result};
use cps::ParentPose;
use nalgebra::Matrix4;
use serde::{Deserialize, Serialize};

use super::adjust::{AdjustmentOutcome, AdjustmentReport};
use super::fuse::{Fused, ScanView, error_heading, error_xy};
use super::inspection::PipeReport;
use super::journal::{Matrix4Record, PoseRecord, matrix_record};
use crate::mission::Mission;
use crate::view::document::Document;

/// One parent station of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct StationRecord {
    /// Station index (0 = start).
    pub index: usize,
    /// The CPS estimate.
    pub pose: ParentPose,
    /// Its covariance (x, y, z, θ).
    pub covariance: Matrix4<f64>,
    /// The prediction's covariance for this station.
    pub predicted_covariance: Matrix4<f64>,
    /// The simulator's true pose (sim backend only).
    pub truth: Option<ParentPose>,
    /// Horizontal error against the truth, metres (sim backend only).
    pub error_xy_m: Option<f64>,
    /// The scan file taken here, relative to the run directory.
    pub scan: Option<String>,
}

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
    pub pose: PoseRecord,
    /// Its 4×4 covariance (x, y, z, θ), m², m·rad, rad².
    pub covariance: Matrix4Record,
    /// The prediction's.
    pub predicted_covariance: Matrix4Record,
    /// The simulator's truth.
    pub truth: Option<PoseRecord>,
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
    pub links: Vec<LinkReport>,
}

/// One ICP match in a [`FusionReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct LinkReport {
    /// The matched (source) scan's station.
    pub source: usize,
    /// The stations of the scans it was matched against.
    pub targets: Vec<usize>,
    /// Correspondences within the gate, when ICP ran.
    pub correspondences: Option<usize>,
    /// RMS residual, metres, when ICP ran.
    pub rmse_m: Option<f64>,
    /// Whether ICP converged.
    pub converged: bool,
    /// Whether the match is used in the fused poses.
    pub accepted: bool,
    /// Why not, when rejected.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// `icp` with `[fusion] degeneracy_ratio`: the directions the match
    /// could not see, held where odometry put the scan — unit vectors in
    /// the order (ω_x, ω_y, ω_z, x, y, z) of the covariance, world frame;
    /// empty when it saw everything (and in the other modes).
    #[serde(default)]
    pub degenerate_directions: Vec<[f64; 6]>,
}

/// One scan in a [`FusionReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FusedScanReport {
    /// The parent station.
    pub station: usize,
    /// Its file, relative to the run directory.
    pub file: String,
    /// The fused body pose (heading = yaw).
    pub pose: PoseRecord,
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

impl FusionReport {
    /// The report of `fused` over `views`.
    pub fn new(views: &[ScanView], fused: &Fused) -> Self {
        let mut sq = [0.0, 0.0];
        let mut known = 0usize;
        let scans = views
            .iter()
            .zip(&fused.scans)
            .map(|(v, f)| {
                let t = f.world_from_body.translation.vector;
                let (roll, pitch, yaw) = f.world_from_body.rotation.euler_angles();
                let m = f.world_from_body.to_homogeneous();
                let mut s = FusedScanReport {
                    station: v.station,
                    file: v.file.clone(),
                    pose: PoseRecord { x_m: t.x, y_m: t.y, z_m: t.z, heading_rad: yaw },
                    rmse_m: f.rmse_m,
                    world_from_body: std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)])),
                    roll_pitch_yaw_rad: [roll, pitch, yaw],
                    covariance: f.covariance.map(|c| std::array::from_fn(|r| std::array::from_fn(|k| c[(r, k)]))),
                    degenerate_directions: directions(&f.unobservable),
                    error_xy_m: None,
                    direct_error_xy_m: None,
                    error_heading_rad: None,
                    direct_error_heading_rad: None,
                };
                if let Some(truth) = &v.truth {
                    let (e, d) = (error_xy(&f.world_from_body, truth), error_xy(&v.direct(), truth));
                    s.error_xy_m = Some(e);
                    s.direct_error_xy_m = Some(d);
                    s.error_heading_rad = Some(error_heading(&f.world_from_body, truth));
                    s.direct_error_heading_rad = Some(error_heading(&v.direct(), truth));
                    sq[0] += e * e;
                    sq[1] += d * d;
                    known += 1;
                }
                s
            })
            .collect();
        let rms = |s: f64| (known > 0).then(|| (s / known as f64).sqrt());
        Self {
            mode: fused.mode.name().into(),
            matches: fused.matches,
            scans,
            rms_error_xy_m: rms(sq[0]),
            direct_rms_error_xy_m: rms(sq[1]),
            seconds: None,
            pipe: None,
            links: fused
                .links
                .iter()
                .map(|l| LinkReport {
                    source: l.source,
                    targets: l.targets.clone(),
                    correspondences: l.correspondences,
                    rmse_m: l.rmse_m,
                    converged: l.converged,
                    accepted: l.rejected.is_none(),
                    reason: l.rejected.clone(),
                    degenerate_directions: directions(&l.unobservable),
                })
                .collect(),
        }
    }
}

impl StationReport {
    fn new(s: &StationRecord) -> Self {
        Self {
            index: s.index,
            pose: (&s.pose).into(),
            covariance: matrix_record(&s.covariance),
            predicted_covariance: matrix_record(&s.predicted_covariance),
            truth: s.truth.as_ref().map(PoseRecord::from),
            error_m: s.error_xy_m,
            scan: s.scan.clone(),
        }
    }
}

impl RunReport {
    /// The report of a run's stations and results.
    pub fn new(
        mission: &Mission,
        stations: &[StationRecord],
        fusion: FusionReport,
        pipe: Option<PipeReport>,
        accepted: bool,
        timings: Timings,
        remeasured: Vec<Remeasured>,
    ) -> Result<Self> {
        let last = stations.last().context("a run has at least the start station")?;
        // Along the true path on the simulator, the estimated one on serial ports.
        let at = |s: &StationRecord| s.truth.unwrap_or(s.pose).position;
        let distance_m: f64 = stations.windows(2).map(|w| (at(&w[1]) - at(&w[0])).norm()).sum();
        let drift = last.error_xy_m.map(|e| if distance_m > 0.0 { 100.0 * e / distance_m } else { 0.0 });
        Ok(Self {
            mission: mission.name.clone(),
            seed: mission.backend.seed,
            backend: if mission.backend.serial.is_some() { "serial" } else { "sim" }.into(),
            scene: mission.backend.scene.clone(),
            crs: Some(CrsReport::new(&mission.crs)),
            stations: stations.iter().map(StationReport::new).collect(),
            final_: FinalReport {
                distance_m,
                sigma_xy2_m2: cps::sigma_xy2(&last.covariance),
                error_xy_m: last.error_xy_m,
                drift_percent: drift,
                error_drift_percent: drift,
            },
            fusion,
            pipe,
            accepted,
            timings,
            adjustment: None,
            remeasured,
        })
    }
}

impl Document for RunReport {
    const NAME: &'static str = "report";
    const VERSION: u32 = 1;
}

impl Document for FusionReport {
    const NAME: &'static str = "fusion";
    const VERSION: u32 = 1;
}

/// `stations.csv`: one row per station, the header with units; with an
/// adjustment its coordinates, σ and 95 % ellipse (a, b, orientation
/// counter-clockwise from +x) at the end of each row.
pub fn write_stations_csv(path: &Path, stations: &[StationRecord], adjusted: Option<&AdjustmentReport>) -> Result<()> {
    let mut csv = String::from(
        "index,x_m,y_m,z_m,heading_rad,sigma_x_m,sigma_y_m,sigma_z_m,sigma_heading_rad,predicted_sigma_xy_m,true_x_m,true_y_m,true_z_m,true_heading_rad,error_xy_m,\
         adjusted_x_m,adjusted_y_m,adjusted_z_m,adjusted_heading_rad,adjusted_sigma_x_m,adjusted_sigma_y_m,adjusted_sigma_z_m,adjusted_sigma_heading_rad,adjusted_sigma_xy_m,ellipse_a95_m,ellipse_b95_m,ellipse_orientation_rad\n",
    );
    for s in stations {
        let sd = |k: usize| s.covariance[(k, k)].max(0.0).sqrt();
        let p = &s.pose;
        // Empty cells without a truth (serial ports).
        let truth = match (&s.truth, s.error_xy_m) {
            (Some(t), Some(e)) => {
                format!("{},{},{},{},{}", t.position.x, t.position.y, t.position.z, t.heading_rad, e)
            }
            _ => ",,,,".to_string(),
        };
        let adj = adjusted.and_then(|a| a.stations.get(s.index)).map_or_else(
            || ",,,,,,,,,,,".to_string(),
            |a| {
                let c = &a.covariance;
                let sd = |k: usize| c[k][k].max(0.0).sqrt();
                format!(
                    "{},{},{},{},{},{},{},{},{},{},{},{}",
                    a.x_m,
                    a.y_m,
                    a.z_m,
                    a.heading_rad,
                    sd(0),
                    sd(1),
                    sd(2),
                    sd(3),
                    a.sigma_xy_m,
                    a.ellipse_95.semi_major_m,
                    a.ellipse_95.semi_minor_m,
                    a.ellipse_95.orientation_rad
                )
            },
        );
        csv += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{adj}\n",
            s.index,
            p.position.x,
            p.position.y,
            p.position.z,
            p.heading_rad,
            sd(0),
            sd(1),
            sd(2),
            sd(3),
            cps::sigma_xy2(&s.predicted_covariance).sqrt(),
            truth
        );
    }
    scanner::io::replace_file(path, csv.as_bytes()).with_context(|| format!("writing {}", path.display()))
}

/// Blind directions (unit ξ = (ω, v)) as JSON rows.
pub(crate) fn directions(d: &[nalgebra::Vector6<f64>]) -> Vec<[f64; 6]> {
    d.iter().map(|v| std::array::from_fn(|i| v[i])).collect()
}
