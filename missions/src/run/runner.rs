//! `cps-survey run`: a mission end to end — the dance cycle by cycle, a
//! scan at each scan station, the scans fused by `[fusion] mode` (directly
//! with the CPS poses, by ICP, or both adjusted together), a journal of
//! every command and reading, and the outputs.
//!
//! Outputs in the run directory:
//! - `mission.toml` — the mission as run (a resume must use the same);
//! - `journal.jsonl` — see [`crate::run::journal`]: every command with its
//!   reading and the team's state after it, flushed as it happens;
//! - `scans/scanNNN.3d` + `.pose` — each scan in the body frame with its
//!   CPS `world_from_body` (3DTK layout), written before the journal
//!   references it;
//! - `report.json`, `stations.csv` — per-station estimate, covariance,
//!   prediction, truth and error ([`crate::run::report`]);
//! - `cloud.<format>` (and with `[pipe]` its deviation map) — the output
//!   stage ([`crate::run::outputs`]);
//! - `mission.rrd` — the Rerun recording ([`crate::view::recording`]).
//!
//! `--resume` replays the journal: each recorded reading is used as it was
//! and the simulated world is put back to its recorded state after each
//! step, so the run continues exactly where it stopped.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use cps::screen::{FieldTest, Misclosure};
use cps::{FixOptions, ParentPose, Reading, TeamState, observe};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use nalgebra::{Matrix3, Matrix4, Point3, Vector3};
use planner::{CyclePrediction, DanceCycle};
use scanner::io::{Format, PointCloud};
use scanner::sim::Robot;
use scanner::{PlanarPose, Prism, Target, Tilt};

use super::backend::{DeviceKind, Fault, Team};
use super::fuse::{Correlation, Fused, ScanView};
use super::journal::{
    ChainRecord, Derived, DriveKey, Driven, EndKey, EndRecord, Event, FixKey, FixRecord, MeasureKey, Measured, Phase,
    Scanned, StationKey, StepKey, Stop, Tilted,
};
use super::outputs::{CloudFiles, Written};
use super::report::StationRecord;
use super::steps::Steps;
use crate::documents::adjustment::{AdjustmentOutcome, AdjustmentReport};
use crate::documents::records::rows;
use crate::documents::run::{FusionReport, Remeasured, RunReport, Timings};
use crate::mission::{FusionMode, Mission};
use crate::planning::Planned;
use crate::view::recording::{Layout, Recorder, Viewer};

/// Nominal drive speed for the recording's `sim_time`, m/s.
pub const DRIVE_SPEED_M_PER_S: f64 = 0.3;
/// Nominal duration of a total-station measurement (ATR lock, distance), s.
pub const MEASURE_S: f64 = 4.0;
/// Nominal duration of a tilt reading, s.
pub const TILT_S: f64 = 1.0;

/// How many times in one session a reading that fails a fix's field test
/// is measured again before the run stops (a resume measures again).
const MAX_REMEASURES: u32 = 2;

/// A total-station sighting of one point: what was aimed at, under which
/// journal key, and what was read.
#[derive(Debug, Clone)]
struct Sighting<'i> {
    key: MeasureKey,
    target: Target,
    /// The point's index in the team state (a child or a control point).
    point: usize,
    instrument: &'i cps::Instrument,
    reading: Reading,
}

/// A misclosure in words: "10.000 m, 0.0000°, 0.0000° off" style.
fn misclosure_words(m: &Misclosure) -> String {
    format!(
        "off by {:+.3} m, {:+.4}°, {:+.4}° (distance, azimuth, elevation)",
        m.slope_m,
        m.azimuth_rad.to_degrees(),
        m.elevation_rad.to_degrees()
    )
}

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

/// What a run returns.
#[derive(Debug, Clone)]
pub struct RunSummary {
    /// The run directory.
    pub dir: PathBuf,
    /// Every station, start included.
    pub stations: Vec<StationRecord>,
    /// Whether the mission's acceptance tolerances hold.
    pub accepted: bool,
    /// Journal events replayed from an earlier, interrupted run.
    pub replayed: usize,
    /// What the report says (`report.json`).
    pub report: RunReport,
    /// The files the run wrote, relative to its directory.
    pub files: Vec<String>,
    /// Points in the merged cloud.
    pub points: usize,
    /// Why the viewer (`--spawn`, `--connect`) did not get the recording.
    pub viewer_warning: Option<String>,
}

/// A drive goal as journaled: x, y, heading.
fn target_of(goal: &PlanarPose) -> [f64; 3] {
    [goal.x_m, goal.y_m, goal.heading_rad]
}

/// Adds the seconds `f` takes to `total`.
fn timed<T>(total: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    *total += t.elapsed().as_secs_f64();
    out
}

/// The progress bars: the dance's steps (station n of N, ETA) and the
/// scans' slices, both only ever moving forward.
#[derive(Debug)]
struct Progress {
    steps: ProgressBar,
    scans: ProgressBar,
    /// Slices of the scans already finished.
    slices_done: u64,
    stations: usize,
}

impl Progress {
    fn new(quiet: bool, planned: &Planned, mission: &Mission) -> Result<Self> {
        let target = if quiet { ProgressDrawTarget::hidden() } else { ProgressDrawTarget::stderr() };
        let multi = MultiProgress::with_draw_target(target);
        let style = |template: &str| -> Result<ProgressStyle> {
            Ok(ProgressStyle::with_template(template)
                .map_err(|e| anyhow::anyhow!("progress style: {e}"))?
                .progress_chars("=> "))
        };
        let n_scans = (0..planned.stations()).filter(|k| mission.scan.scans_at(*k)).count() as u64;
        let steps = multi.add(
            ProgressBar::new(planned.steps.len() as u64)
                .with_style(style("{prefix:>8} [{bar:36}] {pos}/{len} steps, {msg}, ETA {eta}")?),
        );
        steps.set_prefix("survey");
        steps.set_message("starting");
        let scans = multi.add(
            ProgressBar::new(n_scans * mission.scan.slices as u64)
                .with_style(style("{prefix:>8} [{bar:36}] {msg}, ETA {eta}")?),
        );
        scans.set_prefix("scans");
        scans.set_message(format!("{n_scans} scans of {} slices", mission.scan.slices));
        Ok(Self { steps, scans, slices_done: 0, stations: planned.stations() })
    }

    fn at_station(&self, k: usize) {
        self.steps.set_message(format!("station {} of {}", k + 1, self.stations));
    }
}

/// A mission being run.
struct Run<'m> {
    mission: &'m Mission,
    planned: &'m Planned,
    dir: PathBuf,
    steps: Steps,
    team: TeamState,
    progress: Progress,
    /// The merged cloud's files, written a scan at a time (taken when
    /// finished), relative to the mission's cloud `origin`.
    cloud: Option<CloudFiles>,
    origin: Vector3<f64>,
    /// Every scan with its poses (body points kept for the ICP modes) and
    /// where it sits on the recording's timelines.
    views: Vec<ScanView>,
    scan_times: Vec<(i64, f64)>,
    stations: Vec<StationRecord>,
    timings: Timings,
    log_icp_iterations: bool,
    /// The team state's index of the first control prism.
    control_index: usize,
    /// Readings measured again, in order.
    remeasured: Vec<Remeasured>,
}

/// Runs `mission` as `planned` into `dir`: a new run (an existing journal
/// there is an error, so a run is never overwritten), or with `resume` the
/// continuation of the run whose journal is there. A plan that breaks a
/// constraint (`cps-survey plan`) is refused before anything moves.
pub fn run(mission: &Mission, planned: &Planned, dir: &Path, options: &RunOptions) -> Result<RunSummary> {
    let started = Instant::now();
    crate::planning::constraints::refuse_violations(mission, planned)?;
    super::outputs::check_targets(mission, dir, &["report.json", "stations.csv", "adjustment.txt", "mission.rrd"])?;
    let journal = super::resume::open(mission, planned, dir, options.resume, options.abort_after_events)?;
    std::fs::create_dir_all(dir.join("scans")).with_context(|| format!("creating {}", dir.join("scans").display()))?;
    // The cloud's files, filled as the scans come (direct fusion) or once
    // they are fused; their count is stated when they are finished.
    let cloud = CloudFiles::create(mission, dir, None)?;

    let team = Team::new(mission, &planned.dance, options.faults.clone())?;
    let rrd = mission.output.rerun.then(|| dir.join("mission.rrd"));
    let mut rec = Recorder::new(&mission.name, rrd.as_deref(), &options.viewer, mission.robot_labels())?;
    rec.layout(Layout::Mission)?;
    rec.scene(team.scene())?;
    rec.plan(mission, planned, "plan", &[])?;
    let progress = Progress::new(options.quiet, planned, mission)?;
    let resume_hint = format!(
        "cps-survey run {} --out {} --resume",
        shell_word(&mission.source.file.display().to_string()),
        shell_word(&dir.display().to_string())
    );
    let mut state =
        TeamState::new(planned.dance.station_pose(0), mission.plan.start_covariance, planned.dance.n_children())?;
    let control_index = state.n_children();
    if let Some(instrument) = &mission.total_station {
        let points: Vec<_> =
            planned.dance.control.iter().map(|c| (c.position, c.prism_covariance(instrument))).collect();
        state.add_fixed_points(&points)?;
    }
    let steps = Steps {
        journal,
        team,
        rec,
        max_retries: mission.backend.max_retries,
        retry_delay: Duration::from_secs_f64(mission.backend.retry_delay_s),
        resume_hint,
        replayed: 0,
    };
    let mut run = Run {
        mission,
        planned,
        dir: dir.to_path_buf(),
        steps,
        team: state,
        progress,
        cloud: Some(cloud),
        origin: mission.cloud_origin(),
        views: Vec::new(),
        scan_times: Vec::new(),
        stations: Vec::new(),
        timings: Timings::default(),
        remeasured: Vec::new(),
        log_icp_iterations: options.log_icp_iterations,
        control_index,
    };
    run.steps.rec.info(format!("mission \"{}\" starts", mission.name))?;
    // The start: the parent stands at station 0, sights the control
    // points there (resecting its pose from two or more), and scans if due.
    run.start()?;
    run.log_team(None)?;
    run.station(0, planned.prediction.start)?;
    // The dance: cycle by cycle, the children placed ahead, the parent
    // moved and fixed from them, the new station scanned.
    for k in 0..planned.dance.cycles.len() {
        run.cycle(k)?;
    }
    // The scans fused, the outputs written, the journal closed.
    run.finish(started)
}

impl Run<'_> {
    /// One dance cycle: the children move to the formation and are placed
    /// from the standing parent; the parent moves, measures every child and
    /// fixes itself from them; then the station's scan.
    fn cycle(&mut self, k: usize) -> Result<()> {
        let cycle = &self.planned.dance.cycles[k];
        let predicted = &self.planned.prediction.cycles[k];
        self.progress.at_station(cycle.from);
        let Some(instrument) = &self.mission.total_station else {
            return self.solo_cycle(cycle, predicted);
        };
        let from = self.team.parent();
        for &j in &cycle.moved {
            self.place_child(cycle, j, &from, instrument)?;
            self.log_team(Some(predicted))?;
        }
        let nominal = self.drive_parent(cycle)?;
        self.fix_parent(cycle, &nominal, instrument)?;
        self.log_team(Some(predicted))?;
        self.station(cycle.to, predicted.covariance)
    }

    /// Child `j` drives to its formation point and the standing parent at
    /// `from` measures it: its placement.
    fn place_child(
        &mut self,
        cycle: &DanceCycle,
        j: usize,
        from: &ParentPose,
        instrument: &cps::Instrument,
    ) -> Result<()> {
        let at = &cycle.children[j];
        let goal = PlanarPose { x_m: at.x, y_m: at.y, heading_rad: 0.0 };
        let key = DriveKey { cycle: cycle.cycle, robot: self.mission.children[j].clone(), target: target_of(&goal) };
        let driven: Driven = self.steps.step(key, StepKey::Drive, DeviceKind::Drive, |team| {
            team.drive(Robot::Child(j), &goal).map(|o| Driven { distance_m: o.distance_m })
        })?;
        self.steps.rec.advance(driven.distance_m / DRIVE_SPEED_M_PER_S);
        self.progress.steps.inc(1);
        let target = Target { prism: Prism::Child(j), predicted: observe(from, at)? };
        let key = MeasureKey { cycle: cycle.cycle, phase: Phase::Placement, child: Some(j), control: None, attempt: 0 };
        let reading = self.placement_reading(key, &target, instrument)?;
        self.team.place_child(j, &reading, instrument)?;
        let placed = self.team.child(j).context("a placed child has a position")?;
        self.steps.team.relocalise_child(j, &placed)?;
        self.steps.rec.sight_lines("placement", &from.position, &[(placed, None)])
    }

    /// One total-station measurement of `target`, as `instrument` reads it;
    /// with whether the device took it (not the journal's replay).
    fn measure(&mut self, key: MeasureKey, target: &Target, instrument: &cps::Instrument) -> Result<(Reading, bool)> {
        let replayed = self.steps.replayed;
        let m: Measured = self
            .steps
            .step(key, StepKey::Measure, DeviceKind::TotalStation, |team| team.measure(target).map(Measured::new))?;
        self.steps.rec.advance(MEASURE_S);
        self.progress.steps.inc(1);
        Ok((m.measurement().to_reading(instrument), self.steps.replayed == replayed))
    }

    /// A placement's reading. It has no redundancy, so one grossly off the
    /// formation point (cps::screen's bounds, against the parent's estimate)
    /// is measured again, and taken when it is near the formation point or
    /// agrees with the one before it (the child stands off its point: its
    /// drive, not the reading). Refused after [`MAX_REMEASURES`] attempts
    /// in this session.
    fn placement_reading(
        &mut self,
        mut key: MeasureKey,
        target: &Target,
        instrument: &cps::Instrument,
    ) -> Result<Reading> {
        let (mut reading, _) = self.measure(key.clone(), target, instrument)?;
        let mut previous: Option<Reading> = None;
        let mut live = 0;
        loop {
            let off = Misclosure::between(&reading, &target.predicted);
            let agrees = previous.is_some_and(|p| !Misclosure::between(&reading, &p).is_gross());
            if !off.is_gross() || agrees {
                return Ok(reading);
            }
            let what = format!(
                "cycle {}: the placement reading of {} is {} from its formation point",
                key.cycle,
                self.prism_name(key.child.unwrap_or_default()),
                misclosure_words(&off)
            );
            if live >= MAX_REMEASURES {
                let why = format!("{what}, and {} measurements in this session disagree with each other", live + 1);
                return Err(self.refuse(&key, why));
            }
            self.steps.rec.warn(format!("{what}: measured again"))?;
            previous = Some(reading);
            key.attempt += 1;
            self.note_remeasured(key.child.unwrap_or_default(), &key, what);
            let (again, was_live) = self.measure(key.clone(), target, instrument)?;
            live += u32::from(was_live);
            reading = again;
        }
    }

    /// The parent's fix from `sightings` once they pass the field test
    /// ([`cps::screen::field_test`]), taken by the team. A reading the test
    /// names is measured again — the next attempt in the journal, the
    /// superseded one kept — up to [`MAX_REMEASURES`] times in this
    /// session; a fix that still fails is refused, never journaled as a
    /// position (issue 34, S7).
    fn checked_fix(&mut self, cycle: usize, station: usize, sightings: &mut [Sighting<'_>]) -> Result<cps::ParentFix> {
        let options = FixOptions::default();
        let mut live = vec![0; sightings.len()];
        loop {
            let readings: Vec<(usize, Reading, &cps::Instrument)> =
                sightings.iter().map(|s| (s.point, s.reading, s.instrument)).collect();
            let (k, off) = match cps::screen::field_test(&self.team, &readings, &options) {
                FieldTest::Passed => return Ok(self.team.fix_parent_mixed(&readings, &options)?),
                FieldTest::Culprit { index, misclosure } => (index, misclosure),
                FieldTest::Failed { error, worst, fix } => {
                    let why = match (error, worst) {
                        (Some(e), _) => format!("it fails: {e}"),
                        // Not the readings: the fix itself.
                        (None, _) if fix.is_some_and(|(converged, ..)| !converged) => format!(
                            "it does not converge in {} iterations",
                            fix.map_or(0, |(_, iterations, _)| iterations)
                        ),
                        (None, Some((k, m))) if !m.is_gross() => format!(
                            "its σ0² is {:.3e} (at most {:.0e}: the readings disagree far beyond their noise); the reading of {} is {} from it",
                            fix.map_or(f64::NAN, |(.., s)| s),
                            cps::screen::GROSS_SIGMA0_SQUARED,
                            self.prism_name(sightings[k].point),
                            misclosure_words(&m)
                        ),
                        (None, Some((k, m))) => format!(
                            "the reading of {} is {} from it, and {}",
                            self.prism_name(sightings[k].point),
                            misclosure_words(&m),
                            if sightings.len() < 3 {
                                "with two readings no single one can be named"
                            } else {
                                "no single reading explains it"
                            }
                        ),
                        (None, None) => "it does not converge".into(),
                    };
                    let what = format!(
                        "cycle {cycle}: the parent's fix at station {station} from {} readings: {why}",
                        sightings.len()
                    );
                    if live.iter().any(|n| *n >= MAX_REMEASURES) {
                        let key = sightings.last().map(|s| s.key.clone()).context("a fix has sightings")?;
                        return Err(self.refuse(&key, format!("{what}, also when measured again")));
                    }
                    // Too few readings to name one (two points): every one
                    // is measured again.
                    self.steps.rec.warn(format!("{what}: every reading measured again"))?;
                    for k in 0..sightings.len() {
                        self.remeasure(&mut sightings[k], &mut live[k], &what)?;
                    }
                    continue;
                }
            };
            let what = format!(
                "cycle {cycle}: the reading of {} is {} from the parent's fix at station {station} from the other {}",
                self.prism_name(sightings[k].point),
                misclosure_words(&off),
                sightings.len() - 1
            );
            if live[k] >= MAX_REMEASURES {
                let why = format!("{what}, also when measured again ({} time(s) in this session)", live[k]);
                return Err(self.refuse(&sightings[k].key, why));
            }
            self.steps.rec.warn(format!("{what}: a gross error; measured again"))?;
            self.remeasure(&mut sightings[k], &mut live[k], &what)?;
        }
    }

    /// Measures `sighting` again as its next attempt, `why`; counts it in
    /// `live` when the device took it.
    fn remeasure(&mut self, sighting: &mut Sighting<'_>, live: &mut u32, why: &str) -> Result<()> {
        sighting.key.attempt += 1;
        self.note_remeasured(sighting.point, &sighting.key, why.to_string());
        let (reading, was_live) = self.measure(sighting.key.clone(), &sighting.target, sighting.instrument)?;
        sighting.reading = reading;
        *live += u32::from(was_live);
        Ok(())
    }

    /// Notes the re-measurement `key` of the team state's point `point` for
    /// the report.
    fn note_remeasured(&mut self, point: usize, key: &MeasureKey, why: String) {
        let point = self.prism_name(point);
        self.remeasured.push(Remeasured { cycle: key.cycle, point, attempt: key.attempt, why });
    }

    /// Stops the run on a measurement that cannot be trusted: journals the
    /// stop (the readings stay) and returns the error with the resume hint.
    fn refuse(&mut self, key: &MeasureKey, why: String) -> anyhow::Error {
        let stop = Stop {
            device: DeviceKind::TotalStation.name().into(),
            error: why.clone(),
            step: StepKey::Measure(key.clone()),
        };
        if let Err(e) = self.steps.journal.append(Event::Stop(stop)) {
            return e;
        }
        if let Err(e) = self.steps.rec.error(format!("{why}: mission stopped")) {
            return e;
        }
        anyhow::anyhow!(
            "{why}. Nothing is taken as a position from it; the mission stopped cleanly and the journal keeps every \
             reading. Check the prisms and the instrument, then continue (it measures again) with: {}",
            self.steps.resume_hint
        )
    }

    /// The parent drives to the cycle's station; returns its nominal pose.
    fn drive_parent(&mut self, cycle: &DanceCycle) -> Result<ParentPose> {
        let nominal = self.planned.dance.station_pose(cycle.to);
        let goal = PlanarPose::from(&nominal);
        let key = DriveKey { cycle: cycle.cycle, robot: "parent".into(), target: target_of(&goal) };
        let driven: Driven = self.steps.step(key, StepKey::Drive, DeviceKind::Drive, |team| {
            team.drive(Robot::Parent, &goal).map(|o| Driven { distance_m: o.distance_m })
        })?;
        self.steps.rec.advance(driven.distance_m / DRIVE_SPEED_M_PER_S);
        self.progress.steps.inc(1);
        Ok(nominal)
    }

    /// The parent at station `station` (cycle `cycle`, 0 at the start),
    /// standing near `nominal`, sights every control point the plan has it
    /// sight there; each reading with the team-state index of the prism and
    /// its noise model (a control prism's centring is in its position).
    fn sight_control<'i>(
        &mut self,
        cycle: usize,
        station: usize,
        nominal: &ParentPose,
        instrument: &'i cps::Instrument,
    ) -> Result<Vec<Sighting<'i>>> {
        let mut sightings = Vec::new();
        for k in self.planned.dance.sighted_at(station).to_vec() {
            let control = &self.planned.dance.control[k];
            let target = Target { prism: Prism::Control(k), predicted: observe(nominal, &control.position)? };
            let key = MeasureKey {
                cycle,
                phase: Phase::Control,
                child: None,
                control: Some(control.name.clone()),
                attempt: 0,
            };
            let (reading, _) = self.measure(key.clone(), &target, instrument)?;
            sightings.push(Sighting { key, target, point: self.control_index + k, instrument, reading });
        }
        Ok(sightings)
    }

    /// At the start: the control points sighted from station 0, and with
    /// two or more the parent's pose by resection — journaled as the fix
    /// of cycle 0.
    fn start(&mut self) -> Result<()> {
        let Some(instrument) = self.mission.total_station.clone() else { return Ok(()) };
        let sighting = instrument.without_target_centring();
        let nominal = self.planned.dance.station_pose(0);
        let mut sightings = self.sight_control(0, 0, &nominal, &sighting)?;
        if !self.planned.dance.resects_start() {
            return Ok(());
        }
        let fix = self.checked_fix(0, 0, &mut sightings)?;
        self.journal_fix(0, 0, &fix)?;
        self.progress.steps.inc(1);
        let pose = self.team.parent();
        self.steps.team.relocalise_parent(&pose)?;
        let lines: Vec<(Point3<f64>, Option<f64>)> =
            self.planned.dance.sighted_at(0).iter().map(|&k| (self.planned.dance.control[k].position, None)).collect();
        self.steps.rec.sight_lines("control", &pose.position, &lines)?;
        self.steps.rec.fix_metrics(fix.sigma0_squared);
        Ok(())
    }

    /// Whether the journal keeps every scan station's cross-covariances
    /// (versions 1 and 2: the team clones each scan station) rather than
    /// the chain's links (version 3).
    fn clones_scan_stations(&self) -> bool {
        self.steps.journal.version() < 3
    }

    /// Journals a fix with what the scans' joint prior needs: its link in
    /// the chain of scan stations, or (a version 1 or 2 journal) its
    /// cross-covariances to every earlier scan station.
    fn journal_fix(&mut self, cycle: usize, station: usize, fix: &cps::ParentFix) -> Result<()> {
        let pose = self.team.parent();
        let (cross, chain) = if self.clones_scan_stations() {
            let cross = (0..self.team.clones())
                .map(|a| self.team.parent_clone_covariance(a).map(|c| rows(&c)))
                .collect::<cps::Result<Vec<_>>>()?;
            (Some(cross), None)
        } else {
            (None, Some(ChainRecord::of(&self.team)))
        };
        self.steps.note(Event::Fix(Derived {
            key: FixKey { cycle, station },
            data: FixRecord {
                pose: (&pose).into(),
                covariance: rows(&self.team.parent_covariance()),
                sigma0_squared: Some(fix.sigma0_squared),
                redundancy: Some(fix.redundancy),
                scan_cross_covariances: cross,
                chain,
                source: None,
            },
        }))
    }

    /// The parent, moved to near `nominal`, measures every child and every
    /// control point it sees there and fixes its pose from them (seed 003
    /// eqs 7–16); the fix is journaled, and every blunder suspect logged.
    fn fix_parent(&mut self, cycle: &DanceCycle, nominal: &ParentPose, instrument: &cps::Instrument) -> Result<()> {
        let mut sightings = Vec::with_capacity(cycle.children.len());
        for (j, at) in cycle.children.iter().enumerate() {
            let target = Target { prism: Prism::Child(j), predicted: observe(nominal, at)? };
            let key = MeasureKey { cycle: cycle.cycle, phase: Phase::Fix, child: Some(j), control: None, attempt: 0 };
            let (reading, _) = self.measure(key.clone(), &target, instrument)?;
            sightings.push(Sighting { key, target, point: j, instrument, reading });
        }
        let sighting = instrument.without_target_centring();
        let control = self.sight_control(cycle.cycle, cycle.to, nominal, &sighting)?;
        sightings.extend(control);
        let fix = self.checked_fix(cycle.cycle, cycle.to, &mut sightings)?;
        let pose = self.team.parent();
        self.steps.team.relocalise_parent(&pose)?;
        self.journal_fix(cycle.cycle, cycle.to, &fix)?;
        self.progress.steps.inc(1);
        // Sight lines coloured by each child's largest |w|; a blunder is logged.
        let reliability = fix.reliability();
        let mut lines = Vec::with_capacity(sightings.len());
        for (k, Sighting { point: j, .. }) in sightings.iter().enumerate() {
            let w = reliability.largest_w_of_point(k);
            if let Some(w) = w.filter(|w| w.abs() > cps::W_CRITICAL) {
                self.steps.rec.warn(format!(
                    "cycle {}: the measurement of {} has |w| = {:.2} > {:.2}: a possible blunder",
                    cycle.cycle,
                    self.prism_name(*j),
                    w.abs(),
                    cps::W_CRITICAL
                ))?;
            }
            lines.push((self.team.child(*j).context("a sighted child is placed")?, w));
        }
        self.steps.rec.sight_lines("fix", &pose.position, &lines)?;
        self.steps.rec.fix_metrics(fix.sigma0_squared);
        Ok(())
    }

    /// The name of the team state's point `j`: a child or a control point.
    fn prism_name(&self, j: usize) -> String {
        match j.checked_sub(self.control_index) {
            Some(k) => {
                format!("control point \"{}\"", self.planned.dance.control.get(k).map_or("?", |c| c.name.as_str()))
            }
            None => self.mission.children.get(j).cloned().unwrap_or_else(|| format!("child {j}")),
        }
    }

    /// A robot alone drives to the next station and takes the pose its
    /// odometry believes, with the dead-reckoning covariance.
    fn solo_cycle(&mut self, cycle: &DanceCycle, predicted: &CyclePrediction) -> Result<()> {
        let nominal = self.drive_parent(cycle)?;
        let believed = self.steps.team.parent_believed();
        let pose = ParentPose::new(believed.x_m, believed.y_m, nominal.position.z, believed.heading_rad);
        self.team = TeamState::new(pose, predicted.covariance, 0)?;
        self.steps.note(Event::Fix(Derived {
            key: FixKey { cycle: cycle.cycle, station: cycle.to },
            data: FixRecord {
                pose: (&pose).into(),
                covariance: rows(&predicted.covariance),
                sigma0_squared: None,
                redundancy: None,
                scan_cross_covariances: None,
                chain: None,
                source: Some("odometry".into()),
            },
        }))?;
        self.log_team(Some(predicted))?;
        self.station(cycle.to, predicted.covariance)
    }

    /// Logs the team's estimate, truth and ellipsoids to the recording, with
    /// the prediction of the cycle when given.
    fn log_team(&mut self, predicted: Option<&CyclePrediction>) -> Result<()> {
        let truth = self.steps.team.truth();
        let predicted: Option<(&Matrix4<f64>, &[Matrix3<f64>])> =
            predicted.map(|p| (&p.covariance, p.children_covariance.as_slice()));
        self.steps.rec.team(&self.team, truth.as_ref(), predicted)
    }

    /// The parent stands at station `index`: the scan if one is due, then
    /// the station's record.
    fn station(&mut self, index: usize, predicted: Matrix4<f64>) -> Result<()> {
        self.progress.at_station(index);
        let scan = if self.mission.scan.scans_at(index) { Some(self.scan(index)?) } else { None };
        let truth = self.steps.team.truth().map(|t| t.parent);
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
        let tilt: Tilted = self.steps.step(StationKey { station: index }, StepKey::Tilt, DeviceKind::Tilt, |team| {
            team.tilt().map(|t| Tilted { roll_rad: t.roll_rad, pitch_rad: t.pitch_rad })
        })?;
        self.steps.rec.advance(TILT_S);
        let world_from_body =
            Tilt { roll_rad: tilt.roll_rad, pitch_rad: tilt.pitch_rad }.world_from_body(&self.team.parent());
        let name = format!("scans/scan{index:03}");
        let (dir, slices, t) = (&self.dir, self.mission.scan.slices, &mut self.timings);
        let (bar, done) = (&self.progress.scans, self.progress.slices_done);
        bar.set_message(format!("scan at station {}", index + 1));
        let mut taken = None;
        let scanned: Scanned =
            self.steps.step(StationKey { station: index }, StepKey::Scan, DeviceKind::Scanner, |team| {
                let scan =
                    timed(&mut t.scan_s, || team.scan(slices, &mut |slice, _| bar.set_position(done + slice as u64)))?;
                let cloud = PointCloud::from_points(scan.points);
                let file = format!("{name}.3d");
                // The checksum of the bytes as they are written (no read-back).
                let crc = timed(&mut t.scan_files_s, || -> scanner::Result<u32> {
                    let crc = scanner::io::write_with_crc32(&dir.join(&file), &cloud, Format::ThreeDtk)?;
                    scanner::io::write_3dtk_pose(&dir.join(format!("{name}.pose")), &world_from_body)?;
                    Ok(crc)
                })?;
                let points = cloud.len();
                taken = Some(cloud);
                let crc32 = Some(crate::run::journal::crc32_hex(crc));
                Ok(Scanned { file, points, crc32, unix_time_s: Some(super::journal::unix_now()) })
            })?;
        self.progress.slices_done += slices as u64;
        self.progress.scans.set_position(self.progress.slices_done);
        self.progress.steps.inc(1);
        let cloud = match taken {
            Some(cloud) => cloud,
            None => {
                // Replayed: the file must be the one the journal names, and
                // its pose file (derived from the journal) is rewritten if
                // it went missing.
                crate::run::journal::check_scan_file(&self.dir, &scanned)?;
                let pose = self.dir.join(format!("{name}.pose"));
                if !pose.exists() {
                    scanner::io::write_3dtk_pose(&pose, &world_from_body)?;
                }
                timed(&mut self.timings.scan_files_s, || scanner::io::read(&self.dir.join(&scanned.file)))?
            }
        };
        if cloud.len() != scanned.points {
            bail!("{}: {} points, but the journal recorded {}", scanned.file, cloud.len(), scanned.points);
        }
        let origin = self.origin;
        let relative_from_body = super::fuse::relative(&origin, &world_from_body);
        let world = timed(&mut self.timings.fusion_s, || fusion::direct::transform(&cloud.points, &relative_from_body));
        self.steps.rec.advance(slices as f64 / (75.0 * self.mission.scan.resolution.degrees()));
        if self.steps.rec.enabled() {
            let (rec, points) = (&mut self.steps.rec, &cloud.points);
            timed(&mut self.timings.recording_s, || {
                let logged = super::fuse::recorded_world(&world, &origin, points, &world_from_body);
                rec.scan("direct", &format!("scan{index:03}"), logged)
            })?;
        }
        let truth = self.steps.team.truth();
        let believed = self.steps.team.parent_believed();
        let nominal_z = self.planned.dance.station_pose(index).position.z;
        // The station joins the scan stations whose joint covariance the
        // team carries (a robot alone, by odometry, carries none).
        let correlation = if self.clones_scan_stations() {
            let cross = (0..self.team.clones().min(self.views.len()))
                .map(|a| self.team.parent_clone_covariance(a))
                .collect::<cps::Result<Vec<_>>>()?;
            self.team.clone_parent();
            Correlation::Earlier(cross)
        } else {
            let link = ChainRecord::of(&self.team).link(&format!("scan station {index}"))?;
            self.team.set_anchor();
            Correlation::Chain(link)
        };
        let view = ScanView {
            station: index,
            file: scanned.file.clone(),
            // Direct fusion merges as it goes; the ICP modes need every scan at the end.
            body: if self.mission.fusion.mode == FusionMode::Direct { Vec::new() } else { cloud.points },
            pose: self.team.parent(),
            covariance: self.team.parent_covariance(),
            correlation,
            tilt: Tilt { roll_rad: tilt.roll_rad, pitch_rad: tilt.pitch_rad },
            odometry: ParentPose::new(believed.x_m, believed.y_m, nominal_z, believed.heading_rad),
            truth: truth.map(|t| t.tilt.world_from_body(&t.parent)),
            gps_time_s: scanned.unix_time_s.map(scanner::io::gps_time_of_unix),
        };
        if self.mission.fusion.mode == FusionMode::Direct {
            let part = super::fuse::part(world, &view, &world_from_body, &origin);
            let cloud = self.cloud.as_mut().ok_or_else(|| anyhow::anyhow!("the cloud's files are already finished"))?;
            cloud.push(&part, &mut self.timings)?;
        }
        self.views.push(view);
        self.scan_times.push(self.steps.rec.now());
        Ok(scanned.file)
    }

    /// Fuses the scans by the mission's `[fusion] mode` (direct fusion has
    /// merged them already), logs the refined scans and their ICP RMSE.
    fn fuse(&mut self) -> Result<Fused> {
        let views = &self.views;
        let mode = self.mission.fusion.mode;
        let bar = &self.progress.scans;
        if mode != FusionMode::Direct {
            bar.set_message("fusion: ICP matches");
        }
        let fused = timed(&mut self.timings.fusion_s, || {
            let trace = self.log_icp_iterations && self.steps.rec.enabled();
            let scanner = self.mission.scan.scanner_in_body();
            super::fuse::fuse(views, mode, &self.mission.fusion, scanner, trace, &mut |done, total| {
                bar.set_message(format!("fusion: ICP match {done} of {total}"));
            })
        })?;
        if mode == FusionMode::Direct {
            return Ok(fused);
        }
        // Each scan moved once, into the cloud's files and the recording.
        let rec = &mut self.steps.rec;
        if !fused.traces.is_empty() {
            let names: Vec<String> = views.iter().map(|v| format!("scan{:03}", v.station)).collect();
            let bodies: Vec<&[Point3<f32>]> = views.iter().map(|v| v.body.as_slice()).collect();
            timed(&mut self.timings.recording_s, || rec.icp_iterations(&fused.traces, &names, &bodies))?;
        }
        let (cloud, t, origin) = (&mut self.cloud, &mut self.timings, self.origin);
        let cloud = cloud.as_mut().ok_or_else(|| anyhow::anyhow!("the cloud's files are already finished"))?;
        for ((view, at), f) in views.iter().zip(&self.scan_times).zip(&fused.scans) {
            let relative_from_body = super::fuse::relative(&origin, &f.world_from_body);
            let world = timed(&mut t.fusion_s, || fusion::direct::transform(&view.body, &relative_from_body));
            if rec.enabled() {
                timed(&mut t.recording_s, || -> Result<()> {
                    let logged = super::fuse::recorded_world(&world, &origin, &view.body, &f.world_from_body);
                    rec.scan_at("icp", &format!("scan{:03}", view.station), logged, *at)?;
                    if let Some(rmse) = f.rmse_m {
                        rec.icp_metrics(at.0, rmse);
                    }
                    Ok(())
                })?;
            }
            cloud.push(&super::fuse::part(world, view, &f.world_from_body, &origin), t)?;
        }
        Ok(fused)
    }

    /// The network adjustment of the journal's readings (with a total
    /// station): its listing `adjustment.txt` and its place in the
    /// recording; a network that cannot be adjusted is reported, not raised.
    fn adjust(&mut self) -> Result<Option<AdjustmentOutcome>> {
        if self.mission.total_station.is_none() {
            return Ok(None);
        }
        let path = self.dir.join("journal.jsonl");
        let read = super::journal::read_without_cross_covariances(&path)?;
        let report = super::adjust::network(self.mission, self.planned, &read, &path).and_then(|net| {
            super::adjust::adjust(self.mission, self.planned, &net, &cps::batch::AdjustOptions::default())
        });
        Ok(Some(match report {
            Ok(report) => {
                let listing = self.dir.join("adjustment.txt");
                scanner::io::replace_file(&listing, crate::view::listing::listing(self.mission, &report).as_bytes())
                    .with_context(|| format!("writing {}", listing.display()))?;
                self.steps.rec.adjustment(self.mission, &report)?;
                AdjustmentOutcome::Adjusted(Box::new(report))
            }
            Err(e) => {
                let error = format!("{e:#}");
                self.steps.rec.warn(format!("network adjustment failed: {error}"))?;
                AdjustmentOutcome::Failed { error }
            }
        }))
    }

    /// The fusion, the output stage, the reports, the recording's end and
    /// the end of the journal.
    fn finish(mut self, started: Instant) -> Result<RunSummary> {
        self.progress.steps.finish_and_clear();
        let fused = self.fuse()?;
        super::fuse::write_frames(&self.dir.join("scans"), &self.views, &fused)?;
        self.progress.scans.finish_and_clear();
        let fusion = FusionReport::new(&self.views, &fused);
        let cloud = self.cloud.take().ok_or_else(|| anyhow::anyhow!("the cloud's files are already finished"))?;
        let written: Written = cloud.finish(self.mission, &self.dir, &mut self.steps.rec, &mut self.timings)?;
        let adjustment = self.adjust()?;
        let adjusted = adjustment.as_ref().and_then(AdjustmentOutcome::report);
        let accepted = mission_accepted(self.mission, &self.stations, &self.views, &fused, adjusted)
            && written.complete()
            && !matches!(adjustment, Some(AdjustmentOutcome::Failed { .. }));
        self.steps.rec.info(format!("mission ends: acceptance {}", if accepted { "passed" } else { "FAILED" }))?;
        let recording = std::mem::replace(&mut self.steps.rec, Recorder::disabled());
        let recorded = recording.enabled();
        // The recording's end is not allowed to cost the reports: they are
        // written whatever it says, and its error (a full disk) comes after.
        let recording_end = timed(&mut self.timings.recording_s, || recording.finish());
        self.timings.wall_s = started.elapsed().as_secs_f64();
        let mut report = RunReport::new(
            self.mission,
            &self.stations,
            fusion,
            written.pipe.clone(),
            accepted,
            self.timings,
            self.remeasured,
        )?;
        report.adjustment = adjustment;
        crate::documents::write_file(&self.dir.join("report.json"), &report)?;
        let adjusted = report.adjustment.as_ref().and_then(AdjustmentOutcome::report);
        super::report::write_stations_csv(&self.dir.join("stations.csv"), &self.stations, adjusted)?;
        let viewer_warning = recording_end.map_err(|e| {
            anyhow::anyhow!(
                "{e:#}; report.json and stations.csv are written, `run --resume` writes the recording again"
            )
        })?;
        self.steps.note(Event::End(Derived { key: EndKey {}, data: EndRecord { accepted } }))?;
        let mut files: Vec<String> =
            ["mission.toml", "journal.jsonl", "scans/", "report.json", "stations.csv"].map(String::from).to_vec();
        if adjusted.is_some() {
            files.push("adjustment.txt".into());
        }
        files.extend(written.files);
        if recorded {
            files.push("mission.rrd".into());
        }
        Ok(RunSummary {
            dir: self.dir,
            stations: self.stations,
            accepted,
            replayed: self.steps.replayed,
            report,
            files,
            points: written.points,
            viewer_warning,
        })
    }
}

/// Whether the mission's acceptance tolerances hold. A station's error is
/// that of the mission's result: the fused scan pose where an ICP mode
/// refined it, else the station's CPS (or odometry) pose. Every station's
/// σxy is the network adjustment's where there is one, else the filter's.
fn mission_accepted(
    mission: &Mission,
    stations: &[StationRecord],
    views: &[ScanView],
    fused: &Fused,
    adjusted: Option<&AdjustmentReport>,
) -> bool {
    let sigma_xy = stations.last().map_or(0.0, |s| cps::sigma_xy2(&s.covariance).sqrt());
    let worst_station = match adjusted {
        Some(a) => a.stations.iter().map(|s| s.sigma_xy_m).fold(0.0, f64::max),
        None => stations.iter().map(|s| cps::sigma_xy2(&s.covariance).sqrt()).fold(0.0, f64::max),
    };
    let refined = |index: usize| -> Option<f64> {
        if fused.mode == FusionMode::Direct {
            return None;
        }
        let (view, f) = views.iter().zip(&fused.scans).find(|(v, _)| v.station == index)?;
        view.truth.map(|truth| super::fuse::error_xy(&f.world_from_body, &truth))
    };
    // Without a truth (serial ports) there is no station error to check.
    let max_error = stations.iter().filter_map(|s| refined(s.index).or(s.error_xy_m)).fold(0.0, f64::max);
    mission.acceptance.max_final_sigma_xy_m.is_none_or(|m| sigma_xy <= m)
        && mission.acceptance.max_station_error_m.is_none_or(|m| max_error <= m)
        && mission.acceptance.max_station_sigma_xy_m.is_none_or(|m| worst_station <= m)
}

/// The points of `cloud` within `tolerance_m` of the scene's surfaces, as a
/// fraction (used to check a fused cloud).
pub fn on_surface_fraction(scene: &cps::geom::Scene, cloud: &[Point3<f32>], tolerance_m: f64) -> f64 {
    let near = cloud.iter().filter(|p| scene.bvh().distance(&p.cast()).0 <= tolerance_m).count();
    near as f64 / cloud.len().max(1) as f64
}

/// `word` as one word of a POSIX shell command, to paste as it is printed:
/// unchanged when it holds only characters no shell treats specially, else
/// in single quotes ("--out out dir" split the directory in two).
pub fn shell_word(word: &str) -> String {
    if !word.is_empty() && word.chars().all(|c| c.is_ascii_alphanumeric() || "_./:@%+=,-".contains(c)) {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', "'\\''"))
    }
}

#[cfg(test)]
mod tests {
    use super::shell_word;

    #[test]
    fn a_path_with_spaces_or_quotes_is_one_shell_word() {
        assert_eq!(shell_word("runs/hall"), "runs/hall");
        assert_eq!(shell_word("out dir"), "'out dir'");
        assert_eq!(shell_word("it's"), "'it'\\''s'");
        assert_eq!(shell_word("$HOME"), "'$HOME'");
        assert_eq!(shell_word(""), "''");
    }
}
