//! `mission.rrd`: the run as a Rerun recording a surveyor reads at a glance.
//!
//! Timelines `step` (one tick per journal step) and `sim_time` (nominal
//! seconds: drives at [`crate::run::runner::DRIVE_SPEED_M_PER_S`], [`crate::run::runner::MEASURE_S`] per total-station
//! measurement, [`crate::run::runner::TILT_S`] per tilt reading, the LMS's own slice rate per
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
use cps::geom::Scene;
use cps::{CHI2_3D_95_SQRT, ParentPose, TeamState};
use nalgebra::{Matrix3, Matrix4, Point3, SymmetricEigen, UnitQuaternion};
use planner::{Action, Dance, Robot, Step, StepEstimate, Violation};
use rerun::{RecordingStream, RecordingStreamBuilder};

use super::shapes::{ellipse_scale, ellipse_scale_name, scene_mesh};
use crate::mission::Mission;
use crate::planning::Planned;
use crate::run::adjust::AdjustmentReport;
use crate::run::inspection::{Inspection, label};

/// Voxel for the display copy of each scan, metres.
pub const DISPLAY_VOXEL_M: f64 = 0.05;

/// The plan to log under `world/plan/` ([`Recorder::plan`]).
#[derive(Debug, Clone, Copy)]
pub struct PlanLog<'a> {
    /// Entity root: `plan` (as written) or `plan_optimized`; the 3D
    /// entities go under `world/<root>/`, the log and metrics under `<root>/`.
    pub root: &'a str,
    /// The schedule.
    pub dance: &'a Dance,
    /// Its steps ([`Dance::steps`] with the mission's scan stations).
    pub steps: &'a [Step],
    /// Every robot's predicted estimate ([`planner::step_estimates`]).
    pub estimates: &'a [StepEstimate],
    /// Constraints broken, each with its description.
    pub violations: &'a [(Violation, String)],
    /// Robot names: the parent's, then the children's in team order.
    pub names: &'a [String],
}

impl PlanLog<'_> {
    fn name(&self, r: Robot) -> String {
        let k = match r {
            Robot::Parent => 0,
            Robot::Child(j) => j + 1,
        };
        self.names.get(k).cloned().unwrap_or_else(|| format!("robot{k}"))
    }

    /// The ellipsoids' exaggeration: the largest 95 % half axis drawn at
    /// most half a station gap long (1-2-5 steps).
    pub fn ellipsoid_scale(&self) -> f64 {
        let largest = self
            .estimates
            .iter()
            .map(|e| ellipsoid_95(&e.covariance.fixed_view::<3, 3>(0, 0).into_owned()).0)
            .flat_map(|h| h.into_iter().map(f64::from))
            .fold(0.0, f64::max);
        let mut gaps: Vec<f64> =
            self.dance.stations.windows(2).map(|w| (w[1].position - w[0].position).norm()).collect();
        gaps.sort_by(f64::total_cmp);
        ellipse_scale(largest, 0.5 * gaps.get(gaps.len() / 2).copied().unwrap_or(1.0))
    }
}

fn green() -> rerun::Color {
    rerun::Color::from_rgb(40, 170, 70)
}

fn red() -> rerun::Color {
    rerun::Color::from_rgb(220, 40, 40)
}

/// Which default layout a recording opens with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// A run: the world, the accuracy series, fix σ0², the event log.
    Mission,
    /// A plan (`--rrd`): the world, the predicted series, the violations.
    Plan,
}

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

/// Where the recording goes besides `mission.rrd`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum Viewer {
    /// The file only.
    #[default]
    None,
    /// Start a viewer (`rerun` on the PATH) and stream to it too.
    Spawn,
    /// Stream to a running viewer at this URL too
    /// (e.g. `rerun+http://127.0.0.1:9876/proxy`).
    Connect(String),
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

/// The 95 % ellipsoid of a 3×3 position covariance: half sizes along the
/// eigenvectors and the rotation to them.
pub fn ellipsoid_95(cov: &Matrix3<f64>) -> ([f32; 3], rerun::Quaternion) {
    let eig = SymmetricEigen::new(*cov);
    let mut v = eig.eigenvectors;
    if v.determinant() < 0.0 {
        v.column_mut(2).neg_mut();
    }
    let q = UnitQuaternion::from_matrix(&v).coords;
    let h = eig.eigenvalues.map(|l| (CHI2_3D_95_SQRT * l.max(0.0).sqrt()) as f32);
    ([h.x, h.y, h.z], rerun::Quaternion::from_xyzw([q.x as f32, q.y as f32, q.z as f32, q.w as f32]))
}

/// Colour of a fix sight line by Baarda's |w|: green below 2, amber up to
/// the critical value, red above; grey when nothing checks the observation.
pub fn w_colour(w: Option<f64>) -> rerun::Color {
    match w.map(f64::abs) {
        None => rerun::Color::from_rgb(150, 150, 150),
        Some(w) if w < 2.0 => rerun::Color::from_rgb(40, 200, 80),
        Some(w) if w <= cps::W_CRITICAL => rerun::Color::from_rgb(240, 170, 30),
        Some(_) => rerun::Color::from_rgb(230, 40, 40),
    }
}

/// The most points of the deviation map logged to `world/pipe/deviation`.
pub const PIPE_DISPLAY_POINTS: usize = 400_000;

/// Colour of a deviation from a fitted surface: grey within `threshold_m`,
/// then towards full blue (inside) or red (outside) at twice it.
fn deviation_colour(deviation_m: f64, threshold_m: f64) -> rerun::Color {
    let t = (deviation_m.abs() / threshold_m.max(1e-9) - 1.0).clamp(0.0, 1.0);
    if deviation_m.abs() <= threshold_m {
        return rerun::Color::from_rgb(190, 190, 190);
    }
    let mix = |from: f64, to: f64| (from + (to - from) * (0.5 + 0.5 * t)) as u8;
    if deviation_m < 0.0 {
        rerun::Color::from_rgb(mix(190.0, 30.0), mix(190.0, 80.0), mix(190.0, 240.0))
    } else {
        rerun::Color::from_rgb(mix(190.0, 235.0), mix(190.0, 40.0), mix(190.0, 40.0))
    }
}

/// Colour by height within `[lo, hi]` (blue → green → red).
fn height_colour(z: f32, lo: f32, hi: f32) -> rerun::Color {
    let t = ((z - lo) / (hi - lo).max(1e-3)).clamp(0.0, 1.0);
    let (r, g, b) = if t < 0.5 { (0.0, 2.0 * t, 1.0 - 2.0 * t) } else { (2.0 * t - 1.0, 2.0 - 2.0 * t, 0.0) };
    rerun::Color::from_rgb((40.0 + 215.0 * r) as u8, (40.0 + 215.0 * g) as u8, (40.0 + 215.0 * b) as u8)
}

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

    /// Static content: axes convention, the scene, the robots' bodies.
    pub fn scene(&mut self, scene: &Scene) -> Result<()> {
        self.world(Some(scene))?;
        let Some(rec) = &self.rec else { return Ok(()) };
        for (k, name) in self.robots.iter().enumerate() {
            for (root, alpha) in [("robots", 255), ("truth", 90)] {
                let path = format!("world/{root}/{name}/body");
                if k == 0 {
                    let colour = rerun::Color::from_unmultiplied_rgba(60, 120, 230, alpha);
                    rr(rec.log_static(
                        path,
                        &rerun::Boxes3D::from_half_sizes([[0.35_f32, 0.25, 0.2]]).with_colors([colour]),
                    ))?;
                } else {
                    let colour = rerun::Color::from_unmultiplied_rgba(240, 140, 40, alpha);
                    rr(rec.log_static(
                        path,
                        &rerun::Points3D::new([[0.0_f32, 0.0, 0.0]]).with_radii([0.08_f32]).with_colors([colour]),
                    ))?;
                }
            }
        }
        Ok(())
    }

    /// The axes convention and, when given, the scene (static).
    pub fn world(&mut self, scene: Option<&Scene>) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        rr(rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP()))?;
        if let Some(scene) = scene {
            let (vertices, triangles) = scene_mesh(scene);
            rr(rec.log_static(
                "world/scene",
                &rerun::Mesh3D::new(vertices)
                    .with_triangle_indices(triangles)
                    .with_albedo_factor(rerun::datatypes::Rgba32::from_unmultiplied_rgba(200, 200, 210, 60)),
            ))?;
        }
        Ok(())
    }

    /// A mission's plan under `world/<root>/` (`plan` as written,
    /// `plan_optimized`) on the `plan_step` timeline: its steps, every
    /// robot's predicted estimate and each violation described (the
    /// runner's `step` and `sim_time` are left as they were).
    pub fn plan(&mut self, mission: &Mission, planned: &Planned, root: &str, violations: &[Violation]) -> Result<()> {
        let described: Vec<(Violation, String)> =
            violations.iter().map(|v| (v.clone(), v.describe(&|r| mission.robot_name(r)))).collect();
        let names = mission.robot_labels();
        self.log_plan(&PlanLog {
            root,
            dance: &planned.dance,
            steps: &planned.steps,
            estimates: &planned.estimates,
            violations: &described,
            names: &names,
        })
    }

    fn log_plan(&mut self, plan: &PlanLog) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        rec.reset_time();
        let dance = plan.dance;
        let stations: Vec<[f32; 3]> = dance.stations.iter().map(|s| p32(&s.position)).collect();
        rr(rec.log_static(
            format!("world/{}/route", plan.root),
            &rerun::LineStrips3D::new([stations.clone()])
                .with_colors([rerun::Color::from_rgb(60, 120, 230)])
                .with_radii([0.015_f32]),
        ))?;
        let scanned: Vec<usize> = plan
            .steps
            .iter()
            .filter_map(|s| if let Action::Scan { station } = s.action { Some(station) } else { None })
            .collect();
        let colours: Vec<rerun::Color> = (0..stations.len())
            .map(|k| if scanned.contains(&k) { green() } else { rerun::Color::from_rgb(60, 120, 230) })
            .collect();
        rr(rec.log_static(
            format!("world/{}/stations", plan.root),
            &rerun::Points3D::new(stations).with_colors(colours).with_radii([0.06_f32]),
        ))?;
        let scale = plan.ellipsoid_scale();
        let scale_name = ellipse_scale_name(scale);
        let broken = |step: usize| plan.violations.iter().any(|(v, _)| v.step == step);
        let colour = |step: usize| if broken(step) { red() } else { green() };
        let line = |a: &Point3<f64>, b: &Point3<f64>, step: usize| {
            rerun::LineStrips3D::new([[p32(a), p32(b)]]).with_colors([colour(step)]).with_radii([0.01_f32])
        };
        let robot = |p: &Point3<f64>, parent: bool| {
            let c = if parent { rerun::Color::from_rgb(60, 120, 230) } else { rerun::Color::from_rgb(240, 140, 40) };
            rerun::Points3D::new([p32(p)]).with_colors([c]).with_radii([if parent { 0.25_f32 } else { 0.1 }])
        };
        rec.set_time_sequence("plan_step", 0);
        if let Some(s0) = dance.stations.first() {
            rr(rec.log(format!("world/{}/robots/{}", plan.root, plan.name(Robot::Parent)), &robot(&s0.position, true)))?;
        }
        let mut so_far: Vec<(Point3<f64>, String)> = Vec::new();
        let (mut fix_steps, mut sigma_xy, mut sigma_heading) = (Vec::new(), Vec::new(), Vec::new());
        for step in plan.steps {
            rec.set_time_sequence("plan_step", step.index as i64);
            match &step.action {
                Action::MoveChild { child, from, to } => {
                    rr(rec.log(format!("world/{}/moves", plan.root), &line(from, to, step.index)))?;
                    rr(rec.log(
                        format!("world/{}/robots/{}", plan.root, plan.name(Robot::Child(*child))),
                        &robot(to, false),
                    ))?;
                }
                Action::MoveParent { from, to } => {
                    let (a, b) = (dance.stations[*from].position, dance.stations[*to].position);
                    rr(rec.log(format!("world/{}/moves", plan.root), &line(&a, &b, step.index)))?;
                    rr(rec.log(format!("world/{}/robots/{}", plan.root, plan.name(Robot::Parent)), &robot(&b, true)))?;
                }
                Action::Measure { child, station, .. } => {
                    if let Some(c) = dance.child_at(step.cycle, *child) {
                        let from = dance.stations[*station].position;
                        rr(rec.log(format!("world/{}/sight_lines", plan.root), &line(&from, &c, step.index)))?;
                    }
                }
                Action::Sight { control, station } => {
                    if let Some(c) = dance.control.get(*control) {
                        let from = dance.stations[*station].position;
                        rr(rec.log(
                            format!("world/{}/control_sight_lines", plan.root),
                            &line(&from, &c.position, step.index),
                        ))?;
                    }
                }
                Action::Fix { .. } | Action::Scan { .. } => {}
            }
            for e in plan.estimates.iter().filter(|e| e.step == step.index && !e.scan) {
                let (half, q) = ellipsoid_95(&e.covariance.fixed_view::<3, 3>(0, 0).into_owned());
                let half = half.map(|h| h * scale as f32);
                rr(rec.log(
                    format!("world/{}/uncertainty/{}/predicted_95pct_x{scale_name}", plan.root, plan.name(e.robot)),
                    &rerun::Ellipsoids3D::from_centers_and_half_sizes([p32(&e.position)], [half])
                        .with_quaternions([q])
                        .with_colors([rerun::Color::from_rgb(230, 200, 40)])
                        .with_fill_mode(rerun::FillMode::MajorWireframe),
                ))?;
                if e.robot == Robot::Parent {
                    fix_steps.push(step.index as i64);
                    sigma_xy.push(e.sigma_xy2_m2().sqrt());
                    sigma_heading.push(e.covariance[(3, 3)].max(0.0).sqrt());
                }
            }
            let here: Vec<&(Violation, String)> =
                plan.violations.iter().filter(|(v, _)| v.step == step.index).collect();
            for (v, text) in &here {
                let at = v.position(dance, plan.steps);
                so_far.push((at, format!("step {}: {}, {}", v.step, v.check.name(), plan.name(v.robot))));
                rr(rec.log(
                    format!("{}/log", plan.root),
                    &rerun::TextLog::new(text.clone()).with_level(rerun::TextLogLevel::WARN),
                ))?;
            }
            if !here.is_empty() {
                rr(rec.log(
                    format!("world/{}/violations", plan.root),
                    &rerun::Points3D::new(so_far.iter().map(|(p, _)| p32(p)))
                        .with_colors([red()])
                        .with_radii([0.2_f32])
                        .with_labels(so_far.iter().map(|(_, l)| l.clone())),
                ))?;
            }
        }
        for (series, values) in [("predicted_sigma_xy_m", sigma_xy), ("predicted_sigma_heading_rad", sigma_heading)] {
            rr(rec.send_columns(
                format!("{}/metrics/{series}", plan.root),
                [rerun::TimeColumn::new_sequence("plan_step", fix_steps.clone())],
                rr(rerun::Scalars::new(values).columns_of_unit_batches())?,
            ))?;
        }
        rec.reset_time();
        if self.step > 0 || self.sim_time_s > 0.0 {
            rec.set_time_sequence("step", self.step);
            rec.set_duration_secs("sim_time", self.sim_time_s);
        }
        Ok(())
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

    /// Every robot's estimated and true pose and 95 % ellipsoids (achieved,
    /// and predicted when given: the parent's 4×4 and each child's 3×3).
    pub fn team(
        &mut self,
        team: &TeamState,
        truth: Option<&scanner::sim::Truth>,
        predicted: Option<(&Matrix4<f64>, &[Matrix3<f64>])>,
    ) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        let transform = |p: &Point3<f64>, heading: f64| {
            rerun::Transform3D::from_translation_rotation(
                p32(p),
                rerun::Quaternion::from_xyzw([0.0, 0.0, (heading / 2.0).sin() as f32, (heading / 2.0).cos() as f32]),
            )
        };
        let parent = team.parent();
        // (estimate, heading, true position and heading); a child not yet
        // placed is shown where it truly stands (sim) or not at all.
        let mut poses =
            vec![(Some(parent.position), parent.heading_rad, truth.map(|t| (t.parent.position, t.parent.heading_rad)))];
        for j in 0..team.n_children() {
            let true_p = truth.and_then(|t| t.children.get(j).copied());
            poses.push((team.child(j).or(true_p), 0.0, true_p.map(|p| (p, 0.0))));
        }
        for (k, (name, (est, heading, true_pose))) in self.robots.iter().zip(&poses).enumerate() {
            let Some(est) = est else { continue };
            rr(rec.log(format!("world/robots/{name}"), &transform(est, *heading)))?;
            if let Some((true_p, true_heading)) = true_pose {
                rr(rec.log(format!("world/truth/{name}"), &transform(true_p, *true_heading)))?;
            }
            let achieved = if k == 0 {
                team.parent_covariance().fixed_view::<3, 3>(0, 0).into_owned()
            } else {
                team.child_covariance(k - 1)
            };
            let mut ellipsoids = vec![("achieved_95pct", achieved, rerun::Color::from_rgb(60, 120, 230))];
            if let Some((p, children)) = predicted {
                let c =
                    if k == 0 { Some(p.fixed_view::<3, 3>(0, 0).into_owned()) } else { children.get(k - 1).copied() };
                if let Some(c) = c {
                    ellipsoids.push(("predicted_95pct", c, rerun::Color::from_rgb(230, 200, 40)));
                }
            }
            for (what, cov, colour) in ellipsoids {
                let (half, q) = ellipsoid_95(&cov);
                rr(rec.log(
                    format!("world/uncertainty/{name}/{what}"),
                    &rerun::Ellipsoids3D::from_centers_and_half_sizes([p32(est)], [half])
                        .with_quaternions([q])
                        .with_colors([colour])
                        .with_fill_mode(rerun::FillMode::MajorWireframe),
                ))?;
            }
        }
        Ok(())
    }

    /// Sight lines from the parent to children; `w` per line (fix phase)
    /// colours them, `None` (placement: nothing checks it) is grey.
    pub fn sight_lines(&mut self, phase: &str, from: &Point3<f64>, to: &[(Point3<f64>, Option<f64>)]) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        let strips: Vec<[[f32; 3]; 2]> = to.iter().map(|(p, _)| [p32(from), p32(p)]).collect();
        let colours: Vec<rerun::Color> = to.iter().map(|(_, w)| w_colour(*w)).collect();
        rr(rec.log(
            format!("world/sight_lines/{phase}"),
            &rerun::LineStrips3D::new(strips).with_colors(colours).with_radii([0.01_f32]),
        ))
    }

    /// Adds the parent's estimated and true position to its trajectories.
    pub fn trajectory(&mut self, estimate: &ParentPose, truth: Option<&ParentPose>) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        let parent = self.robots.first().map_or("parent", String::as_str);
        for (what, p, colour) in [
            ("estimate", Some(estimate), rerun::Color::from_rgb(60, 120, 230)),
            ("truth", truth, rerun::Color::from_unmultiplied_rgba(60, 120, 230, 90)),
        ] {
            let Some(p) = p else { continue };
            let line = self.trajectories.entry(what).or_default();
            line.push(p32(&p.position));
            rr(rec.log(
                format!("world/trajectories/{parent}/{what}"),
                &rerun::LineStrips3D::new([line.clone()]).with_colors([colour]).with_radii([0.02_f32]),
            ))?;
        }
        Ok(())
    }

    /// One scan in the world frame, thinned to [`DISPLAY_VOXEL_M`] and
    /// coloured by height (on the worker thread); `kind` is `direct` or `icp`.
    pub fn scan(&mut self, kind: &str, name: &str, world_points: Vec<Point3<f32>>) -> Result<()> {
        let now = self.now();
        self.scan_at(kind, name, world_points, now)
    }

    /// The current (step, sim_time) position on the timelines.
    pub fn now(&self) -> (i64, f64) {
        (self.step, self.sim_time_s)
    }

    /// Like [`Recorder::scan`], at an earlier time `at` from [`Recorder::now`]
    /// (an ICP-refined scan shown where its direct twin was taken).
    pub fn scan_at(&mut self, kind: &str, name: &str, world_points: Vec<Point3<f32>>, at: (i64, f64)) -> Result<()> {
        let Some((send, _)) = &self.scans else { return Ok(()) };
        let job =
            ScanJob { path: format!("world/scans/{kind}/{name}"), points: world_points, step: at.0, sim_time_s: at.1 };
        if send.send(job).is_err() {
            // The worker stopped on an error; `finish` reports it.
            self.scans.take().map(|(_, worker)| worker.join());
            anyhow::bail!("the recording's scan thread stopped");
        }
        Ok(())
    }

    /// Every ICP iteration of the fusion on the `icp_iteration` timeline
    /// (one tick per iteration, runs in the order they ran): each scan's
    /// points once, in its own frame, under a transform that follows the
    /// scan's world pose through the iterations, and how far each
    /// iteration moved it. `names[k]` and `bodies[k]` are scan k's.
    pub fn icp_iterations(
        &mut self,
        traces: &[fusion::multiview::IcpTrace],
        names: &[String],
        bodies: &[&[Point3<f32>]],
    ) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        rec.reset_time();
        let mut tick = 0_i64;
        let mut shown = vec![false; names.len()];
        let (mut ticks, mut shifts) = (Vec::new(), Vec::new());
        for t in traces {
            let (Some(name), Some(body)) = (names.get(t.scan), bodies.get(t.scan)) else { continue };
            let path = format!("world/scans/icp_iterations/{name}");
            let mut previous: Option<nalgebra::Isometry3<f64>> = None;
            for pose in &t.world_from_scan {
                rec.set_time_sequence("icp_iteration", tick);
                if !shown[t.scan] {
                    shown[t.scan] = true;
                    let thin = scanner::reduced_points(body, DISPLAY_VOXEL_M * 2.0).unwrap_or_else(|_| body.to_vec());
                    rr(rec.log(
                        format!("{path}/points"),
                        &rerun::Points3D::new(thin.iter().map(|p| [p.x, p.y, p.z]))
                            .with_colors([rerun::Color::from_rgb(230, 120, 40)])
                            .with_radii([0.015_f32]),
                    ))?;
                }
                let q = pose.rotation.coords;
                rr(rec.log(
                    path.as_str(),
                    &rerun::Transform3D::from_translation_rotation(
                        p32(&Point3::from(pose.translation.vector)),
                        rerun::Quaternion::from_xyzw([q.x as f32, q.y as f32, q.z as f32, q.w as f32]),
                    ),
                ))?;
                if let Some(p) = previous {
                    ticks.push(tick);
                    shifts.push((pose.translation.vector - p.translation.vector).norm());
                }
                previous = Some(*pose);
                tick += 1;
            }
        }
        if !ticks.is_empty() {
            rr(rec.send_columns(
                "metrics/icp_iteration_shift_m",
                [rerun::TimeColumn::new_sequence("icp_iteration", ticks)],
                rr(rerun::Scalars::new(shifts).columns_of_unit_batches())?,
            ))?;
        }
        rec.reset_time();
        rec.set_time_sequence("step", self.step);
        rec.set_duration_secs("sim_time", self.sim_time_s);
        Ok(())
    }

    /// The pipe inspection: the cloud coloured by deviation (at most
    /// [`PIPE_DISPLAY_POINTS`], evenly picked), the fitted axis and a
    /// labelled box around each anomaly.
    pub fn pipe(&mut self, cloud: &[Point3<f32>], inspection: &Inspection, threshold_m: f64) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        let every = cloud.len().div_ceil(PIPE_DISPLAY_POINTS).max(1);
        let shown = cloud.iter().zip(&inspection.deviations).step_by(every);
        let (points, colours): (Vec<[f32; 3]>, Vec<rerun::Color>) =
            shown.map(|(p, d)| ([p.x, p.y, p.z], deviation_colour(f64::from(*d), threshold_m))).unzip();
        rr(rec.log("world/pipe/deviation", &rerun::Points3D::new(points).with_colors(colours).with_radii([0.004_f32])))?;
        let pipe = &inspection.fit.pipe;
        rr(rec.log("world/pipe/axis", &rerun::LineStrips3D::new([[p32(&pipe.a), p32(&pipe.b)]])))?;
        if inspection.anomalies.is_empty() {
            return Ok(());
        }
        let (mins, sizes): (Vec<[f32; 3]>, Vec<[f32; 3]>) = inspection
            .anomalies
            .iter()
            .map(|a| (p32(&a.bounds.0), p32(&Point3::from(a.bounds.1 - a.bounds.0))))
            .unzip();
        let labels: Vec<String> = inspection.anomalies.iter().map(|a| label(pipe, a)).collect();
        rr(rec.log(
            "world/pipe/anomalies",
            &rerun::Boxes3D::from_mins_and_sizes(mins, sizes).with_labels(labels).with_colors([red()]),
        ))
    }

    /// The network adjustment at the end of a run: the control points
    /// (`world/control`, labelled), every reading as a sight line between
    /// the adjusted station and point coloured by its largest |w|
    /// (`world/adjustment/observations`), the ones data snooping removed in
    /// red (`world/adjustment/removed`), the misclosure at each control
    /// point as an arrow from its given position, exaggerated ×k
    /// (`world/adjustment/misclosures_x<k>`), and the tests in the log.
    pub fn adjustment(&mut self, mission: &Mission, report: &AdjustmentReport) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        if !mission.control.is_empty() {
            rr(rec.log(
                "world/control",
                &rerun::Points3D::new(mission.control.iter().map(|c| p32(&c.position_m)))
                    .with_labels(mission.control.iter().map(|c| c.name.clone()))
                    .with_colors([rerun::Color::from_rgb(200, 60, 200)])
                    .with_radii([0.06_f32]),
            ))?;
        }
        let point = |id: &str| report.points.iter().find(|p| p.id == id).map(|p| Point3::new(p.x_m, p.y_m, p.z_m));
        let (mut lines, mut colours, mut removed) = (Vec::new(), Vec::new(), Vec::new());
        for reading in report.observations.chunks(3) {
            let Some(o) = reading.first() else { continue };
            let (Some(station), Some(to)) = (report.stations.get(o.station), point(&o.target)) else { continue };
            let line = [p32(&Point3::new(station.x_m, station.y_m, station.z_m)), p32(&to)];
            if reading.iter().any(|o| o.removed) {
                removed.push(line);
                continue;
            }
            let w = reading.iter().filter_map(|o| o.w).max_by(|a, b| a.abs().total_cmp(&b.abs()));
            lines.push(line);
            colours.push(w_colour(w));
        }
        rr(rec.log(
            "world/adjustment/observations",
            &rerun::LineStrips3D::new(lines).with_colors(colours).with_radii([0.008_f32]),
        ))?;
        if !removed.is_empty() {
            rr(rec.log(
                "world/adjustment/removed",
                &rerun::LineStrips3D::new(removed).with_colors([red()]).with_radii([0.02_f32]),
            ))?;
        }
        if !report.misclosures.is_empty() {
            let largest =
                report.misclosures.iter().map(|m| (m.horizontal_m.powi(2) + m.dz_m.powi(2)).sqrt()).fold(0.0, f64::max);
            let scale = ellipse_scale(largest, 1.0);
            let (origins, vectors): (Vec<[f32; 3]>, Vec<[f32; 3]>) = report
                .misclosures
                .iter()
                .filter_map(|m| {
                    let c = mission.control.iter().find(|c| c.name == m.control)?;
                    let v = [m.dx_m, m.dy_m, m.dz_m].map(|d| (d * scale) as f32);
                    Some((p32(&c.position_m), v))
                })
                .unzip();
            rr(rec.log(
                format!("world/adjustment/misclosures_x{}", ellipse_scale_name(scale)),
                &rerun::Arrows3D::from_vectors(vectors)
                    .with_origins(origins)
                    .with_labels(
                        report.misclosures.iter().map(|m| format!("{} {:.1} mm", m.control, 1e3 * m.horizontal_m)),
                    )
                    .with_colors([rerun::Color::from_rgb(200, 60, 200)]),
            ))?;
        }
        let g = &report.global_test;
        let level = if report.model_accepted { rerun::TextLogLevel::INFO } else { rerun::TextLogLevel::WARN };
        let text = format!(
            "network adjustment: σ0² = {:.3}, redundancy {}, global test {}; {} observation(s) removed by data snooping; model {}",
            report.sigma0_squared,
            report.redundancy,
            if g.passed { "passed" } else { "FAILED" },
            report.removed.len() + report.removed_coordinates.len(),
            if report.model_accepted { "accepted" } else { "NOT accepted" }
        );
        self.event(level, text)?;
        for o in report.observations.iter().filter(|o| o.removed) {
            self.warn(format!(
                "removed by data snooping: {} of {} from station {} (w = {:.2})",
                o.kind,
                o.target,
                o.station,
                o.w.unwrap_or(f64::NAN)
            ))?;
        }
        Ok(())
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

    /// A parent station's figures for the `metrics/` series: σxy, predicted
    /// σxy, σθ and (sim) its error to the truth.
    pub fn station_metrics(&mut self, covariance: &Matrix4<f64>, predicted: &Matrix4<f64>, error_xy_m: Option<f64>) {
        let s = &mut self.series;
        s.station_steps.push(self.step);
        s.sigma_xy_m.push(cps::sigma_xy2(covariance).sqrt());
        s.predicted_sigma_xy_m.push(cps::sigma_xy2(predicted).sqrt());
        s.sigma_heading_rad.push(covariance[(3, 3)].max(0.0).sqrt());
        if let Some(e) = error_xy_m {
            s.error_steps.push(self.step);
            s.error_xy_m.push(e);
        }
    }

    /// A parent fix's variance factor σ0², for `metrics/fix_sigma0_squared`.
    pub fn fix_metrics(&mut self, sigma0_squared: f64) {
        self.series.fix_steps.push(self.step);
        self.series.sigma0_squared.push(sigma0_squared);
    }

    /// A scan's ICP residual at step `at`, for `metrics/icp_rmse_m`.
    pub fn icp_metrics(&mut self, at: i64, rmse_m: f64) {
        self.series.icp_steps.push(at);
        self.series.icp_rmse_m.push(rmse_m);
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// The 95 % ellipsoid's axes are √(χ²₃ · eigenvalue) along the
    /// eigenvectors: a covariance rotated by 30° about z gives back the
    /// rotation and the half sizes.
    #[test]
    fn ellipsoid_axes_follow_the_covariance() {
        let r = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians());
        let d = Matrix3::from_diagonal(&Vector3::new(4e-4, 1e-4, 9e-6));
        let cov = r.matrix() * d * r.matrix().transpose();
        let (half, q) = ellipsoid_95(&cov);
        let q =
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.0[3], q.0[0], q.0[1], q.0[2]).cast::<f64>());
        let mut expected = [0.02, 0.01, 0.003].map(|s| s * CHI2_3D_95_SQRT);
        expected.sort_by(f64::total_cmp);
        let mut got = half.map(f64::from);
        got.sort_by(f64::total_cmp);
        for (g, e) in got.iter().zip(expected) {
            assert!((g - e).abs() < 1e-6, "{got:?} vs {expected:?}");
        }
        // Each axis of the rotated frame, scaled by its half size, lies on the
        // ellipsoid xᵀ Σ⁻¹ x = χ².
        let inv = cov.try_inverse().expect("invertible");
        for (k, h) in half.iter().enumerate() {
            let x = q * (Vector3::ith(k, 1.0) * f64::from(*h));
            let m = (x.transpose() * inv * x)[(0, 0)];
            assert!((m - CHI2_3D_95_SQRT.powi(2)).abs() < 1e-4 * m, "axis {k}: {m}");
        }
        assert_eq!(w_colour(None), rerun::Color::from_rgb(150, 150, 150));
        assert_ne!(w_colour(Some(-4.0)), w_colour(Some(1.0)));
    }
}
