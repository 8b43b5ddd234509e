//! `mission.rrd`: the run as a Rerun recording a surveyor reads at a glance.
//!
//! Timelines `step` (one tick per journal step) and `sim_time` (nominal
//! seconds: drives at [`crate::run::observer::DRIVE_SPEED_M_PER_S`], [`crate::run::observer::MEASURE_S`] per total-station
//! measurement, [`crate::run::observer::TILT_S`] per tilt reading, the LMS's own slice rate per
//! scan). Entities:
//!
//! | path | archetype | when |
//! |---|---|---|
//! | `world` | `ViewCoordinates` RIGHT_HAND_Z_UP | static |
//! | `world/scene` | `Mesh3D` of the scene's surfaces | static |
//! | `world/robots/<name>` | `Transform3D` of the estimate | every step |
//! | `world/robots/<name>/body` | `Boxes3D` (parent) / `Points3D` (child) | static |
//! | `world/truth/<name>` (+ `/body`, dimmer) | true pose (sim) | every step |
//! | `world/trajectories/<name>/{estimate,truth}` | `LineStrips3D` | every parent fix |
//! | `world/uncertainty/<name>/{achieved,predicted}_95pct` | `Ellipsoids3D`, 95 % (3D χ²) | every step |
//! | `world/sight_lines/{placement,fix}` | `LineStrips3D`; fix lines coloured by Baarda \|w\| | each measurement |
//! | `world/scans/direct/scanNNN` | `Points3D`, voxel-thinned for display | each scan |
//! | `world/scans/icp/scanNNN` | the same at the ICP-refined pose, at its direct twin's time | ICP fusion modes |
//! | `metrics/{sigma_xy_m,predicted_sigma_xy_m,sigma_heading_rad,error_xy_m}` | `Scalars`, column-wise | each station |
//! | `metrics/fix_sigma0_squared` | `Scalars`, column-wise | each parent fix |
//! | `metrics/icp_rmse_m` | `Scalars`, column-wise, at each scan's step | ICP fusion modes |
//! | `world/pipe/deviation` | `Points3D` of the cloud coloured by deviation from the fitted pipe (blue inside, red outside, grey within the threshold) | `[pipe]`, at the end |
//! | `world/pipe/axis`, `world/pipe/anomalies` | `LineStrips3D` of the fitted axis; `Boxes3D` around each anomaly, labelled | likewise |
//! | `log` | `TextLog` of mission events, warnings for retries and blunders | as they happen |
//! | `world/scans/icp_iterations/scanNNN` (+ `/points`) | `Transform3D` of the scan per ICP iteration over `Points3D` in the scan's frame | `run --log-icp-iterations`, timeline `icp_iteration` |
//! | `metrics/icp_iteration_shift_m` | `Scalars`: how far each iteration moved its scan | likewise |
//!
//! The plan ([`Recorder::plan`]; also `plan`/`predict --rrd FILE`) on its own
//! timeline `plan_step` (the index of [`planner::Dance::steps`]):
//!
//! | path | archetype | when |
//! |---|---|---|
//! | `world/plan/route` | `LineStrips3D` through the parent's stations | static |
//! | `world/plan/stations` | `Points3D`; scan stations green | static |
//! | `world/plan/robots/<name>` | `Points3D` at the planned position | each move (and step 0) |
//! | `world/plan/moves` | `LineStrips3D` of the move, green, red if it breaks a constraint | each move |
//! | `world/plan/sight_lines` | `LineStrips3D` parent → child, green, red if it breaks a constraint | each measurement |
//! | `world/plan/uncertainty/<name>/predicted_95pct_x<k>` | `Ellipsoids3D`, 95 %, exaggerated ×k | each placement and fix |
//! | `world/plan/violations` | `Points3D`, red, every violation so far, labelled | each violating step |
//! | `plan/log` | `TextLog`: each violation described (warning) | each violating step |
//! | `plan/metrics/{predicted_sigma_xy_m,predicted_sigma_heading_rad}` | `Scalars`, column-wise | each parent fix |

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use nalgebra::Point3;
use planner::Violation;
use rerun::{RecordingStream, RecordingStreamBuilder};

use crate::mission::Mission;
use crate::planning::Planned;

pub use crate::view::target::{Layout, Viewer};
use colours::height_colour;

mod colours;
mod plan;
mod run;

/// Voxel for the display copy of each scan, metres.
pub const DISPLAY_VOXEL_M: f64 = 0.05;

/// The default layout: the 3D world large on the left, the series and the
/// log on the right, side panels collapsed, time on the run's timeline.
fn blueprint(layout: Layout) -> rerun::blueprint::Blueprint {
    use rerun::blueprint::components::PanelState;
    use rerun::blueprint::{
        Blueprint, BlueprintPanel, ContainerLike, Horizontal, SelectionPanel, Spatial3DView, TextLogView, TimePanel,
        TimeSeriesView, Vertical,
    };
    let (timeline, right): (&str, Vec<ContainerLike>) = match layout {
        Layout::Mission => (
            "step",
            vec![
                TimeSeriesView::new("σxy achieved, predicted, error to truth (m)")
                    .with_contents(["/metrics/sigma_xy_m", "/metrics/predicted_sigma_xy_m", "/metrics/error_xy_m"])
                    .into(),
                TimeSeriesView::new("parent fix σ0², ICP RMSE (m)")
                    .with_contents(["/metrics/fix_sigma0_squared", "/metrics/icp_rmse_m"])
                    .into(),
                TextLogView::new("events").with_origin("/log").into(),
            ],
        ),
        Layout::Plan => (
            "plan_step",
            vec![
                TimeSeriesView::new("predicted σxy (m), σθ (rad)").with_contents(["/plan/metrics/**"]).into(),
                TimeSeriesView::new("optimized: predicted σxy (m), σθ (rad)")
                    .with_contents(["/plan_optimized/metrics/**"])
                    .into(),
                TextLogView::new("violations").with_contents(["/plan/log"]).into(),
            ],
        ),
    };
    Blueprint::new(
        Horizontal::new([Spatial3DView::new("world").with_origin("/world").into(), Vertical::new(right).into()])
            .with_column_shares([2.0, 1.0]),
    )
    .with_blueprint_panel(BlueprintPanel::new().with_state(PanelState::Collapsed))
    .with_selection_panel(SelectionPanel::new().with_state(PanelState::Collapsed))
    .with_time_panel(TimePanel::new().with_state(PanelState::Collapsed).with_timeline(timeline))
}

/// Whether this build can record: it can (the `recording` feature).
pub fn available() -> Result<()> {
    Ok(())
}

/// The time series gathered during the run, sent column-wise at the end.
#[derive(Debug, Default)]
struct Series {
    station_steps: Vec<i64>,
    sigma_xy_m: Vec<f64>,
    predicted_sigma_xy_m: Vec<f64>,
    sigma_heading_rad: Vec<f64>,
    error_steps: Vec<i64>,
    error_xy_m: Vec<f64>,
    fix_steps: Vec<i64>,
    sigma0_squared: Vec<f64>,
    icp_steps: Vec<i64>,
    icp_rmse_m: Vec<f64>,
}

/// A scan to thin and log on the recorder's worker thread.
#[derive(Debug)]
struct ScanJob {
    path: String,
    points: Vec<Point3<f32>>,
    step: i64,
    sim_time_s: f64,
}

/// Logs a run to Rerun; a disabled recorder does nothing. Scans are thinned
/// and logged on a worker thread, so the mission does not wait for them.
#[derive(Debug)]
pub struct Recorder {
    rec: Option<RecordingStream>,
    scans: Option<(std::sync::mpsc::Sender<ScanJob>, std::thread::JoinHandle<Result<()>>)>,
    step: i64,
    sim_time_s: f64,
    robots: Vec<String>,
    series: Series,
    trajectories: BTreeMap<&'static str, Vec<[f32; 3]>>,
    /// The recording file, if any (named in its errors).
    file: Option<PathBuf>,
    /// The viewer's URL, if the recording streams to one.
    viewer: Option<String>,
}

/// How long the end of a recording waits for a viewer to take it.
pub const VIEWER_TIMEOUT: Duration = Duration::from_secs(10);

/// How long the end of a recording waits for a file that stopped growing.
pub const FILE_STALL: Duration = Duration::from_secs(5);

/// One wait of a flush, between looks at the file.
const FLUSH_SLICE: Duration = Duration::from_millis(500);

fn rr<T, E: std::error::Error + Send + Sync + 'static>(r: Result<T, E>) -> Result<T> {
    r.context("logging to the Rerun recording")
}

fn p32(p: &Point3<f64>) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

/// The most points of the deviation map logged to `world/pipe/deviation`.
pub const PIPE_DISPLAY_POINTS: usize = 400_000;

/// Logs a scan thinned to [`DISPLAY_VOXEL_M`], coloured by height.
fn log_scan(rec: &RecordingStream, path: String, points: &[Point3<f32>]) -> Result<()> {
    let thin = scanner::reduced_points(points, DISPLAY_VOXEL_M)?;
    let (lo, hi) = thin.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| (lo.min(p.z), hi.max(p.z)));
    let colours: Vec<rerun::Color> = thin.iter().map(|p| height_colour(p.z, lo, hi)).collect();
    rr(rec.log(
        path,
        &rerun::Points3D::new(thin.iter().map(|p| [p.x, p.y, p.z])).with_colors(colours).with_radii([0.015_f32]),
    ))
}

impl Recorder {
    /// A recorder that logs nothing.
    pub fn disabled() -> Self {
        Self {
            rec: None,
            scans: None,
            step: 0,
            sim_time_s: 0.0,
            robots: Vec::new(),
            series: Series::default(),
            trajectories: BTreeMap::new(),
            file: None,
            viewer: None,
        }
    }

    /// Records to `file` (when given) and to `viewer`; with neither, a
    /// disabled recorder. `robots` are the parent's and the children's names.
    pub fn new(mission: &str, file: Option<&Path>, viewer: &Viewer, robots: Vec<String>) -> Result<Self> {
        let builder = RecordingStreamBuilder::new("cps-survey").recording_name(mission);
        let file_sink = |path: &Path| -> Result<rerun::sink::FileSink> {
            rerun::sink::FileSink::new(path).with_context(|| format!("creating {}", path.display()))
        };
        let grpc = |url: &str| -> Result<rerun::sink::GrpcSink> {
            let uri =
                url.parse().with_context(|| format!("viewer URL {url}: expected rerun+http://HOST:PORT/proxy"))?;
            Ok(rerun::sink::GrpcSink::new(uri))
        };
        let url = match viewer {
            Viewer::None => None,
            Viewer::Spawn => {
                // Bound to the loopback interface: the viewer's default
                // (every interface) would serve the survey to the network.
                let options = rerun::SpawnOptions {
                    extra_args: vec!["--bind".into(), "127.0.0.1".into()],
                    ..rerun::SpawnOptions::default()
                };
                rerun::spawn(&options).context("starting the Rerun viewer (is `rerun` on the PATH?)")?;
                Some(format!("rerun+http://127.0.0.1:{}/proxy", rerun::DEFAULT_SERVER_PORT))
            }
            Viewer::Connect(url) => Some(url.clone()),
        };
        let viewer = url.clone();
        let rec = match (file, url) {
            (None, None) => return Ok(Self::disabled()),
            (Some(path), None) => rr(builder.set_sinks((file_sink(path)?,)))?,
            (None, Some(url)) => rr(builder.set_sinks((grpc(&url)?,)))?,
            (Some(path), Some(url)) => rr(builder.set_sinks((file_sink(path)?, grpc(&url)?)))?,
        };
        let (send, receive) = std::sync::mpsc::channel::<ScanJob>();
        let worker_rec = rec.clone();
        let worker = std::thread::Builder::new()
            .name("rerun-scans".into())
            .spawn(move || -> Result<()> {
                for job in receive {
                    // Time is per thread in Rerun: set it for each scan.
                    worker_rec.set_time_sequence("step", job.step);
                    worker_rec.set_duration_secs("sim_time", job.sim_time_s);
                    log_scan(&worker_rec, job.path, &job.points)?;
                }
                Ok(())
            })
            .context("starting the recording's scan thread")?;
        Ok(Self {
            rec: Some(rec),
            scans: Some((send, worker)),
            robots,
            file: file.map(Path::to_path_buf),
            viewer,
            ..Self::disabled()
        })
    }

    /// Sends the default layout (the viewer opens with it; "reset
    /// blueprint" in the viewer returns to it).
    pub fn layout(&mut self, layout: Layout) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        let activation = rerun::blueprint::BlueprintActivation { make_active: true, make_default: true };
        rr(blueprint(layout).send(rec, activation))
    }

    /// True when something is recorded.
    pub fn enabled(&self) -> bool {
        self.rec.is_some()
    }

    /// Advances both timelines: one step, `seconds` of nominal time.
    pub fn advance(&mut self, seconds: f64) {
        self.step += 1;
        self.sim_time_s += seconds;
        if let Some(rec) = &self.rec {
            rec.set_time_sequence("step", self.step);
            rec.set_duration_secs("sim_time", self.sim_time_s);
        }
    }

    /// The current (step, sim_time) position on the timelines.
    pub fn now(&self) -> (i64, f64) {
        (self.step, self.sim_time_s)
    }

    /// A mission event in the text log.
    fn event(&mut self, level: &'static str, text: String) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        rr(rec.log("log", &rerun::TextLog::new(text).with_level(level)))
    }

    /// An event of the mission, in the log.
    pub fn info(&mut self, text: impl Into<String>) -> Result<()> {
        self.event(rerun::TextLogLevel::INFO, text.into())
    }

    /// A warning (a retry, a blunder suspect), in the log.
    pub fn warn(&mut self, text: impl Into<String>) -> Result<()> {
        self.event(rerun::TextLogLevel::WARN, text.into())
    }

    /// An error that stops the mission, in the log.
    pub fn error(&mut self, text: impl Into<String>) -> Result<()> {
        self.event(rerun::TextLogLevel::ERROR, text.into())
    }

    /// Waits for the scans, sends the time series column-wise and flushes
    /// the recording. A viewer that does not take it within
    /// [`VIEWER_TIMEOUT`] (gone, never there, no display) is not an error:
    /// the warning is returned, the file is complete. A file that cannot be
    /// written (disk full) is an error naming it.
    pub fn finish(mut self) -> Result<Option<String>> {
        if let Some((send, worker)) = self.scans.take() {
            drop(send);
            worker.join().map_err(|_| anyhow::anyhow!("the recording's scan thread panicked"))??;
        }
        let Some(rec) = &self.rec else { return Ok(None) };
        let s = &self.series;
        let columns = |path: &str, steps: &[i64], values: &[f64]| -> Result<()> {
            if steps.is_empty() {
                return Ok(());
            }
            rr(rec.send_columns(
                path,
                [rerun::TimeColumn::new_sequence("step", steps.to_vec())],
                rr(rerun::Scalars::new(values.iter().copied()).columns_of_unit_batches())?,
            ))
        };
        columns("metrics/sigma_xy_m", &s.station_steps, &s.sigma_xy_m)?;
        columns("metrics/predicted_sigma_xy_m", &s.station_steps, &s.predicted_sigma_xy_m)?;
        columns("metrics/sigma_heading_rad", &s.station_steps, &s.sigma_heading_rad)?;
        columns("metrics/error_xy_m", &s.error_steps, &s.error_xy_m)?;
        columns("metrics/fix_sigma0_squared", &s.fix_steps, &s.sigma0_squared)?;
        columns("metrics/icp_rmse_m", &s.icp_steps, &s.icp_rmse_m)?;
        self.flush()
    }

    /// Flushes the recording, never waiting without end: rerun 0.36
    /// blocks for good on a file writer that failed (a full disk), so the
    /// wait goes on only while `mission.rrd` grows, and a stream left in
    /// that state is not dropped (its drop would block too).
    fn flush(&mut self) -> Result<Option<String>> {
        use rerun::sink::SinkFlushError;
        let Some(rec) = &self.rec else { return Ok(None) };
        let file = self.file.clone();
        let name = || file.as_ref().map_or_else(|| "the recording".to_string(), |f| f.display().to_string());
        let size = || file.as_ref().and_then(|f| std::fs::metadata(f).ok()).map(|m| m.len());
        let started = Instant::now();
        let (mut last_size, mut grew_at) = (size(), Instant::now());
        let failure = loop {
            match rec.flush_with_timeout(FLUSH_SLICE) {
                Ok(()) => return Ok(None),
                // The gRPC sink's failure: the viewer is gone or never
                // came; the file sink (flushed first) is complete.
                Err(e @ SinkFlushError::Failed { .. }) if self.viewer.is_some() && e.to_string().contains("gRPC") => {
                    let url = self.viewer.as_deref().unwrap_or_default();
                    return Ok(Some(viewer_warning(url, &e, file.as_deref())));
                }
                Err(SinkFlushError::Timeout) => {
                    let now = size();
                    if now != last_size {
                        (last_size, grew_at) = (now, Instant::now());
                    }
                    if let Some(url) = self.viewer.as_deref()
                        && started.elapsed() >= VIEWER_TIMEOUT
                        && grew_at.elapsed() >= FILE_STALL
                    {
                        std::mem::forget(self.rec.take());
                        let e = SinkFlushError::Timeout;
                        return Ok(Some(viewer_warning(url, &e, None)));
                    }
                    if self.viewer.is_none() && grew_at.elapsed() >= FILE_STALL {
                        break anyhow::anyhow!(
                            "not written: it stopped growing at {} bytes for {} s (is the disk full?)",
                            last_size.unwrap_or(0),
                            FILE_STALL.as_secs()
                        );
                    }
                }
                Err(e) => break anyhow::anyhow!("{e} (is the disk full?)"),
            }
        };
        std::mem::forget(self.rec.take());
        Err(failure.context(format!("writing {}", name())))
    }
}

/// What a run says when its viewer did not take the recording.
fn viewer_warning(url: &str, e: &rerun::sink::SinkFlushError, file: Option<&Path>) -> String {
    let kept = file.map_or_else(String::new, |f| format!("; {} is complete", f.display()));
    format!("the viewer at {url} did not take the recording within {} s ({e}){kept}", VIEWER_TIMEOUT.as_secs())
}

/// Writes a plan recording (`plan`/`predict --rrd FILE`): the scene and
/// each plan — its root (`plan`, `plan_optimized`), the plan and its
/// violations — on the `plan_step` timeline.
pub fn write_plan_rrd(mission: &Mission, path: &Path, plans: &[(&str, &Planned, &[Violation])]) -> Result<()> {
    let mut rec = Recorder::new(&mission.name, Some(path), &Viewer::None, mission.robot_labels())?;
    rec.layout(Layout::Plan)?;
    let scene = plans.first().and_then(|(_, p, _)| p.checked_scene());
    rec.world(scene)?;
    for (root, planned, violations) in plans {
        rec.plan(mission, planned, root, violations)?;
    }
    rec.finish().map(|_| ())
}
