//! `cps-survey run`: a mission on the simulator, end to end — the dance
//! cycle by cycle, a scan at each scan station fused directly with the CPS
//! pose, a journal of every command and reading, and the outputs.
//!
//! Outputs in the run directory:
//! - `mission.toml` — the mission as run (a resume must use the same);
//! - `journal.jsonl` — see [`crate::journal`]: every command with its
//!   reading and the simulator's state after it, flushed as it happens;
//! - `scans/scanNNN.3d` + `.pose` — each scan in the body frame with its
//!   CPS `world_from_body` (3DTK layout), written before the journal
//!   references it;
//! - `report.json`, `stations.csv` — per-station estimate, covariance,
//!   prediction, truth and error;
//! - `cloud.<format>` — the merged world-frame cloud in each `[output]` format;
//! - `mission.rrd` — the Rerun recording ([`crate::recording`]).
//!
//! `--resume` replays the journal: each recorded reading is used as it was
//! and the simulated world is put back to its recorded state after each
//! step, so the run continues exactly where it stopped.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use cps::{FixOptions, ParentPose, TeamState, observe};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use nalgebra::{Matrix4, Point3};
use planner::{Dance, DanceCycle, Prediction};
use scanner::io::{Format, PointCloud};
use scanner::sim::Robot;
use scanner::{PlanarPose, Target, Tilt, TsMeasurement, TsStatus};
use serde::{Deserialize, Serialize, de::DeserializeOwned};
use serde_json::{Value, json};

use crate::backend::{DeviceKind, Fault, Team};
use crate::fuse::{Fused, ScanView};
use crate::journal::Journal;
use crate::mission::{FusionMode, Mission};
use crate::recording::{DRIVE_SPEED_M_PER_S, MEASURE_S, Recorder, TILT_S, Viewer};

/// How to run.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// No progress bars.
    pub quiet: bool,
    /// Continue the run whose journal is in the directory.
    pub resume: bool,
    /// Faults to inject into the simulated devices.
    pub faults: Vec<Fault>,
    /// Abort the process after writing this many journal events (a crash
    /// at a chosen point, for testing `--resume`).
    pub abort_after_events: Option<usize>,
    /// A live viewer to stream to besides `mission.rrd`.
    pub viewer: Viewer,
    /// Log every ICP iteration of the fusion to the recording, on the
    /// `icp_iteration` timeline.
    pub log_icp_iterations: bool,
}

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
    /// The simulator's true pose (sim backend only).
    pub truth: Option<ParentPose>,
    /// Horizontal error against the truth, metres (sim backend only).
    pub error_xy_m: Option<f64>,
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
    /// Journal events replayed from an earlier, interrupted run.
    pub replayed: usize,
    /// The fusion's figures as in `report.json`'s `fusion`.
    pub fusion: Value,
    /// The pipe inspection as in `report.json`'s `pipe`, with `[pipe]`.
    pub pipe: Option<Value>,
}

/// A drive's report, as journaled.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Driven {
    distance_m: f64,
}

/// A total-station measurement in the instrument's convention, as journaled.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Measured {
    slope_raw_m: f64,
    hz_rad: f64,
    v_rad: f64,
    reduced_accuracy: bool,
}

impl Measured {
    fn from(m: TsMeasurement) -> Self {
        Self {
            slope_raw_m: m.slope_raw_m,
            hz_rad: m.hz_rad,
            v_rad: m.v_rad,
            reduced_accuracy: m.status == TsStatus::ReducedAccuracy,
        }
    }

    fn measurement(&self) -> TsMeasurement {
        TsMeasurement {
            slope_raw_m: self.slope_raw_m,
            hz_rad: self.hz_rad,
            v_rad: self.v_rad,
            status: if self.reduced_accuracy { TsStatus::ReducedAccuracy } else { TsStatus::Ok },
        }
    }
}

/// A tilt reading, as journaled.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Tilted {
    roll_rad: f64,
    pitch_rad: f64,
}

/// A scan written to the run directory, as journaled.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Scanned {
    file: String,
    points: usize,
}

fn pose_json(p: &ParentPose) -> Value {
    json!({"x_m": p.position.x, "y_m": p.position.y, "z_m": p.position.z, "heading_rad": p.heading_rad})
}

fn matrix_json(m: &Matrix4<f64>) -> Value {
    json!((0..4).map(|i| (0..4).map(|j| m[(i, j)]).collect::<Vec<_>>()).collect::<Vec<_>>())
}

/// The journal, the devices and the retry policy: every command of the run
/// goes through [`Steps::step`].
struct Steps {
    journal: Journal,
    sim: Team,
    rec: Recorder,
    max_retries: u32,
    retry_delay: Duration,
    resume_hint: String,
    bar: ProgressBar,
    replayed: usize,
}

impl Steps {
    /// One device command. While the journal holds recorded steps, the next
    /// one (which must be this command) is used as it was and the simulated
    /// world is put back to its recorded state after it. Otherwise the
    /// device is commanded — again after a failure, up to the mission's
    /// retries — and the reading is journaled with the simulator's state.
    fn step<T: Serialize + DeserializeOwned>(
        &mut self,
        key: Value,
        device: DeviceKind,
        mut command: impl FnMut(&mut Team) -> scanner::Result<T>,
    ) -> Result<T> {
        self.bar.inc(1);
        if let Some(event) = self.journal.next_recorded(&key)? {
            self.replayed += 1;
            self.sim.restore(&event["sim"]).context("restoring the team's state from the journal")?;
            return serde_json::from_value(event["data"].clone())
                .with_context(|| format!("journal event {event}: unreadable data"));
        }
        let mut attempt = 0;
        loop {
            match command(&mut self.sim) {
                Ok(data) => {
                    let mut event = key;
                    event["data"] = serde_json::to_value(&data)?;
                    event["sim"] = self.sim.checkpoint();
                    self.journal.append(event)?;
                    return Ok(data);
                }
                Err(e) if attempt < self.max_retries => {
                    attempt += 1;
                    self.journal.append(json!({"event": "retry", "device": device.name(), "attempt": attempt,
                        "error": e.to_string(), "step": key}))?;
                    self.rec
                        .event(rerun::TextLogLevel::WARN, format!("{e}: retry {attempt} of {}", self.max_retries))?;
                    std::thread::sleep(self.retry_delay);
                }
                Err(e) => {
                    self.journal.append(json!({"event": "stop", "device": device.name(), "error": e.to_string(),
                        "step": key}))?;
                    self.rec.event(rerun::TextLogLevel::ERROR, format!("{e}: mission stopped"))?;
                    bail!(
                        "{} failed {} time(s), last: {e}. The mission stopped cleanly; the journal keeps every \
                         reading so far. Once the device answers, continue with: {}",
                        device.name(),
                        attempt + 1,
                        self.resume_hint
                    );
                }
            }
        }
    }

    /// A result the run derives (a fix, the end): journaled live; on replay
    /// the recorded one must be there.
    fn note(&mut self, key: Value, data: Value) -> Result<()> {
        if self.journal.next_recorded(&key)?.is_some() {
            self.replayed += 1;
            return Ok(());
        }
        let mut event = key;
        event["data"] = data;
        self.journal.append(event)
    }
}

/// Where the wall time went, seconds (positioning is the rest of `wall_s`).
#[derive(Debug, Default, Clone, Copy, Serialize)]
struct Timings {
    /// Simulating the 3D scans.
    scan_s: f64,
    /// Writing `scans/`.
    scan_files_s: f64,
    /// Direct fusion of the scans.
    fusion_s: f64,
    /// Writing the merged cloud files.
    cloud_files_s: f64,
    /// Recording `mission.rrd` (on the mission's thread; scans are thinned
    /// and logged on a worker, waited for at the end).
    recording_s: f64,
    /// The pipe inspection (fit, deviation map, anomalies) and its file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pipe_s: Option<f64>,
}

/// Adds the seconds `f` takes to `total`.
fn timed<T>(total: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    *total += t.elapsed().as_secs_f64();
    out
}

/// A mission being run.
struct Run<'m> {
    mission: &'m Mission,
    dance: Dance,
    prediction: Prediction,
    dir: PathBuf,
    steps: Steps,
    team: TeamState,
    scan_bar: ProgressBar,
    merged: Vec<Point3<f32>>,
    /// Every scan with its poses (body points kept for the ICP modes) and
    /// where it sits on the recording's timelines.
    views: Vec<ScanView>,
    scan_times: Vec<(i64, f64)>,
    stations: Vec<StationRecord>,
    timings: Timings,
    log_icp_iterations: bool,
}

/// Runs `mission` on the simulator into `dir`: a new run (an existing
/// journal there is an error, so a run is never overwritten), or with
/// `resume` the continuation of the run whose journal is there. A plan that
/// breaks a constraint (`cps-survey plan`) is refused before anything moves.
pub fn run(mission: &Mission, dir: &Path, options: &RunOptions) -> Result<RunSummary> {
    let started = Instant::now();
    let dance = crate::predict::dance(mission)?;
    crate::plan::refuse_violations(mission, &dance)?;
    let prediction = crate::predict::prediction(mission)?;
    std::fs::create_dir_all(dir.join("scans")).with_context(|| format!("creating {}", dir.display()))?;
    let journal_path = dir.join("journal.jsonl");
    let mission_copy = dir.join("mission.toml");
    let mut journal = if options.resume {
        let (mut journal, start) = Journal::resume(&journal_path)?;
        journal.abort_after(options.abort_after_events);
        let as_run =
            std::fs::read_to_string(&mission_copy).with_context(|| format!("reading {}", mission_copy.display()))?;
        let scene_changed = match &mission.backend.scene_file {
            Some((_, text)) => std::fs::read_to_string(dir.join("scene.toml")).ok().as_ref() != Some(text),
            None => false,
        };
        if as_run != mission.source.text || start["seed"] != json!(mission.backend.seed) || scene_changed {
            bail!(
                "{} is not the mission this run started with ({}{}); resume with that file",
                mission.source.file.display(),
                mission_copy.display(),
                if scene_changed { ", and its scene file changed since: see scene.toml there" } else { "" }
            );
        }
        journal
    } else {
        let mut journal = Journal::create(&journal_path)?;
        journal.abort_after(options.abort_after_events);
        std::fs::write(&mission_copy, &mission.source.text)
            .with_context(|| format!("writing {}", mission_copy.display()))?;
        if let Some((_, text)) = &mission.backend.scene_file {
            std::fs::write(dir.join("scene.toml"), text)
                .with_context(|| format!("writing {}/scene.toml", dir.display()))?;
        }
        journal.append(json!({"event": "start", "mission": mission.name, "seed": mission.backend.seed,
            "scene": mission.backend.scene, "stations": dance.stations.len(), "children": mission.children}))?;
        journal
    };
    if options.resume {
        journal.append(json!({"event": "resume"}))?;
    }

    let sim = Team::new(mission, &dance, options.faults.clone())?;
    let rrd = mission.output.rerun.then(|| dir.join("mission.rrd"));
    let mut rec = Recorder::new(&mission.name, rrd.as_deref(), &options.viewer, crate::plan::robot_names(mission))?;
    rec.layout(crate::recording::Layout::Mission)?;
    rec.scene(sim.scene())?;
    crate::plan::log_plan(&mut rec, mission, "plan", &dance, &prediction, &[])?;

    let progress = MultiProgress::with_draw_target(if options.quiet {
        ProgressDrawTarget::hidden()
    } else {
        ProgressDrawTarget::stderr()
    });
    let style = ProgressStyle::with_template("{prefix:>8} [{bar:40}] {pos}/{len} {msg}")
        .map_err(|e| anyhow::anyhow!("progress style: {e}"))?
        .progress_chars("=> ");
    let n = mission.children.len() as u64;
    let scans = (0..dance.stations.len()).filter(|k| mission.scan.scans_at(*k)).count() as u64;
    let total_steps = dance.cycles.iter().map(|c| 2 * c.moved.len() as u64 + n + 1).sum::<u64>() + 2 * scans;
    let bar = progress.add(ProgressBar::new(total_steps).with_style(style.clone()));
    bar.set_prefix("steps");
    let scan_bar = progress.add(ProgressBar::new(mission.scan.slices as u64).with_style(style));
    scan_bar.set_prefix("scan");

    let resume_hint = format!("cps-survey run {} --out {} --resume", mission.source.file.display(), dir.display());
    let team = TeamState::new(dance.station_pose(0), mission.plan.start_covariance, dance.n_children())?;
    let steps = Steps {
        journal,
        sim,
        rec,
        max_retries: mission.backend.max_retries,
        retry_delay: Duration::from_secs_f64(mission.backend.retry_delay_s),
        resume_hint,
        bar,
        replayed: 0,
    };
    let mut run = Run {
        mission,
        dance,
        prediction,
        dir: dir.to_path_buf(),
        steps,
        team,
        scan_bar,
        merged: Vec::new(),
        views: Vec::new(),
        scan_times: Vec::new(),
        stations: Vec::new(),
        timings: Timings::default(),
        log_icp_iterations: options.log_icp_iterations,
    };
    run.steps.rec.event(rerun::TextLogLevel::INFO, format!("mission \"{}\" starts", mission.name))?;
    run.station(0, mission.plan.start_covariance, None)?;
    for k in 0..run.dance.cycles.len() {
        run.cycle(k)?;
    }
    run.finish(started)
}

impl Run<'_> {
    /// One dance cycle: the children move to the formation and are measured
    /// from the standing parent; the parent moves and fixes itself from
    /// them; then the station's scan.
    fn cycle(&mut self, k: usize) -> Result<()> {
        let cycle: DanceCycle = self.dance.cycles[k].clone();
        let predicted = self.prediction.cycles[k].clone();
        let mission: &Mission = self.mission;
        let Some(inst) = &mission.total_station else {
            return self.solo_cycle(&cycle, &predicted);
        };
        let from = self.team.parent();
        for &j in &cycle.moved {
            let at = &cycle.children[j];
            let goal = PlanarPose { x_m: at.x, y_m: at.y, heading_rad: 0.0 };
            let robot = &self.mission.children[j];
            let driven: Driven = self.steps.step(
                json!({"event": "drive", "cycle": cycle.cycle, "robot": robot, "target": [goal.x_m, goal.y_m, goal.heading_rad]}),
                DeviceKind::Drive,
                |sim| sim.drive(Robot::Child(j), &goal).map(|o| Driven { distance_m: o.distance_m }),
            )?;
            self.steps.rec.advance(driven.distance_m / DRIVE_SPEED_M_PER_S);
            let target = Target { child: j, predicted: observe(&from, at)? };
            let m: Measured = self.steps.step(
                json!({"event": "measure", "cycle": cycle.cycle, "phase": "placement", "child": j}),
                DeviceKind::TotalStation,
                |sim| sim.measure(&target).map(Measured::from),
            )?;
            self.team.place_child(j, &m.measurement().to_reading(inst), inst)?;
            self.steps.rec.advance(MEASURE_S);
            let placed = self.team.child(j).context("a placed child has a position")?;
            self.steps.sim.relocalise_child(j, &placed)?;
            self.steps.rec.sight_lines("placement", &from.position, &[(placed, None)])?;
            self.log_team(Some(&predicted.covariance), &predicted.children_covariance)?;
        }

        let nominal = self.drive_parent(&cycle)?;
        let mut readings = Vec::with_capacity(cycle.children.len());
        for (j, at) in cycle.children.iter().enumerate() {
            let target = Target { child: j, predicted: observe(&nominal, at)? };
            let m: Measured = self.steps.step(
                json!({"event": "measure", "cycle": cycle.cycle, "phase": "fix", "child": j}),
                DeviceKind::TotalStation,
                |sim| sim.measure(&target).map(Measured::from),
            )?;
            self.steps.rec.advance(MEASURE_S);
            readings.push((j, m.measurement().to_reading(inst)));
        }
        let fix = self.team.fix_parent(&readings, inst, &FixOptions::default())?;
        let pose = self.team.parent();
        self.steps.sim.relocalise_parent(&pose)?;
        // cov(this station, each earlier scan station): the scans' joint prior.
        let cross = (0..self.team.clones())
            .map(|a| self.team.parent_clone_covariance(a).map(|c| matrix_json(&c)))
            .collect::<cps::Result<Vec<_>>>()?;
        self.steps.note(
            json!({"event": "fix", "cycle": cycle.cycle, "station": cycle.to}),
            json!({"pose": pose_json(&pose), "covariance": matrix_json(&self.team.parent_covariance()),
                "sigma0_squared": fix.sigma0_squared, "redundancy": fix.redundancy,
                "scan_cross_covariances": cross}),
        )?;

        // Sight lines coloured by each child's largest |w|; a blunder is logged.
        let reliability = fix.reliability();
        let mut lines = Vec::with_capacity(readings.len());
        for (k, (j, _)) in readings.iter().enumerate() {
            let w = reliability.w_statistics[3 * k..3 * k + 3]
                .iter()
                .flatten()
                .copied()
                .max_by(|a, b| a.abs().total_cmp(&b.abs()));
            if let Some(w) = w.filter(|w| w.abs() > crate::recording::W_CRITICAL) {
                self.steps.rec.event(
                    rerun::TextLogLevel::WARN,
                    format!(
                        "cycle {}: the measurement of {} has |w| = {:.2} > {}: a possible blunder",
                        cycle.cycle,
                        self.mission.children[*j],
                        w.abs(),
                        crate::recording::W_CRITICAL
                    ),
                )?;
            }
            lines.push((self.team.child(*j).context("a sighted child is placed")?, w));
        }
        self.steps.rec.sight_lines("fix", &pose.position, &lines)?;
        self.steps.rec.fix_metrics(fix.sigma0_squared);
        self.log_team(Some(&predicted.covariance), &predicted.children_covariance)?;
        self.station(cycle.to, predicted.covariance, Some(&predicted.children_covariance))
    }

    /// The parent drives to the cycle's station; returns its nominal pose.
    fn drive_parent(&mut self, cycle: &DanceCycle) -> Result<ParentPose> {
        let nominal = self.dance.station_pose(cycle.to);
        let goal = PlanarPose::from(&nominal);
        let driven: Driven = self.steps.step(
            json!({"event": "drive", "cycle": cycle.cycle, "robot": "parent", "target": [goal.x_m, goal.y_m, goal.heading_rad]}),
            DeviceKind::Drive,
            |sim| sim.drive(Robot::Parent, &goal).map(|o| Driven { distance_m: o.distance_m }),
        )?;
        self.steps.rec.advance(driven.distance_m / DRIVE_SPEED_M_PER_S);
        Ok(nominal)
    }

    /// A robot alone drives to the next station and takes the pose its
    /// odometry believes, with the dead-reckoning covariance.
    fn solo_cycle(&mut self, cycle: &DanceCycle, predicted: &planner::CyclePrediction) -> Result<()> {
        let nominal = self.drive_parent(cycle)?;
        let believed = self.steps.sim.parent_believed();
        let pose = ParentPose::new(believed.x_m, believed.y_m, nominal.position.z, believed.heading_rad);
        self.team = TeamState::new(pose, predicted.covariance, 0)?;
        self.steps.note(
            json!({"event": "fix", "cycle": cycle.cycle, "station": cycle.to}),
            json!({"pose": pose_json(&pose), "covariance": matrix_json(&predicted.covariance), "source": "odometry"}),
        )?;
        self.log_team(Some(&predicted.covariance), &[])?;
        self.station(cycle.to, predicted.covariance, Some(&[]))
    }

    /// Logs the team's estimate, truth and ellipsoids to the recording.
    fn log_team(&mut self, predicted: Option<&Matrix4<f64>>, children: &[nalgebra::Matrix3<f64>]) -> Result<()> {
        let truth = self.steps.sim.truth();
        self.steps.rec.team(&self.team, truth.as_ref(), predicted.map(|p| (p, children)))
    }

    /// The parent stands at station `index`: the scan if one is due, then
    /// the station's record.
    fn station(
        &mut self,
        index: usize,
        predicted: Matrix4<f64>,
        children: Option<&[nalgebra::Matrix3<f64>]>,
    ) -> Result<()> {
        if children.is_none() {
            self.log_team(None, &[])?;
        }
        let scan = if self.mission.scan.scans_at(index) { Some(self.scan(index)?) } else { None };
        let truth = self.steps.sim.truth().map(|t| t.parent);
        let pose = self.team.parent();
        let error_xy_m = truth.map(|t| (pose.position.xy() - t.position.xy()).norm());
        let covariance = self.team.parent_covariance();
        self.steps.rec.trajectory(&pose, truth.as_ref())?;
        self.steps.rec.station_metrics(&covariance, &predicted, error_xy_m);
        self.stations.push(StationRecord {
            index,
            pose,
            covariance,
            predicted_covariance: predicted,
            truth,
            error_xy_m,
            scan,
        });
        Ok(())
    }

    /// Reads the tilt, takes a 3D scan, writes it to `scans/` and fuses it
    /// directly with the CPS pose; returns the scan file's name.
    fn scan(&mut self, index: usize) -> Result<String> {
        let tilt: Tilted = self.steps.step(json!({"event": "tilt", "station": index}), DeviceKind::Tilt, |sim| {
            sim.tilt().map(|t| Tilted { roll_rad: t.roll_rad, pitch_rad: t.pitch_rad })
        })?;
        self.steps.rec.advance(TILT_S);
        let world_from_body =
            Tilt { roll_rad: tilt.roll_rad, pitch_rad: tilt.pitch_rad }.world_from_body(&self.team.parent());
        let name = format!("scans/scan{index:03}");
        let (dir, slices, bar, t) = (&self.dir, self.mission.scan.slices, &self.scan_bar, &mut self.timings);
        let mut taken = None;
        let scanned: Scanned =
            self.steps.step(json!({"event": "scan", "station": index}), DeviceKind::Scanner, |sim| {
                bar.reset();
                let scan = timed(&mut t.scan_s, || sim.scan(slices, &mut |done, _| bar.set_position(done as u64)))?;
                let cloud = PointCloud::from_points(scan.points);
                timed(&mut t.scan_files_s, || {
                    scanner::io::write(&dir.join(format!("{name}.3d")), &cloud, Format::ThreeDtk)?;
                    scanner::io::write_3dtk_pose(&dir.join(format!("{name}.pose")), &world_from_body)
                })?;
                let points = cloud.len();
                taken = Some(cloud);
                Ok(Scanned { file: format!("{name}.3d"), points })
            })?;
        let cloud = match taken {
            Some(cloud) => cloud,
            None => timed(&mut self.timings.scan_files_s, || scanner::io::read(&self.dir.join(&scanned.file)))?,
        };
        if cloud.len() != scanned.points {
            bail!("{}: {} points, but the journal recorded {}", scanned.file, cloud.len(), scanned.points);
        }
        let world = timed(&mut self.timings.fusion_s, || fusion::direct::transform(&cloud.points, &world_from_body));
        self.steps.rec.advance(slices as f64 / (75.0 * self.mission.scan.resolution.degrees()));
        if self.steps.rec.enabled() {
            let rec = &mut self.steps.rec;
            timed(&mut self.timings.recording_s, || rec.scan("direct", &format!("scan{index:03}"), world.clone()))?;
        }
        let truth = self.steps.sim.truth();
        let believed = self.steps.sim.parent_believed();
        let nominal_z = self.dance.station_pose(index).position.z;
        // The station joins the scan stations whose joint covariance the
        // team carries (a robot alone, by odometry, carries none).
        let cross_covariance = (0..self.team.clones().min(self.views.len()))
            .map(|a| self.team.parent_clone_covariance(a))
            .collect::<cps::Result<Vec<_>>>()?;
        self.team.clone_parent();
        let view = ScanView {
            station: index,
            file: scanned.file.clone(),
            // Direct fusion merges as it goes; the ICP modes need every scan at the end.
            body: if self.mission.fusion.mode == FusionMode::Direct { Vec::new() } else { cloud.points },
            pose: self.team.parent(),
            covariance: self.team.parent_covariance(),
            cross_covariance,
            tilt: Tilt { roll_rad: tilt.roll_rad, pitch_rad: tilt.pitch_rad },
            odometry: ParentPose::new(believed.x_m, believed.y_m, nominal_z, believed.heading_rad),
            truth: truth.map(|t| t.tilt.world_from_body(&t.parent)),
        };
        self.views.push(view);
        self.scan_times.push(self.steps.rec.now());
        if self.mission.fusion.mode == FusionMode::Direct {
            self.merged.extend(world);
        }
        Ok(scanned.file)
    }

    /// Fuses the scans by the mission's `[fusion] mode` (direct fusion has
    /// merged them already), logs the refined scans and their ICP RMSE.
    fn fuse(&mut self) -> Result<Fused> {
        let views = &self.views;
        let mode = self.mission.fusion.mode;
        let bar = &self.scan_bar;
        bar.set_prefix("fusion");
        let fused = timed(&mut self.timings.fusion_s, || {
            let trace = self.log_icp_iterations && self.steps.rec.enabled();
            let scanner = self.mission.scan.scanner_in_body();
            crate::fuse::fuse(views, mode, &self.mission.fusion, scanner, trace, &mut |done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            })
        })?;
        if mode == FusionMode::Direct {
            return Ok(fused);
        }
        // Each scan moved once, into the merged cloud and the recording.
        let rec = &mut self.steps.rec;
        if !fused.traces.is_empty() {
            let names: Vec<String> = views.iter().map(|v| format!("scan{:03}", v.station)).collect();
            let bodies: Vec<&[Point3<f32>]> = views.iter().map(|v| v.body.as_slice()).collect();
            timed(&mut self.timings.recording_s, || rec.icp_iterations(&fused.traces, &names, &bodies))?;
        }
        let (merged, t) = (&mut self.merged, &mut self.timings);
        for ((view, at), f) in views.iter().zip(&self.scan_times).zip(&fused.scans) {
            let world = timed(&mut t.fusion_s, || fusion::direct::transform(&view.body, &f.world_from_body));
            if rec.enabled() {
                timed(&mut t.recording_s, || -> Result<()> {
                    rec.scan_at("icp", &format!("scan{:03}", view.station), world.clone(), *at)?;
                    if let Some(rmse) = f.rmse_m {
                        rec.icp_metrics(at.0, rmse);
                    }
                    Ok(())
                })?;
            }
            merged.extend(world);
        }
        Ok(fused)
    }

    /// The merged cloud, the reports, the recording's series and the end
    /// of the journal.
    fn finish(mut self, started: Instant) -> Result<RunSummary> {
        self.steps.bar.finish_and_clear();
        let fused = self.fuse()?;
        self.scan_bar.finish_and_clear();
        let fusion = crate::fuse::report_json(&self.views, &fused);
        let merged = PointCloud::from_points(std::mem::take(&mut self.merged));
        timed(&mut self.timings.cloud_files_s, || -> Result<()> {
            for format in &self.mission.output.formats {
                let path = self.dir.join(format!("cloud.{format}"));
                scanner::io::write(&path, &merged, Format::from_path(&path)?)?;
            }
            Ok(())
        })?;
        let pipe = match &self.mission.pipe {
            Some(plan) => Some(self.inspect_pipe(plan, &merged.points)?),
            None => None,
        };
        // A pipe mission without its deviation report has not done its job.
        let pipe_failed = pipe.as_ref().is_some_and(|p| p.get("error").is_some());
        let accepted = mission_accepted(self.mission, &self.stations, &self.views, &fused) && !pipe_failed;
        self.steps.rec.event(
            rerun::TextLogLevel::INFO,
            format!("mission ends: acceptance {}", if accepted { "passed" } else { "FAILED" }),
        )?;
        let recording = std::mem::replace(&mut self.steps.rec, Recorder::disabled());
        timed(&mut self.timings.recording_s, || recording.finish())?;
        let results = Results { fusion: fusion.clone(), pipe: pipe.clone(), accepted };
        write_reports(
            self.mission,
            &self.dir,
            &self.stations,
            &results,
            started.elapsed().as_secs_f64(),
            &self.timings,
        )?;
        self.steps.note(json!({"event": "end"}), json!({"accepted": accepted}))?;
        let replayed = self.steps.replayed;
        Ok(RunSummary {
            dir: self.dir,
            stations: self.stations,
            points: merged.len(),
            accepted,
            replayed,
            fusion,
            pipe,
        })
    }

    /// The `[pipe]` inspection of the merged cloud: the deviation map
    /// written, the recording's `world/pipe/…`, `report.json`'s `pipe`. A
    /// fit that fails is reported (`{"error": …}`) after everything else
    /// has been written, not raised (a file that cannot be written is an
    /// error).
    fn inspect_pipe(&mut self, plan: &crate::mission::PipePlan, cloud: &[Point3<f32>]) -> Result<Value> {
        let started = Instant::now();
        let result = crate::pipe::inspect(plan, cloud);
        if let Ok(inspection) = &result {
            crate::pipe::write_deviation_map(&self.dir, cloud, inspection)?;
        }
        self.timings.pipe_s = Some(started.elapsed().as_secs_f64());
        match result {
            Ok(inspection) => {
                timed(&mut self.timings.recording_s, || self.steps.rec.pipe(cloud, &inspection, plan.threshold_m))?;
                Ok(crate::pipe::report_json(plan, &inspection))
            }
            Err(e) => {
                let message = format!("{e:#}");
                self.steps.rec.event(rerun::TextLogLevel::WARN, format!("pipe inspection failed: {message}"))?;
                Ok(json!({ "error": message }))
            }
        }
    }
}

/// What `report.json` says beyond the stations.
struct Results {
    fusion: Value,
    pipe: Option<Value>,
    accepted: bool,
}

/// Whether the mission's acceptance tolerances hold. A station's error is
/// that of the mission's result: the fused scan pose where an ICP mode
/// refined it, else the station's CPS (or odometry) pose.
fn mission_accepted(mission: &Mission, stations: &[StationRecord], views: &[ScanView], fused: &Fused) -> bool {
    let sigma_xy = stations.last().map_or(0.0, |s| cps::sigma_xy2(&s.covariance).sqrt());
    let refined = |index: usize| -> Option<f64> {
        if fused.mode == FusionMode::Direct {
            return None;
        }
        let (view, f) = views.iter().zip(&fused.scans).find(|(v, _)| v.station == index)?;
        view.truth.map(|truth| crate::fuse::error_xy(&f.world_from_body, &truth))
    };
    // Without a truth (serial ports) there is no station error to check.
    let max_error = stations.iter().filter_map(|s| refined(s.index).or(s.error_xy_m)).fold(0.0, f64::max);
    mission.acceptance.max_final_sigma_xy_m.is_none_or(|m| sigma_xy <= m)
        && mission.acceptance.max_station_error_m.is_none_or(|m| max_error <= m)
}

/// Writes `report.json` and `stations.csv`.
fn write_reports(
    mission: &Mission,
    dir: &Path,
    stations: &[StationRecord],
    results: &Results,
    wall_s: f64,
    timings: &Timings,
) -> Result<()> {
    let last = stations.last().context("a run has at least the start station")?;
    // Along the true path on the simulator, the estimated one on serial ports.
    let at = |s: &StationRecord| s.truth.unwrap_or(s.pose).position;
    let distance_m: f64 = stations.windows(2).map(|w| (at(&w[1]) - at(&w[0])).norm()).sum();
    let sigma_xy2 = cps::sigma_xy2(&last.covariance);
    let mut timings = serde_json::to_value(timings)?;
    timings["wall_s"] = json!(wall_s);
    let mut report = json!({
        "mission": mission.name,
        "seed": mission.backend.seed,
        "backend": if mission.backend.serial.is_some() { "serial" } else { "sim" },
        "scene": mission.backend.scene,
        "stations": stations.iter().map(|s| json!({
            "index": s.index,
            "pose": pose_json(&s.pose),
            "covariance": matrix_json(&s.covariance),
            "predicted_covariance": matrix_json(&s.predicted_covariance),
            "truth": s.truth.as_ref().map(pose_json),
            "error_m": s.error_xy_m,
            "scan": s.scan,
        })).collect::<Vec<_>>(),
        "final": {
            "distance_m": distance_m,
            "sigma_xy2_m2": sigma_xy2,
            "error_xy_m": last.error_xy_m,
            "drift_percent": last.error_xy_m.map(|e| if distance_m > 0.0 { 100.0 * e / distance_m } else { 0.0 }),
        },
        "fusion": results.fusion,
        "accepted": results.accepted,
        "timings": timings,
    });
    if let Some(pipe) = &results.pipe {
        report["pipe"] = pipe.clone();
    }
    std::fs::write(dir.join("report.json"), serde_json::to_string_pretty(&report)? + "\n")
        .with_context(|| format!("writing {}", dir.join("report.json").display()))?;
    let mut csv = String::from(
        "index,x_m,y_m,z_m,heading_rad,sigma_x_m,sigma_y_m,sigma_z_m,sigma_heading_rad,predicted_sigma_xy_m,true_x_m,true_y_m,true_z_m,true_heading_rad,error_xy_m\n",
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
        csv += &format!(
            "{},{},{},{},{},{},{},{},{},{},{}\n",
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
    std::fs::write(dir.join("stations.csv"), csv)
        .with_context(|| format!("writing {}", dir.join("stations.csv").display()))
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
            "{:>7} {:>10.3} {:>10.3} {:>9.2} {:>11.2} {:>11} {:>9}",
            st.index,
            st.pose.position.x,
            st.pose.position.y,
            1e3 * cps::sigma_xy2(&st.covariance).sqrt(),
            1e3 * cps::sigma_xy2(&st.predicted_covariance).sqrt(),
            st.error_xy_m.map_or("-".to_string(), |e| format!("{:.2}", 1e3 * e)),
            if st.scan.is_some() { "yes" } else { "-" }
        )?;
    }
    if let (Some(mode), Some(rms), Some(direct)) =
        (s.fusion["mode"].as_str(), s.fusion["rms_error_xy_m"].as_f64(), s.fusion["direct_rms_error_xy_m"].as_f64())
        && mode != "direct"
    {
        writeln!(
            out,
            "fusion {mode}: {} ICP matches; RMS horizontal error of the scan poses {:.2} mm (direct: {:.2} mm)",
            s.fusion["matches"],
            1e3 * rms,
            1e3 * direct
        )?;
    }
    if let Some(pipe) = &s.pipe {
        crate::pipe::write_summary(out, pipe)?;
    }
    if s.replayed > 0 {
        writeln!(out, "resumed: {} journal events replayed", s.replayed)?;
    }
    writeln!(
        out,
        "outputs in {} (report.json, stations.csv, journal.jsonl, scans/, cloud.*{}{})",
        s.dir.display(),
        if s.pipe.is_some() { format!(", {}", crate::pipe::DEVIATION_FILE) } else { String::new() },
        if mission.output.rerun { ", mission.rrd — view with: rerun mission.rrd" } else { "" }
    )?;
    writeln!(out, "acceptance: {}", if s.accepted { "passed" } else { "FAILED" })
}
