//! Fusion of a mission's scans by `[fusion] mode` — at the end of `run`, or
//! afterwards from a run directory with `cps-survey fuse RUN_DIR --mode`.
//!
//! - `direct`: each scan with its CPS pose and measured tilt;
//! - `icp`: scan matching alone — simultaneous matching (seed 000 §4.2)
//!   from the odometry's guesses (where each drive believed it stopped, with
//!   the measured tilt), the first scan held at its CPS pose;
//! - `cps-icp`: the scans' CPS poses as a joint prior (every station's 4×4
//!   covariance and the cross-covariances the leapfrog chain creates between
//!   stations, and the tilt sensor's σ: [`fusion::graph::JointPrior::cps`])
//!   and ICP between overlapping scans as relative measurements, adjusted
//!   together ([`fusion::multiview::register_with_priors`]).
//!
//! A run's scans are in its journal: each `scan` event names its file (body
//! frame, 3DTK layout), the `tilt` event before it holds the tilt, the
//! `fix` event of that station the CPS pose, its covariance and its
//! cross-covariances with the earlier scan stations, and the
//! simulator's state the truth and the drive's believed pose.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use cps::ParentPose;
use fusion::icp::{IcpConfig, Kernel};
use fusion::multiview::{MultiviewConfig, Strategy};
use nalgebra::{Isometry3, Matrix4, Point3};
use scanner::Tilt;
use scanner::io::{Format, PointCloud};
use serde_json::{Value, json};

use crate::mission::{FusionMode, FusionPlan, Mission};

/// One scan of a run with everything fusion needs.
#[derive(Debug, Clone)]
pub struct ScanView {
    /// The parent station it was taken at.
    pub station: usize,
    /// Its file, relative to the run directory.
    pub file: String,
    /// The points in the body frame.
    pub body: Vec<Point3<f32>>,
    /// The CPS pose of the station.
    pub pose: ParentPose,
    /// Its 4×4 covariance (x, y, z, θ).
    pub covariance: Matrix4<f64>,
    /// cov(this station, each earlier scan's station), 4×4 each, in scan
    /// order, as the CPS chain correlates them (shorter or empty where
    /// nothing is known: taken as zero).
    pub cross_covariance: Vec<Matrix4<f64>>,
    /// The measured tilt.
    pub tilt: Tilt,
    /// Where the parent's drive believed it stood (odometry).
    pub odometry: ParentPose,
    /// The simulator's true `world_from_body`, when known.
    pub truth: Option<Isometry3<f64>>,
}

impl ScanView {
    /// `world_from_body` of the direct transformation.
    pub fn direct(&self) -> Isometry3<f64> {
        self.tilt.world_from_body(&self.pose)
    }

    /// `world_from_body` from odometry and the measured tilt.
    pub fn odometry_guess(&self) -> Isometry3<f64> {
        self.tilt.world_from_body(&self.odometry)
    }
}

/// One scan's fused pose.
#[derive(Debug, Clone, PartialEq)]
pub struct FusedScan {
    /// The parent station.
    pub station: usize,
    /// The fused `world_from_body`.
    pub world_from_body: Isometry3<f64>,
    /// RMS residual of the scan's last ICP match, metres (`None` for direct
    /// fusion and for the scan that fixes the frame).
    pub rmse_m: Option<f64>,
}

/// The fusion of a run's scans.
#[derive(Debug, Clone)]
pub struct Fused {
    /// The mode.
    pub mode: FusionMode,
    /// Every scan, in order.
    pub scans: Vec<FusedScan>,
    /// ICP runs.
    pub matches: usize,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Every ICP run iteration by iteration, when asked for (`trace`).
    pub traces: Vec<fusion::multiview::IcpTrace>,
}

/// The tilt sensor's standard deviation the simulator uses (0.01°).
pub const TILT_SIGMA_RAD: f64 = 0.01 * std::f64::consts::PI / 180.0;

/// The ICP settings of `plan` for scans in the body frame whose scanner
/// stands at `scanner_in_body`: back faces rejected.
fn multiview_config(plan: &FusionPlan, strategy: Strategy, scanner_in_body: Point3<f64>) -> MultiviewConfig {
    MultiviewConfig {
        strategy,
        icp: IcpConfig {
            max_correspondence_m: plan.max_correspondence_m,
            max_iterations: plan.max_iterations,
            kernel: if plan.huber_m > 0.0 { Kernel::Huber { width_m: plan.huber_m } } else { Kernel::None },
            reject_back_faces: true,
            source_viewpoint: scanner_in_body,
            ..IcpConfig::default()
        },
        source_voxel_m: plan.voxel_m,
        target_voxel_m: plan.voxel_m / 2.0,
        min_pairs: plan.min_pairs,
        ..MultiviewConfig::default()
    }
}

/// Fuses `views` by `mode` with the settings of `plan`, the scanner at
/// `scanner_in_body` in the body frame the scans are in; `progress(done,
/// total)` is called as scans are matched. With `trace`, every ICP run is
/// kept iteration by iteration ([`Fused::traces`]).
pub fn fuse(
    views: &[ScanView],
    mode: FusionMode,
    plan: &FusionPlan,
    scanner_in_body: Point3<f64>,
    trace: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Fused> {
    let started = Instant::now();
    let scans: Vec<&[Point3<f32>]> = views.iter().map(|v| v.body.as_slice()).collect();
    let mut traces = Vec::new();
    let traced = |mut c: MultiviewConfig| {
        c.icp.trace = trace;
        c
    };
    let (poses, rmse, matches): (Vec<Isometry3<f64>>, Vec<Option<f64>>, usize) = match mode {
        FusionMode::Direct => (views.iter().map(ScanView::direct).collect(), vec![None; views.len()], 0),
        _ if views.is_empty() => (Vec::new(), Vec::new(), 0),
        FusionMode::Icp => {
            // The first scan holds the frame at its CPS pose; the rest start
            // from odometry. A coarse pass, then a fine one from its result.
            let mut guesses: Vec<Isometry3<f64>> = views.iter().map(ScanView::odometry_guess).collect();
            let shift = views[0].direct() * guesses[0].inverse();
            guesses.iter_mut().for_each(|g| *g = shift * *g);
            let mut config = traced(multiview_config(plan, Strategy::Simultaneous, scanner_in_body));
            let coarse = fusion::multiview::register_views(&scans, &guesses, &config, progress)
                .context("ICP fusion (simultaneous matching, coarse pass)")?;
            config.overlap_m = Some(plan.max_correspondence_m);
            config.icp.max_correspondence_m = plan.fine_correspondence_m;
            let r = fusion::multiview::register_views(&scans, &coarse.world_from_scan, &config, progress)
                .context("ICP fusion (simultaneous matching, fine pass)")?;
            traces = coarse.traces.into_iter().chain(r.traces).collect();
            let rmse = r.last_match.iter().map(|m| m.as_ref().map(|m| m.rmse_m)).collect();
            (r.world_from_scan, rmse, coarse.matches + r.matches)
        }
        FusionMode::CpsIcp => {
            let prior = joint_prior(views)?;
            let r = fusion::multiview::register_with_priors(
                &scans,
                &prior,
                &traced(multiview_config(plan, Strategy::Pairwise, scanner_in_body)),
                plan.max_partners,
                plan.icp_variance_factor,
                &[plan.max_correspondence_m, plan.fine_correspondence_m],
                progress,
            )
            .context("CPS+ICP fusion")?;
            let mut rmse = vec![None; views.len()];
            for (_, s, m) in &r.matches {
                rmse[*s] = Some(m.rmse_m);
            }
            traces = r.traces;
            (r.world_from_scan, rmse, r.matches.len())
        }
    };
    let scans = views
        .iter()
        .zip(poses)
        .zip(rmse)
        .map(|((v, world_from_body), rmse_m)| FusedScan { station: v.station, world_from_body, rmse_m })
        .collect();
    Ok(Fused { mode, scans, matches, seconds: started.elapsed().as_secs_f64(), traces })
}

/// The scans' joint CPS prior: the 4N×4N covariance of their stations
/// from each view's covariance and cross-covariances, mapped to the
/// scanners' poses with the tilt ([`fusion::graph::JointPrior::cps`]).
pub fn joint_prior(views: &[ScanView]) -> Result<fusion::graph::JointPrior> {
    let n = views.len();
    let mut joint = faer::Mat::<f64>::zeros(4 * n, 4 * n);
    for (i, v) in views.iter().enumerate() {
        let blocks = v.cross_covariance.iter().take(i).enumerate().chain([(i, &v.covariance)]);
        for (k, block) in blocks {
            for r in 0..4 {
                for c in 0..4 {
                    joint[(4 * i + r, 4 * k + c)] = block[(r, c)];
                    joint[(4 * k + c, 4 * i + r)] = block[(r, c)];
                }
            }
        }
    }
    let scanners: Vec<Isometry3<f64>> = views.iter().map(ScanView::direct).collect();
    let poses: Vec<ParentPose> = views.iter().map(|v| v.pose).collect();
    let tilts: Vec<Tilt> = views.iter().map(|v| v.tilt).collect();
    Ok(fusion::graph::JointPrior::cps(&scanners, &poses, &tilts, &joint, TILT_SIGMA_RAD)?)
}

/// Horizontal distance between the body origins of two poses, metres.
pub fn error_xy(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    (a.translation.vector.xy() - b.translation.vector.xy()).norm()
}

/// Heading difference of two poses (rotation of the body x axis about z), radians.
pub fn error_heading(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    let (xa, xb) = (a.rotation * nalgebra::Vector3::x(), b.rotation * nalgebra::Vector3::x());
    cps::wrap_angle(xa.y.atan2(xa.x) - xb.y.atan2(xb.x))
}

/// The merged world-frame cloud of `views` at the `fused` poses.
pub fn merged(views: &[ScanView], fused: &Fused) -> Vec<Point3<f32>> {
    let mut out = Vec::with_capacity(views.iter().map(|v| v.body.len()).sum());
    for (v, f) in views.iter().zip(&fused.scans) {
        out.extend(fusion::direct::transform(&v.body, &f.world_from_body));
    }
    out
}

fn number(v: &Value, what: &str, line: usize) -> Result<f64> {
    v.as_f64().with_context(|| format!("journal line {line}: {what}: expected a number, found {v}"))
}

fn matrix_of(v: &Value, what: &str, line: usize) -> Result<Matrix4<f64>> {
    let rows = v.as_array().filter(|r| r.len() == 4);
    let rows = rows.with_context(|| format!("journal line {line}: {what}: expected 4×4"))?;
    let mut m = Matrix4::zeros();
    for (i, row) in rows.iter().enumerate() {
        for j in 0..4 {
            m[(i, j)] = number(&row[j], what, line)?;
        }
    }
    Ok(m)
}

fn pose_of(v: &Value, line: usize) -> Result<ParentPose> {
    Ok(ParentPose::new(
        number(&v["x_m"], "pose.x_m", line)?,
        number(&v["y_m"], "pose.y_m", line)?,
        number(&v["z_m"], "pose.z_m", line)?,
        number(&v["heading_rad"], "pose.heading_rad", line)?,
    ))
}

/// The scans of the run in `dir` with their poses, from its journal and
/// `mission.toml` (a run interrupted before its end gives the scans taken).
pub fn load_run(dir: &Path) -> Result<(Mission, Vec<ScanView>)> {
    let mission_path = dir.join("mission.toml");
    if !mission_path.exists() {
        bail!("{} is not a run directory: {} is missing", dir.display(), mission_path.display());
    }
    let scene_copy = dir.join("scene.toml");
    let mission = if scene_copy.exists() {
        Mission::load_with_scene(&mission_path, &scene_copy)?
    } else {
        Mission::load(&mission_path)?
    };
    let dance = crate::predict::dance(&mission)?;
    let (lines, _) = crate::journal::read(&dir.join("journal.jsonl"))?;
    let mut pose = (dance.station_pose(0), mission.plan.start_covariance);
    let mut cross: Vec<Matrix4<f64>> = Vec::new();
    let mut tilt = None;
    let mut views = Vec::new();
    for l in &lines {
        let e = &l.event;
        match e["event"].as_str() {
            Some("fix") => {
                let d = &e["data"];
                let c = matrix_of(&d["covariance"], "fix covariance", l.line)?;
                pose = (pose_of(&d["pose"], l.line)?, c);
                cross = match d["scan_cross_covariances"].as_array() {
                    Some(list) => list
                        .iter()
                        .map(|m| matrix_of(m, "fix scan_cross_covariances", l.line))
                        .collect::<Result<Vec<_>>>()?,
                    None => Vec::new(),
                };
            }
            Some("tilt") => {
                let d = &e["data"];
                tilt = Some(Tilt {
                    roll_rad: number(&d["roll_rad"], "tilt roll_rad", l.line)?,
                    pitch_rad: number(&d["pitch_rad"], "tilt pitch_rad", l.line)?,
                });
            }
            Some("scan") => {
                let station = e["station"].as_u64().context("scan event without a station")? as usize;
                let file = e["data"]["file"]
                    .as_str()
                    .with_context(|| format!("journal line {}: scan event without a file", l.line))?
                    .to_string();
                let tilt =
                    tilt.take().with_context(|| format!("journal line {}: scan without a tilt reading", l.line))?;
                let cloud = scanner::io::read(&dir.join(&file)).with_context(|| format!("reading {file}"))?;
                let sim = &e["sim"];
                let truth = sim["truth"]["parent"].as_array().filter(|a| a.len() == 4).and_then(|p| {
                    let t = sim["truth"]["tilt"].as_array().filter(|a| a.len() == 2)?;
                    let f = |v: &Value| v.as_f64();
                    let p = ParentPose::new(f(&p[0])?, f(&p[1])?, f(&p[2])?, f(&p[3])?);
                    Some(Tilt { roll_rad: f(&t[0])?, pitch_rad: f(&t[1])? }.world_from_body(&p))
                });
                let nominal = dance.station_pose(station.min(dance.stations.len() - 1));
                let odometry = crate::backend::parent_believed_in(sim)
                    .map_or(nominal, |b| ParentPose::new(b.x_m, b.y_m, nominal.position.z, b.heading_rad));
                views.push(ScanView {
                    station,
                    file,
                    body: cloud.points,
                    pose: pose.0,
                    covariance: pose.1,
                    cross_covariance: std::mem::take(&mut cross),
                    tilt,
                    odometry,
                    truth,
                });
            }
            _ => {}
        }
    }
    Ok((mission, views))
}

/// `cps-survey fuse RUN_DIR --mode M`: re-fuses a run from its journal and
/// scans into `RUN_DIR/fusion/<mode>/` (the cloud in the mission's formats
/// and `fusion.json`; with `[pipe]` also the pipe inspection of the new
/// cloud: `fusion.json`'s `pipe` and the deviation map), and prints per scan the fused pose and, on the
/// simulator, its error next to the direct fusion's.
pub fn fuse_run(dir: &Path, mode: Option<FusionMode>, json_out: bool, out: &mut dyn Write) -> Result<PathBuf> {
    let (mission, views) = load_run(dir)?;
    if views.is_empty() {
        bail!("{}: the journal has no scans to fuse", dir.display());
    }
    let mode = mode.unwrap_or(mission.fusion.mode);
    let fused = fuse(&views, mode, &mission.fusion, mission.scan.scanner_in_body(), false, &mut |_, _| {})?;
    let target = dir.join("fusion").join(mode.name());
    std::fs::create_dir_all(&target).with_context(|| format!("creating {}", target.display()))?;
    let cloud = PointCloud::from_points(merged(&views, &fused));
    for format in &mission.output.formats {
        let path = target.join(format!("cloud.{format}"));
        scanner::io::write(&path, &cloud, Format::from_path(&path)?)?;
    }
    let mut report = report_json(&views, &fused);
    report["seconds"] = json!(fused.seconds);
    if let Some(plan) = &mission.pipe {
        let inspection = crate::pipe::inspect(plan, &cloud.points)?;
        crate::pipe::write_deviation_map(&target, &cloud.points, &inspection)?;
        report["pipe"] = crate::pipe::report_json(plan, &inspection);
    }
    std::fs::write(target.join("fusion.json"), serde_json::to_string_pretty(&report)? + "\n")
        .with_context(|| format!("writing {}", target.join("fusion.json").display()))?;
    if json_out {
        writeln!(out, "{report}")?;
    } else {
        write_table(out, &views, &fused)?;
        if let Some(pipe) = report.get("pipe") {
            crate::pipe::write_summary(out, pipe)?;
        }
        writeln!(out, "outputs in {}", target.display())?;
    }
    Ok(target)
}

/// The fusion as JSON: mode, matches, per scan the fused pose, its
/// RMSE and (sim) the horizontal and heading errors of it and of the direct
/// fusion; and the RMS of those errors.
pub fn report_json(views: &[ScanView], fused: &Fused) -> Value {
    let mut sq = [0.0, 0.0];
    let mut known = 0usize;
    let scans: Vec<Value> = views
        .iter()
        .zip(&fused.scans)
        .map(|(v, f)| {
            let t = f.world_from_body.translation.vector;
            let (_, _, yaw) = f.world_from_body.rotation.euler_angles();
            let mut s = json!({"station": v.station, "file": v.file,
                "pose": {"x_m": t.x, "y_m": t.y, "z_m": t.z, "heading_rad": yaw}, "rmse_m": f.rmse_m});
            if let Some(truth) = &v.truth {
                let (e, d) = (error_xy(&f.world_from_body, truth), error_xy(&v.direct(), truth));
                s["error_xy_m"] = json!(e);
                s["direct_error_xy_m"] = json!(d);
                s["error_heading_rad"] = json!(error_heading(&f.world_from_body, truth));
                s["direct_error_heading_rad"] = json!(error_heading(&v.direct(), truth));
                sq[0] += e * e;
                sq[1] += d * d;
                known += 1;
            }
            s
        })
        .collect();
    let rms = |s: f64| if known > 0 { json!((s / known as f64).sqrt()) } else { Value::Null };
    json!({"mode": fused.mode.name(), "matches": fused.matches, "scans": scans,
        "rms_error_xy_m": rms(sq[0]), "direct_rms_error_xy_m": rms(sq[1])})
}

/// A table: one row per scan.
pub fn write_table(out: &mut dyn Write, views: &[ScanView], fused: &Fused) -> std::io::Result<()> {
    writeln!(
        out,
        "fusion {}: {} scans, {} ICP matches, {:.2} s",
        fused.mode.name(),
        views.len(),
        fused.matches,
        fused.seconds
    )?;
    writeln!(
        out,
        "{:>7} {:>10} {:>10} {:>9} {:>8} {:>11} {:>11} {:>11}",
        "station", "x_m", "y_m", "z_m", "rmse_mm", "error_mm", "direct_mm", "Δθ_arcsec"
    )?;
    let mm = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.2}", 1e3 * v));
    for (v, f) in views.iter().zip(&fused.scans) {
        let t = f.world_from_body.translation.vector;
        let truth = v.truth.as_ref();
        writeln!(
            out,
            "{:>7} {:>10.3} {:>10.3} {:>9.3} {:>8} {:>11} {:>11} {:>11}",
            v.station,
            t.x,
            t.y,
            t.z,
            mm(f.rmse_m),
            mm(truth.map(|tr| error_xy(&f.world_from_body, tr))),
            mm(truth.map(|tr| error_xy(&v.direct(), tr))),
            truth.map_or("-".to_string(), |tr| format!(
                "{:.1}",
                error_heading(&f.world_from_body, tr).to_degrees() * 3600.0
            )),
        )?;
    }
    Ok(())
}
