//! `cps-survey run`: a mission end to end — the dance cycle by cycle, a
//! scan at each scan station, the scans fused by `[fusion] mode` (directly
//! with the CPS poses, by ICP, or both adjusted together), a journal of
//! every command and reading, and the outputs.
//!
//! Outputs in the run directory:
//! - `mission.toml` — the mission as run (a resume must use the same);
//! - `journal.jsonl` — see [`crate::journal`]: every command with its
//!   reading and the team's state after it, flushed as it happens;
//! - `scans/scanNNN.3d` + `.pose` — each scan in the body frame with its
//!   CPS `world_from_body` (3DTK layout), written before the journal
//!   references it;
//! - `report.json`, `stations.csv` — per-station estimate, covariance,
//!   prediction, truth and error ([`crate::products::report`]);
//! - `cloud.<format>` (and with `[pipe]` its deviation map) — the output
//!   stage ([`crate::products::outputs`]);
//! - `mission.rrd` — the Rerun recording ([`crate::view::recording`]).
//!
//! `--resume` replays the journal: each recorded reading is used as it was
//! and the simulated world is put back to its recorded state after each
//! step, so the run continues exactly where it stopped.
//!
//! Here the dance itself (start, cycle, placement, drive, station); in
//! `sightings` the total station's readings tested, measured again or
//! refused and the fixes; in `scan` a station's scan; in `finish` the
//! fusion, the outputs and the reports. Every device command goes through
//! the [`Dispatch`] (journal, replay, retries), everything shown through
//! the [`Observer`] (recording, progress, timings).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use cps::{ParentPose, TeamState, observe};
use nalgebra::{Matrix4, Point3, Vector3};
use planner::{CyclePrediction, DanceCycle};
use scanner::sim::Robot;
use scanner::{PlanarPose, Prism, Target};

mod finish;
mod scan;
mod sightings;

use super::backend::{DeviceKind, Fault};
use super::dispatch::Dispatch;
use super::observer::Observer;
use crate::documents::records::rows;
use crate::documents::run::{Remeasured, RunReport};
use crate::journal::{Derived, DriveKey, Driven, Event, FixKey, FixRecord, MeasureKey, Phase, StepKey};
use crate::mission::Mission;
use crate::planning::Planned;
use crate::products::fuse::ScanView;
use crate::products::outputs::CloudFiles;
use crate::products::report::StationRecord;
use crate::view::recording::{Layout, Recorder, Viewer};

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

/// A mission being run.
struct Run<'m> {
    mission: &'m Mission,
    planned: &'m Planned,
    dir: PathBuf,
    dispatch: Dispatch,
    obs: Observer,
    team: TeamState,
    /// The merged cloud's files, written a scan at a time (taken when
    /// finished), relative to the mission's cloud `origin`.
    cloud: Option<CloudFiles>,
    origin: Vector3<f64>,
    /// Every scan with its poses (body points kept for the ICP modes) and
    /// where it sits on the recording's timelines.
    views: Vec<ScanView>,
    scan_times: Vec<(i64, f64)>,
    stations: Vec<StationRecord>,
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
    crate::products::outputs::check_targets(
        mission,
        dir,
        &["report.json", "stations.csv", "adjustment.txt", "mission.rrd"],
    )?;
    let journal = super::resume::open(mission, planned, dir, options.resume, options.abort_after_events)?;
    std::fs::create_dir_all(dir.join("scans")).with_context(|| format!("creating {}", dir.join("scans").display()))?;
    // The cloud's files, filled as the scans come (direct fusion) or once
    // they are fused; their count is stated when they are finished.
    let cloud = CloudFiles::create(mission, dir, None)?;

    let team = super::backend::open(mission, &planned.dance, options.faults.clone())?;
    let rrd = mission.output.rerun.then(|| dir.join("mission.rrd"));
    let mut rec = Recorder::new(&mission.name, rrd.as_deref(), &options.viewer, mission.robot_labels())?;
    rec.layout(Layout::Mission)?;
    rec.scene(team.scene())?;
    rec.plan(mission, planned, "plan", &[])?;
    let obs = Observer::new(mission, planned, rec, options.quiet, options.log_icp_iterations)?;
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
    let dispatch = Dispatch {
        journal,
        team,
        max_retries: mission.backend.max_retries,
        retry_delay: Duration::from_secs_f64(mission.backend.retry_delay_s),
        resume_hint,
        replayed: 0,
    };
    let mut run = Run {
        mission,
        planned,
        dir: dir.to_path_buf(),
        dispatch,
        obs,
        team: state,
        cloud: Some(cloud),
        origin: mission.cloud_origin(),
        views: Vec::new(),
        scan_times: Vec::new(),
        stations: Vec::new(),
        remeasured: Vec::new(),
        control_index,
    };
    run.obs.info(format!("mission \"{}\" starts", mission.name))?;
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
        self.obs.at_station(cycle.from);
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
        let driven: Driven = self.dispatch.step(&mut self.obs, key, StepKey::Drive, DeviceKind::Drive, |team, _| {
            team.drive(Robot::Child(j), &goal).map(|o| Driven { distance_m: o.distance_m })
        })?;
        self.obs.drove(driven.distance_m);
        let target = Target { prism: Prism::Child(j), predicted: observe(from, at)? };
        let key = MeasureKey { cycle: cycle.cycle, phase: Phase::Placement, child: Some(j), control: None, attempt: 0 };
        let reading = self.placement_reading(key, &target, instrument)?;
        self.team.place_child(j, &reading, instrument)?;
        let placed = self.team.child(j).context("a placed child has a position")?;
        self.dispatch.team.relocalise_child(j, &placed)?;
        self.obs.placed(from, placed)
    }

    /// The parent drives to the cycle's station; returns its nominal pose.
    fn drive_parent(&mut self, cycle: &DanceCycle) -> Result<ParentPose> {
        let nominal = self.planned.dance.station_pose(cycle.to);
        let goal = PlanarPose::from(&nominal);
        let key = DriveKey { cycle: cycle.cycle, robot: "parent".into(), target: target_of(&goal) };
        let driven: Driven = self.dispatch.step(&mut self.obs, key, StepKey::Drive, DeviceKind::Drive, |team, _| {
            team.drive(Robot::Parent, &goal).map(|o| Driven { distance_m: o.distance_m })
        })?;
        self.obs.drove(driven.distance_m);
        Ok(nominal)
    }

    /// Whether the journal keeps every scan station's cross-covariances
    /// (versions 1 and 2: the team clones each scan station) rather than
    /// the chain's links (version 3).
    fn clones_scan_stations(&self) -> bool {
        self.dispatch.journal.version() < 3
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
        let believed = self.dispatch.team.parent_believed();
        let pose = ParentPose::new(believed.x_m, believed.y_m, nominal.position.z, believed.heading_rad);
        self.team = TeamState::new(pose, predicted.covariance, 0)?;
        self.dispatch.note(Event::Fix(Derived {
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
        let truth = self.dispatch.team.truth();
        self.obs.team(&self.team, truth.as_ref(), predicted)
    }

    /// The parent stands at station `index`: the scan if one is due, then
    /// the station's record.
    fn station(&mut self, index: usize, predicted: Matrix4<f64>) -> Result<()> {
        self.obs.at_station(index);
        let scan = if self.mission.scan.scans_at(index) { Some(self.scan(index)?) } else { None };
        let truth = self.dispatch.team.truth().map(|t| t.parent);
        let pose = self.team.parent();
        let error_xy_m = truth.map(|t| (pose.position.xy() - t.position.xy()).norm());
        let covariance = self.team.parent_covariance();
        self.obs.station(&pose, truth.as_ref(), &covariance, &predicted, error_xy_m)?;
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
