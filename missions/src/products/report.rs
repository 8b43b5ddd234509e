//! The reports a run writes: `report.json` and `fusion.json` made from the
//! run's stations and fused scans ([`crate::documents::run`]), and
//! `stations.csv`.

use std::path::Path;

use anyhow::{Context, Result};
use cps::ParentPose;
use nalgebra::Matrix4;

use super::fuse::{Fused, ScanView, error_heading, error_xy};
use crate::documents::adjustment::AdjustmentReport;
use crate::documents::pipe::PipeReport;
use crate::documents::records::{Link, Pose, directions, rows};
use crate::documents::run::{
    CrsReport, FinalReport, FusedScanReport, FusionReport, Remeasured, RunReport, StationReport, Timings,
};
use crate::mission::Mission;

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
                    pose: Pose { x_m: t.x, y_m: t.y, z_m: t.z, heading_rad: yaw },
                    rmse_m: f.rmse_m,
                    world_from_body: rows(&m),
                    roll_pitch_yaw_rad: [roll, pitch, yaw],
                    covariance: f.covariance.as_ref().map(rows),
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
            settled: fused.settled,
            scans,
            rms_error_xy_m: rms(sq[0]),
            direct_rms_error_xy_m: rms(sq[1]),
            seconds: None,
            pipe: None,
            links: fused
                .links
                .iter()
                .map(|l| Link {
                    source: l.source,
                    targets: l.targets.clone(),
                    overlap: None,
                    correspondences: l.correspondences,
                    rmse_m: l.rmse_m,
                    converged: l.converged,
                    iterations: l.iterations,
                    accepted: l.rejected.is_none(),
                    reason: l.rejected.clone(),
                    degenerate_directions: directions(&l.unobservable),
                    cycle: None,
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
            covariance: rows(&s.covariance),
            predicted_covariance: rows(&s.predicted_covariance),
            truth: s.truth.as_ref().map(Pose::from),
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
