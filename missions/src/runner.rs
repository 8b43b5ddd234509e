//! `cps-survey run`: a mission on the simulator, end to end — the dance
//! cycle by cycle, a scan at each scan station fused directly with the CPS
//! pose, a journal of every command and reading, and the outputs.
//!
//! Outputs in the run directory:
//! - `journal.jsonl` — one JSON object per line (`"v": 1`), appended and
//!   flushed as each command is given and each reading taken;
//! - `scans/scanNNN.3d` + `.pose` — each scan in the body frame with its
//!   CPS `world_from_body` (3DTK layout), written before the journal
//!   references it;
//! - `report.json`, `stations.csv` — per-station estimate, covariance,
//!   prediction, truth and error;
//! - `cloud.<format>` — the merged world-frame cloud in each `[output]` format.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use cps::{FixOptions, ParentPose, TeamState, observe};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use nalgebra::{Isometry3, Matrix4, Point3, Translation3, UnitQuaternion};
use scanner::io::{Format, PointCloud};
use scanner::sim::{
    LmsConfig, LmsRangeMode, OdometryError, Robot, SimDrive, SimHead, SimLms, SimTilt, SimTotalStation, SimWorld,
};
use scanner::{Drive, HeadKind, PlanarPose, Target, TiltSensor, TotalStation, scan_3d};
use serde_json::{Value, json};

use crate::mission::Mission;

/// Journal schema version.
pub const JOURNAL_VERSION: u32 = 1;

/// One parent station of a finished run.
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
    /// The simulator's true pose.
    pub truth: ParentPose,
    /// Horizontal error against the truth, metres.
    pub error_xy_m: f64,
    /// The scan file taken here, relative to the run directory.
    pub scan: Option<String>,
}

/// What a run returns.
#[derive(Debug, Clone)]
pub struct RunSummary {
    /// The run directory.
    pub dir: PathBuf,
    /// Every station, start included.
    pub stations: Vec<StationRecord>,
    /// Points in the merged cloud.
    pub points: usize,
    /// Whether the mission's acceptance tolerances hold.
    pub accepted: bool,
}

/// Appends JSON lines and flushes each one.
struct Journal(File);

impl Journal {
    fn log(&mut self, mut event: Value) -> Result<()> {
        event["v"] = json!(JOURNAL_VERSION);
        let mut line = serde_json::to_string(&event)?;
        line.push('\n');
        self.0.write_all(line.as_bytes()).and_then(|()| self.0.flush()).context("writing journal.jsonl")
    }
}

fn pose_json(p: &ParentPose) -> Value {
    json!({"x_m": p.position.x, "y_m": p.position.y, "z_m": p.position.z, "heading_rad": p.heading_rad})
}

fn matrix_json(m: &Matrix4<f64>) -> Value {
    json!((0..4).map(|i| (0..4).map(|j| m[(i, j)]).collect::<Vec<_>>()).collect::<Vec<_>>())
}

fn planar(p: &ParentPose) -> PlanarPose {
    PlanarPose { x_m: p.position.x, y_m: p.position.y, heading_rad: p.heading_rad }
}

fn bars(quiet: bool) -> MultiProgress {
    MultiProgress::with_draw_target(if quiet { ProgressDrawTarget::hidden() } else { ProgressDrawTarget::stderr() })
}

/// Runs `mission` on the simulator into `dir` (created; an existing journal
/// there is an error, so a finished run is never overwritten).
pub fn run(mission: &Mission, dir: &Path, quiet: bool) -> Result<RunSummary> {
    let started = Instant::now();
    let dance = crate::predict::dance(mission)?;
    let prediction = crate::predict::prediction(mission)?;
    std::fs::create_dir_all(dir.join("scans")).with_context(|| format!("creating {}", dir.display()))?;
    let journal_path = dir.join("journal.jsonl");
    if journal_path.exists() {
        bail!("{} already holds a run ({}); choose another --out directory", dir.display(), journal_path.display());
    }
    let mut journal =
        Journal(File::create(&journal_path).with_context(|| format!("creating {}", journal_path.display()))?);
    let (inst, seed) = (&mission.total_station, mission.backend.seed);
    journal.log(json!({"event": "start", "mission": mission.name, "seed": seed, "scene": mission.backend.scene,
        "stations": dance.stations.len(), "children": mission.children}))?;

    // The simulated world: the parent truly at station 0, the children at
    // their first formation points.
    let scene = cps::geom::builtin(&mission.backend.scene)?;
    let start = dance.station_pose(0);
    let first = dance.cycles.first().map(|c| c.children.clone()).unwrap_or_default();
    let world = SimWorld::new(scene, start, first.clone());
    let odometry = OdometryError::default();
    let mut parent_drive = SimDrive::new(world.clone(), Robot::Parent, planar(&start), odometry, seed)?;
    let mut child_drives = first
        .iter()
        .enumerate()
        .map(|(j, p)| {
            let at = PlanarPose { x_m: p.x, y_m: p.y, heading_rad: 0.0 };
            SimDrive::new(world.clone(), Robot::Child(j), at, odometry, seed)
        })
        .collect::<scanner::Result<Vec<_>>>()?;
    let mut total_station = SimTotalStation::new(world.clone(), inst.clone(), seed);
    let mut tilt = SimTilt::new(world.clone(), 0.01f64.to_radians(), seed);
    let body_from_head =
        Isometry3::from_parts(Translation3::from(mission.scan.body_from_head_m), UnitQuaternion::identity());
    let lms_config = LmsConfig { resolution: mission.scan.resolution, mode: LmsRangeMode::Mm32, sigma_range_m: 0.005 };
    let mut lms = SimLms::new(world.clone(), lms_config, HeadKind::RotatingTable, body_from_head, seed);
    let mut head = SimHead::new(world.clone(), HeadKind::RotatingTable);

    let mut team = TeamState::new(start, mission.plan.start_covariance, dance.n_children())?;
    let progress = bars(quiet);
    let style = ProgressStyle::with_template("{prefix:>8} [{bar:40}] {pos}/{len} {msg}")
        .map_err(|e| anyhow::anyhow!("progress style: {e}"))?
        .progress_chars("=> ");
    let mission_bar = progress.add(ProgressBar::new(dance.cycles.len() as u64).with_style(style.clone()));
    mission_bar.set_prefix("cycles");
    let scan_bar = progress.add(ProgressBar::new(mission.scan.slices as u64).with_style(style));
    scan_bar.set_prefix("scan");

    let mut merged = Vec::new();
    let mut stations = Vec::with_capacity(dance.stations.len());
    let record = |index: usize, team: &TeamState, predicted: Matrix4<f64>, scan: Option<String>| {
        let truth = world.truth().parent;
        let pose = team.parent();
        let error_xy_m = (pose.position.xy() - truth.position.xy()).norm();
        StationRecord {
            index,
            pose,
            covariance: team.parent_covariance(),
            predicted_covariance: predicted,
            truth,
            error_xy_m,
            scan,
        }
    };
    let mut take_scan = |index: usize, team: &TeamState, journal: &mut Journal| -> Result<Option<String>> {
        let every = mission.scan.every_n_stations;
        if every == 0 || !index.is_multiple_of(every) {
            return Ok(None);
        }
        let tilt_reading = tilt.read()?;
        journal.log(json!({"event": "tilt", "station": index, "roll_rad": tilt_reading.roll_rad,
            "pitch_rad": tilt_reading.pitch_rad}))?;
        scan_bar.reset();
        let scan = scan_3d(&mut head, &mut lms, mission.scan.slices, &body_from_head, &mut |done, _| {
            scan_bar.set_position(done as u64);
        })?;
        let world_from_body = tilt_reading.world_from_body(&team.parent());
        let name = format!("scans/scan{index:03}");
        let points = scan.len();
        merged.extend(fusion::direct::transform(&scan.points, &world_from_body));
        let cloud = PointCloud::from_points(scan.points);
        scanner::io::write(&dir.join(format!("{name}.3d")), &cloud, Format::ThreeDtk)?;
        scanner::io::write_3dtk_pose(&dir.join(format!("{name}.pose")), &world_from_body)?;
        journal.log(json!({"event": "scan", "station": index, "file": format!("{name}.3d"), "points": points}))?;
        Ok(Some(format!("{name}.3d")))
    };

    let scan = take_scan(0, &team, &mut journal)?;
    stations.push(record(0, &team, mission.plan.start_covariance, scan));
    for (cycle, predicted) in dance.cycles.iter().zip(&prediction.cycles) {
        let from = team.parent();
        // The children move to the formation and are measured from the standing parent.
        for (j, target) in cycle.children.iter().enumerate() {
            let goal = PlanarPose { x_m: target.x, y_m: target.y, heading_rad: 0.0 };
            let odo = child_drives[j].move_to(&goal)?;
            journal.log(json!({"event": "drive", "robot": mission.children[j], "cycle": cycle.cycle,
                "target": [goal.x_m, goal.y_m, goal.heading_rad], "distance_m": odo.distance_m}))?;
            let m = total_station.measure(&Target { child: j, predicted: observe(&from, target)? })?;
            journal.log(json!({"event": "measure", "cycle": cycle.cycle, "phase": "placement", "child": j,
                "slope_raw_m": m.slope_raw_m, "hz_rad": m.hz_rad, "v_rad": m.v_rad}))?;
            team.place_child(j, &m.to_reading(inst), inst)?;
        }
        // The parent moves to the next station and fixes itself from the children.
        let nominal = dance.station_pose(cycle.to);
        let odo = parent_drive.move_to(&planar(&nominal))?;
        journal.log(json!({"event": "drive", "robot": "parent", "cycle": cycle.cycle,
            "target": [nominal.position.x, nominal.position.y, nominal.heading_rad], "distance_m": odo.distance_m}))?;
        let mut readings = Vec::with_capacity(cycle.children.len());
        for (j, target) in cycle.children.iter().enumerate() {
            let m = total_station.measure(&Target { child: j, predicted: observe(&nominal, target)? })?;
            journal.log(json!({"event": "measure", "cycle": cycle.cycle, "phase": "fix", "child": j,
                "slope_raw_m": m.slope_raw_m, "hz_rad": m.hz_rad, "v_rad": m.v_rad}))?;
            readings.push((j, m.to_reading(inst)));
        }
        let fix = team.fix_parent(&readings, inst, &FixOptions::default())?;
        journal.log(json!({"event": "fix", "cycle": cycle.cycle, "station": cycle.to,
            "pose": pose_json(&team.parent()), "covariance": matrix_json(&team.parent_covariance()),
            "sigma0_squared": fix.sigma0_squared}))?;
        let scan = take_scan(cycle.to, &team, &mut journal)?;
        stations.push(record(cycle.to, &team, predicted.covariance, scan));
        mission_bar.inc(1);
    }
    mission_bar.finish_and_clear();
    scan_bar.finish_and_clear();

    let merged = PointCloud::from_points(merged);
    for format in &mission.output.formats {
        let path = dir.join(format!("cloud.{format}"));
        scanner::io::write(&path, &merged, Format::from_path(&path)?)?;
    }
    let accepted = write_reports(mission, dir, &stations, started.elapsed().as_secs_f64())?;
    journal.log(json!({"event": "end", "accepted": accepted}))?;
    Ok(RunSummary { dir: dir.to_path_buf(), stations, points: merged.len(), accepted })
}

/// Writes `report.json` and `stations.csv`; returns whether the mission's
/// acceptance tolerances hold.
fn write_reports(mission: &Mission, dir: &Path, stations: &[StationRecord], seconds: f64) -> Result<bool> {
    let last = stations.last().context("a run has at least the start station")?;
    let distance_m: f64 = stations.windows(2).map(|w| (w[1].truth.position - w[0].truth.position).norm()).sum();
    let sigma_xy2 = cps::sigma_xy2(&last.covariance);
    let max_error = stations.iter().map(|s| s.error_xy_m).fold(0.0, f64::max);
    let accepted = mission.acceptance.max_final_sigma_xy_m.is_none_or(|m| sigma_xy2.sqrt() <= m)
        && mission.acceptance.max_station_error_m.is_none_or(|m| max_error <= m);
    let report = json!({
        "mission": mission.name,
        "seed": mission.backend.seed,
        "backend": "sim",
        "scene": mission.backend.scene,
        "stations": stations.iter().map(|s| json!({
            "index": s.index,
            "pose": pose_json(&s.pose),
            "covariance": matrix_json(&s.covariance),
            "predicted_covariance": matrix_json(&s.predicted_covariance),
            "truth": pose_json(&s.truth),
            "error_m": s.error_xy_m,
            "scan": s.scan,
        })).collect::<Vec<_>>(),
        "final": {
            "distance_m": distance_m,
            "sigma_xy2_m2": sigma_xy2,
            "error_xy_m": last.error_xy_m,
            "drift_percent": if distance_m > 0.0 { 100.0 * last.error_xy_m / distance_m } else { 0.0 },
        },
        "accepted": accepted,
        "timings": {"wall_seconds": seconds},
    });
    std::fs::write(dir.join("report.json"), serde_json::to_string_pretty(&report)? + "\n")
        .with_context(|| format!("writing {}", dir.join("report.json").display()))?;
    let mut csv = String::from(
        "index,x_m,y_m,z_m,heading_rad,sigma_x_m,sigma_y_m,sigma_z_m,sigma_heading_rad,predicted_sigma_xy_m,true_x_m,true_y_m,true_z_m,true_heading_rad,error_xy_m\n",
    );
    for s in stations {
        let sd = |k: usize| s.covariance[(k, k)].max(0.0).sqrt();
        let (p, t) = (&s.pose, &s.truth);
        csv += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
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
            t.position.x,
            t.position.y,
            t.position.z,
            t.heading_rad,
            s.error_xy_m
        );
    }
    std::fs::write(dir.join("stations.csv"), csv)
        .with_context(|| format!("writing {}", dir.join("stations.csv").display()))?;
    Ok(accepted)
}

/// The points of `cloud` within `tolerance_m` of the scene's surfaces, as a
/// fraction (used to check a fused cloud).
pub fn on_surface_fraction(scene: &cps::geom::Scene, cloud: &[Point3<f32>], tolerance_m: f64) -> f64 {
    let near = cloud.iter().filter(|p| scene.bvh().distance(&p.cast()).0 <= tolerance_m).count();
    near as f64 / cloud.len().max(1) as f64
}

/// The run's summary for the terminal: one line per station and the final
/// figures.
pub fn write_summary(out: &mut dyn Write, mission: &Mission, s: &RunSummary) -> std::io::Result<()> {
    writeln!(
        out,
        "mission \"{}\" (seed {}): {} stations, {} points fused",
        mission.name,
        mission.backend.seed,
        s.stations.len(),
        s.points
    )?;
    writeln!(
        out,
        "{:>7} {:>10} {:>10} {:>9} {:>11} {:>11} {:>9}",
        "station", "x_m", "y_m", "σxy_mm", "pred σxy_mm", "error_xy_mm", "scan"
    )?;
    for st in &s.stations {
        writeln!(
            out,
            "{:>7} {:>10.3} {:>10.3} {:>9.2} {:>11.2} {:>11.2} {:>9}",
            st.index,
            st.pose.position.x,
            st.pose.position.y,
            1e3 * cps::sigma_xy2(&st.covariance).sqrt(),
            1e3 * cps::sigma_xy2(&st.predicted_covariance).sqrt(),
            1e3 * st.error_xy_m,
            if st.scan.is_some() { "yes" } else { "-" }
        )?;
    }
    writeln!(out, "outputs in {} (report.json, stations.csv, journal.jsonl, scans/, cloud.*)", s.dir.display())?;
    writeln!(out, "acceptance: {}", if s.accepted { "passed" } else { "FAILED" })
}
