//! What a run shows while it goes — the Rerun recording, the progress bars
//! and where the wall time went — behind one value with one call per event
//! of the dance, so the runner's steps read like the dance.
//!
//! The recording's `sim_time` is a nominal clock: drives at
//! [`DRIVE_SPEED_M_PER_S`], [`MEASURE_S`] per total-station measurement,
//! [`TILT_S`] per tilt reading, the LMS's own slice rate per scan.

use std::time::Instant;

use anyhow::Result;
use cps::{ParentPose, TeamState};
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use nalgebra::{Matrix3, Matrix4, Point3};
use planner::CyclePrediction;

use crate::documents::adjustment::AdjustmentReport;
use crate::documents::run::Timings;
use crate::mission::Mission;
use crate::planning::Planned;
use crate::view::recording::Recorder;

/// Nominal drive speed for the recording's `sim_time`, m/s.
pub const DRIVE_SPEED_M_PER_S: f64 = 0.3;
/// Nominal duration of a total-station measurement (ATR lock, distance), s.
pub const MEASURE_S: f64 = 4.0;
/// Nominal duration of a tilt reading, s.
pub const TILT_S: f64 = 1.0;

/// The recording, the progress bars and the timings of a run.
#[derive(Debug)]
pub struct Observer {
    /// The recording (the output stage logs the clouds into it).
    pub rec: Recorder,
    progress: Progress,
    /// Where the wall time went.
    pub timings: Timings,
    log_icp_iterations: bool,
}

/// One sighting of a fix as shown: the point's name, where it is, its
/// largest |w| (the fix's reliability, [`cps::ParentFix::reliability`]).
#[derive(Debug, Clone)]
pub struct Shown {
    /// A child's name or `control point "NAME"`.
    pub name: String,
    /// Where the point is.
    pub at: Point3<f64>,
    /// Its reading's largest |w|.
    pub w: Option<f64>,
}

impl Observer {
    /// The observer of `mission` as `planned`: `rec` (already showing the
    /// scene and the plan), bars unless `quiet`.
    pub fn new(
        mission: &Mission,
        planned: &Planned,
        rec: Recorder,
        quiet: bool,
        log_icp_iterations: bool,
    ) -> Result<Self> {
        let progress = Progress::new(quiet, planned, mission)?;
        Ok(Self { rec, progress, timings: Timings::default(), log_icp_iterations })
    }

    /// A line of the mission's log.
    pub fn info(&mut self, text: impl Into<String>) -> Result<()> {
        self.rec.info(text)
    }

    /// A warning: a reading measured again, a retry, a failed adjustment.
    pub fn warn(&mut self, text: impl Into<String>) -> Result<()> {
        self.rec.warn(text)
    }

    /// The mission stopped: why.
    pub fn stopped(&mut self, text: impl Into<String>) -> Result<()> {
        self.rec.error(text)
    }

    /// The parent stands at (or leaves from) station `k`.
    pub fn at_station(&self, k: usize) {
        self.progress.steps.set_message(format!("station {} of {}", k + 1, self.progress.stations));
    }

    /// A robot drove `distance_m`.
    pub fn drove(&mut self, distance_m: f64) {
        self.rec.advance(distance_m / DRIVE_SPEED_M_PER_S);
        self.progress.steps.inc(1);
    }

    /// The total station measured a prism.
    pub fn measured(&mut self) {
        self.rec.advance(MEASURE_S);
        self.progress.steps.inc(1);
    }

    /// The standing parent at `from` placed a child at `placed`.
    pub fn placed(&mut self, from: &ParentPose, placed: Point3<f64>) -> Result<()> {
        self.rec.sight_lines("placement", &from.position, &[(placed, None)])
    }

    /// The parent resected its start `pose` from the control points at
    /// `control` (σ0² of the fix).
    pub fn resected(&mut self, pose: &ParentPose, control: &[Point3<f64>], sigma0_squared: f64) -> Result<()> {
        self.progress.steps.inc(1);
        let lines: Vec<(Point3<f64>, Option<f64>)> = control.iter().map(|p| (*p, None)).collect();
        self.rec.sight_lines("control", &pose.position, &lines)?;
        self.rec.fix_metrics(sigma0_squared);
        Ok(())
    }

    /// The parent fixed its `pose` in `cycle` from `sightings`: sight lines
    /// coloured by each reading's largest |w|, a warning for a possible
    /// blunder (|w| above [`cps::W_CRITICAL`]).
    pub fn fixed(&mut self, cycle: usize, pose: &ParentPose, sightings: &[Shown], sigma0_squared: f64) -> Result<()> {
        self.progress.steps.inc(1);
        for s in sightings {
            if let Some(w) = s.w.filter(|w| w.abs() > cps::W_CRITICAL) {
                self.rec.warn(format!(
                    "cycle {cycle}: the measurement of {} has |w| = {:.2} > {:.2}: a possible blunder",
                    s.name,
                    w.abs(),
                    cps::W_CRITICAL
                ))?;
            }
        }
        let lines: Vec<(Point3<f64>, Option<f64>)> = sightings.iter().map(|s| (s.at, s.w)).collect();
        self.rec.sight_lines("fix", &pose.position, &lines)?;
        self.rec.fix_metrics(sigma0_squared);
        Ok(())
    }

    /// The team's estimate and truth, with the prediction of the cycle.
    pub fn team(
        &mut self,
        team: &TeamState,
        truth: Option<&scanner::sim::Truth>,
        predicted: Option<&CyclePrediction>,
    ) -> Result<()> {
        let predicted: Option<(&Matrix4<f64>, &[Matrix3<f64>])> =
            predicted.map(|p| (&p.covariance, p.children_covariance.as_slice()));
        self.rec.team(team, truth, predicted)
    }

    /// A station's record: the estimate against the truth and the
    /// prediction.
    pub fn station(
        &mut self,
        pose: &ParentPose,
        truth: Option<&ParentPose>,
        covariance: &Matrix4<f64>,
        predicted: &Matrix4<f64>,
        error_xy_m: Option<f64>,
    ) -> Result<()> {
        self.rec.trajectory(pose, truth)?;
        self.rec.station_metrics(covariance, predicted, error_xy_m);
        Ok(())
    }

    /// The tilt sensor was read.
    pub fn tilted(&mut self) {
        self.rec.advance(TILT_S);
    }

    /// `scan` — the scanner's slices at station `index`, given a callback
    /// for each slice done — timed and shown on the scans' bar.
    pub fn scanning<T>(&mut self, index: usize, scan: impl FnOnce(&mut dyn FnMut(usize, usize)) -> T) -> T {
        let (bar, done) = (&self.progress.scans, self.progress.slices_done);
        bar.set_message(format!("scan at station {}", index + 1));
        timed(&mut self.timings.scan_s, || scan(&mut |slice, _| bar.set_position(done + slice as u64)))
    }

    /// A scan of `slices` slices is taken (or replayed); the recording's
    /// clock moves on by the scanner's time at `resolution_deg`.
    pub fn scanned(&mut self, slices: usize, resolution_deg: f64) {
        self.progress.slices_done += slices as u64;
        self.progress.scans.set_position(self.progress.slices_done);
        self.progress.steps.inc(1);
        self.rec.advance(slices as f64 / (75.0 * resolution_deg));
    }

    /// `f` counted as writing or reading scan files.
    pub fn scan_files<T>(&mut self, f: impl FnOnce() -> T) -> T {
        timed(&mut self.timings.scan_files_s, f)
    }

    /// `f` counted as fusion.
    pub fn fusing<T>(&mut self, f: impl FnOnce() -> T) -> T {
        timed(&mut self.timings.fusion_s, f)
    }

    /// A scan's points in the world, as `kind` (`direct`, `icp`) fused them,
    /// logged now — or at `at` — when there is a recording (`points` gives
    /// them, called only then).
    pub fn scan(
        &mut self,
        kind: &str,
        name: &str,
        at: Option<(i64, f64)>,
        points: impl FnOnce() -> Vec<Point3<f32>>,
    ) -> Result<()> {
        if !self.rec.enabled() {
            return Ok(());
        }
        let rec = &mut self.rec;
        timed(&mut self.timings.recording_s, || match at {
            Some(at) => rec.scan_at(kind, name, points(), at),
            None => rec.scan(kind, name, points()),
        })
    }

    /// Where the recording's clocks stand.
    pub fn now(&self) -> (i64, f64) {
        self.rec.now()
    }

    /// Whether every ICP iteration is to be logged.
    pub fn traces_icp(&self) -> bool {
        self.log_icp_iterations && self.rec.enabled()
    }

    /// `fuse` — the fusion, given a callback for each ICP match done (of
    /// how many) — timed, and shown on the scans' bar when it runs ICP.
    pub fn fusion<T>(&mut self, icp: bool, fuse: impl FnOnce(&mut dyn FnMut(usize, usize)) -> T) -> T {
        let bar = &self.progress.scans;
        if icp {
            bar.set_message("fusion: ICP matches");
        }
        timed(&mut self.timings.fusion_s, || {
            fuse(&mut |done, total| bar.set_message(format!("fusion: ICP match {done} of {total}")))
        })
    }

    /// Every ICP iteration of the fusion (`--log-icp-iterations`).
    pub fn icp_iterations(
        &mut self,
        traces: &[fusion::multiview::IcpTrace],
        names: &[String],
        bodies: &[&[Point3<f32>]],
    ) -> Result<()> {
        let rec = &mut self.rec;
        timed(&mut self.timings.recording_s, || rec.icp_iterations(traces, names, bodies))
    }

    /// A refined scan's last ICP residual, at its scan time `at`.
    pub fn icp_residual(&mut self, at: i64, rmse_m: f64) {
        self.rec.icp_metrics(at, rmse_m);
    }

    /// The network adjustment of `mission`'s readings.
    pub fn adjusted(&mut self, mission: &Mission, report: &AdjustmentReport) -> Result<()> {
        self.rec.adjustment(mission, report)
    }

    /// The dance and the scans are done: the bars go.
    pub fn dance_done(&self) {
        self.progress.steps.finish_and_clear();
    }

    /// The fusion is done.
    pub fn fusion_done(&self) {
        self.progress.scans.finish_and_clear();
    }

    /// The recording ends (its error, such as a full disk, returned to say
    /// after the reports are written); with whether there was one and the
    /// viewer's warning. The timings' wall time is set from `started`.
    pub fn finish(&mut self, started: Instant) -> (bool, Result<Option<String>>) {
        let recording = std::mem::replace(&mut self.rec, Recorder::disabled());
        let recorded = recording.enabled();
        let end = timed(&mut self.timings.recording_s, || recording.finish());
        self.timings.wall_s = started.elapsed().as_secs_f64();
        (recorded, end)
    }
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
}
