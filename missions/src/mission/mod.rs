//! The mission file: raw TOML → validated, unit-converted [`Mission`].
//!
//! Keys carry their unit in their name; every problem in a file is reported
//! at once, each with file:line:column (see docs/mission.md,
//! the mission reference). This file holds the validated types; [`read`] reads a file
//! into them, one function per table, through the span-keeping
//! [`reader`]; [`diagnostics`] are the problems it finds.

pub mod diagnostics;
pub mod read;
pub mod reader;

use std::ops::Range;
use std::path::PathBuf;
use std::sync::Arc;

use cps::Instrument;
use nalgebra::{Matrix4, Point3, Vector3};

use diagnostics::{Diagnostic, Diagnostics, Source};

/// The dance to plan and predict.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Parent waypoints, world frame, metres.
    pub route_m: Vec<Point3<f64>>,
    /// Distance between parent stations along the route, metres.
    pub stride_m: f64,
    /// Child offsets (forward, left, up) in the parent frame, team order, metres.
    pub formation_m: Vec<Vector3<f64>>,
    /// The generated formation (`formation = { kind = ... }`) the offsets
    /// come from, with its `up_m`; `None` when `formation_m` lists them.
    pub formation: Option<(planner::FormationKind, f64)>,
    /// Covariance of the start pose (x, y, z, θ), m² and rad²; zero when known.
    pub start_covariance: Matrix4<f64>,
    /// How the team advances (`strategy`, `hops`).
    pub strategy: planner::Strategy,
    /// The moving robot must stay in sight (`track`, default false).
    pub track: bool,
    /// Steepest move, radians (`max_slope_deg`; `None`: unchecked).
    pub max_slope_rad: Option<f64>,
    /// Radius of every robot's footprint, metres (`[team] footprint_radius_m`,
    /// default 0.3).
    pub footprint_radius_m: f64,
    /// What `plan --optimize` may change (`[plan.search]`).
    pub search: Search,
    /// Where the parent sights the control points (`control_at`).
    pub control_at: ControlAt,
}

pub use planner::control::ControlAt;

/// A control point (`[[control]]`): a reflector at given coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Control {
    /// `name`, unique.
    pub name: String,
    /// `position_m`, world frame (the mission's coordinate system).
    pub position_m: Point3<f64>,
    /// `sigma_m` squared on the diagonal (x, y, z); zero holds a
    /// coordinate fixed (absent: all fixed).
    pub covariance: nalgebra::Matrix3<f64>,
}

/// The space `cps-survey plan --optimize` searches (`[plan.search]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Search {
    /// Strategies to try (`strategies`, default both).
    pub strategies: Vec<String>,
    /// Largest `hops` tried for parent hops (`max_hops`, default 4).
    pub max_hops: usize,
    /// Strides to try, metres (`strides_m`; default the written stride
    /// × 0.5, 0.75, 1, 1.25, 1.5 and 2).
    pub strides_m: Vec<f64>,
    /// Longest sight line a formation may need, metres
    /// (`max_sight_line_m`; default the total station's `max_range_m`,
    /// at most 200 m).
    pub max_sight_line_m: f64,
}

/// Pass/fail tolerances.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Acceptance {
    /// Largest acceptable final √(σx² + σy²), metres.
    pub max_final_sigma_xy_m: Option<f64>,
    /// Largest acceptable horizontal error of any station against the
    /// simulator's truth, metres (sim backend only).
    pub max_station_error_m: Option<f64>,
    /// Largest acceptable √(σx² + σy²) of any station, metres: the batch
    /// adjustment's (predicted, and of the run).
    pub max_station_sigma_xy_m: Option<f64>,
}

/// Where the devices come from (`[backend]`).
#[derive(Debug, Clone)]
pub struct Backend {
    /// The simulator's scene: a built-in name (`scene`, default `"hall"`),
    /// or the path of `scene_file` as written.
    pub scene: String,
    /// The scene itself (built-in, or parsed from `scene_file`), built once
    /// when the mission is read.
    pub scene_model: Arc<cps::geom::Scene>,
    /// `scene_file`: the file's resolved path and text (checked to parse).
    pub scene_file: Option<(PathBuf, String)>,
    /// Whether the file has a `[backend]` table: the plan is then checked
    /// against its scene (line of sight, tracking, clearance, scan range);
    /// without one it is planned in open space.
    pub given: bool,
    /// Seed of every simulated device (`seed`, default 1).
    pub seed: u64,
    /// Attempts after the first when a device command fails
    /// (`max_retries`, default 2).
    pub max_retries: u32,
    /// Pause before each retry, seconds (`retry_delay_s`, default 0.5).
    pub retry_delay_s: f64,
    /// The simulated drives' odometry error (`odometry_*`, `terrain_tilt_sigma_deg`).
    pub odometry: scanner::sim::OdometryError,
    /// The instruments' ports with `kind = "serial"` (`[backend.serial]`);
    /// `None` runs on the simulator.
    pub serial: Option<SerialPorts>,
}

/// Where the real instruments are (`[backend.serial]`).
#[derive(Debug, Clone, PartialEq)]
pub struct SerialPorts {
    /// The total station's port (`total_station`; required with children).
    pub total_station: Option<String>,
    /// Its baud rate (`total_station_baud`, default 9600).
    pub total_station_baud: u32,
    /// Deadline of one GeoCOM reply, seconds (`total_station_timeout_s`,
    /// default 5; a distance measurement takes 1–3 s).
    pub total_station_timeout_s: f64,
    /// The tilt sensor's port (`tilt`).
    pub tilt: String,
    /// Its baud rate (`tilt_baud`, default 9600).
    pub tilt_baud: u32,
    /// Its sentence rate (`tilt_rate_hz`, default 10).
    pub tilt_rate_hz: f64,
    /// The LMS-2xx's port (`scanner`).
    pub scanner: String,
    /// The session baud rate the scanner is switched to (`scanner_baud`:
    /// 9600, 19200, 38400 or 500000; default 38400).
    pub scanner_baud: u32,
    /// Continuous output instead of one request per slice
    /// (`scanner_continuous`, default false).
    pub scanner_continuous: bool,
    /// The scan head's port (`head`).
    pub head: String,
    /// The drives' ports: the parent's first, then the children's in
    /// `[team] children` order (`drives`).
    pub drives: Vec<String>,
    /// The drives' and the head's baud rate (`robot_baud`, default 115200).
    pub robot_baud: u32,
    /// Deadline of one drive move, seconds (`move_timeout_s`, default 120).
    pub move_timeout_s: f64,
}

/// What the scanner does (`[scan]`).
#[derive(Debug, Clone, PartialEq)]
pub struct ScanPlan {
    /// Scan at every n-th parent station, 0 = never (`every_n_stations`,
    /// default 1; station 0 is the start).
    pub every_n_stations: usize,
    /// Scan exactly at these stations instead (`stations`, ascending,
    /// distinct; exclusive with `every_n_stations`).
    pub stations: Option<Vec<usize>>,
    /// Table steps per 360° (`slices`, default 180).
    pub slices: usize,
    /// LMS angular resolution (`resolution_deg`: 1, 0.5 or 0.25; default 1).
    pub resolution: scanner::sim::LmsResolution,
    /// Scan head centre in the body frame (`body_from_head_m`, default
    /// [0, 0, 0.4]), metres.
    pub body_from_head_m: Vector3<f64>,
    /// The head (`head`: `"rotating-table"`, default, or `"pitching"`).
    pub head: scanner::HeadKind,
}

impl Default for ScanPlan {
    fn default() -> Self {
        Self {
            every_n_stations: 1,
            stations: None,
            slices: 180,
            resolution: scanner::sim::LmsResolution::One,
            body_from_head_m: Vector3::new(0.0, 0.0, 0.4),
            head: scanner::HeadKind::RotatingTable,
        }
    }
}

impl ScanPlan {
    /// The scan head's mount on the body: `body_from_head_m`, no rotation.
    pub fn body_from_head(&self) -> nalgebra::Isometry3<f64> {
        nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::from(self.body_from_head_m),
            nalgebra::UnitQuaternion::identity(),
        )
    }

    /// Where the scanner stands in the body frame (the head's mount; the
    /// 2D scanner turns about it).
    pub fn scanner_in_body(&self) -> nalgebra::Point3<f64> {
        nalgebra::Point3::from(self.body_from_head_m)
    }

    /// Whether the scanner scans at station `k`.
    pub fn scans_at(&self, k: usize) -> bool {
        match &self.stations {
            Some(list) => list.binary_search(&k).is_ok(),
            None => self.every_n_stations != 0 && k.is_multiple_of(self.every_n_stations),
        }
    }
}

/// How the scans become one cloud (`[fusion] mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FusionMode {
    /// Each scan with its CPS pose and tilt (seed 003's direct transformation).
    Direct,
    /// Scan matching alone: simultaneous matching (seed 000 §4.2) from the
    /// odometry's pose guesses, the first scan fixed at its CPS pose.
    Icp,
    /// The CPS pose of each scan as a prior, ICP between overlapping scans,
    /// adjusted together in a pose graph.
    CpsIcp,
}

impl FusionMode {
    /// The mode's name in mission files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            FusionMode::Direct => "direct",
            FusionMode::Icp => "icp",
            FusionMode::CpsIcp => "cps-icp",
        }
    }

    /// The mode called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        [FusionMode::Direct, FusionMode::Icp, FusionMode::CpsIcp].into_iter().find(|m| m.name() == name)
    }
}

/// Mode names `[fusion] mode` accepts.
pub const FUSION_MODES: [&str; 3] = ["direct", "icp", "cps-icp"];

/// `[fusion] line_ratio` when `degeneracy_ratio` is set and it is not
/// ([`fusion::links::DEFAULT_LINE_RATIO`]): the rig's scanner takes its
/// scans in slices, and where they lie far apart (fewer `slices`) a
/// pipe's axis looked seen through their lines' normals (docs/fusion.md,
/// the sewer at 60 slices).
pub const DEFAULT_LINE_RATIO: f64 = fusion::links::DEFAULT_LINE_RATIO;

/// `[fusion] corner_ratio` when not given: off, unlike `match
/// --corner-ratio` (0.1). At the fusion's fixed cells (0.1–0.2 m; its fine
/// pass's 0.1 m reach) nearly every neighbourhood is judged sparse, and
/// the corners left out are what holds a corridor's scans along it: the
/// simulated corridor's `icp` fusion 14.8 mm RMS with 0.1 against 4.1 mm
/// without, the hall's 1.71 against 1.72 (docs/fusion.md, "The corner
/// test in a mission's fusion").
pub const DEFAULT_CORNER_RATIO: f64 = 0.0;

/// Fusion settings (`[fusion]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FusionPlan {
    /// The mode (`mode`, default `"direct"`).
    pub mode: FusionMode,
    /// Reduced-points cell of the scans matched (`voxel_m`, default 0.2); the
    /// model side uses half of it.
    pub voxel_m: f64,
    /// ICP correspondence distance of the first, coarse pass
    /// (`max_correspondence_m`, default 0.5).
    pub max_correspondence_m: f64,
    /// … and of the second, fine pass from the first's result
    /// (`fine_correspondence_m`, default 0.1; ≤ `max_correspondence_m`).
    pub fine_correspondence_m: f64,
    /// ICP iteration cap per match (`max_iterations`, default 50).
    pub max_iterations: usize,
    /// Huber kernel width (`huber_m`, default 0.02; 0 = plain least squares).
    pub huber_m: f64,
    /// Two scans overlap with more correspondences than this (`min_pairs`,
    /// default 250, as in seed 000).
    pub min_pairs: usize,
    /// `cps-icp`: each scan is matched against at most this many earlier
    /// scans (`max_partners`, default 4).
    pub max_partners: usize,
    /// `cps-icp`: ICP covariances are multiplied by this before the
    /// adjustment (`icp_variance_factor`, default 1; raise it when the
    /// scans' errors are correlated, e.g. by a miscalibrated scanner).
    pub icp_variance_factor: f64,
    /// `icp`: a match leaves a direction where odometry put the scan when
    /// its eigenvalue of the normal matrix is below this ratio of the
    /// largest — a pipe's axis and the roll about it — and reports it in
    /// the links (`degeneracy_ratio`, default 0: off; the sewer uses 1e-2,
    /// see docs/fusion.md). `cps-icp` does not need it: the CPS prior holds
    /// the scans and its gate leaves out a match that slid.
    pub degeneracy_ratio: f64,
    /// `icp` with `degeneracy_ratio`: judge the blind directions without
    /// the points whose normal is not a surface's — their ten nearest
    /// neighbours along one scan line (the middle PCA eigenvalue below
    /// this ratio of the largest) or with no clear smallest direction,
    /// unless their 40 nearest are a line too or a surface with the same
    /// normal (`line_ratio`, `match --line-ratio`'s key; default
    /// [`DEFAULT_LINE_RATIO`] with `degeneracy_ratio`, else 0: off; see
    /// docs/fusion.md).
    pub line_ratio: f64,
    /// `icp` and `cps-icp`: leave out each point-to-plane pair whose
    /// target normal came from a neighbourhood that is not one plane (its
    /// smallest PCA eigenvalue above this share of its middle one: a floor
    /// meeting a wall), judged where the scan is sparse — such normals
    /// lean towards the scanner that saw them and bend a chain of matches
    /// (`corner_ratio`, `match --corner-ratio`'s key; default
    /// [`DEFAULT_CORNER_RATIO`], off; docs/fusion.md).
    pub corner_ratio: f64,
    /// `icp`: the simultaneous pass runs at most this many matches in each
    /// new scan's queue at each stage before it abandons the queue and
    /// reports the stage not settled (`max_matches_per_scan`, default 100;
    /// `match --max-matches-per-scan`, docs/match.md).
    pub max_matches_per_scan: usize,
}

impl Default for FusionPlan {
    fn default() -> Self {
        Self {
            mode: FusionMode::Direct,
            voxel_m: 0.2,
            max_correspondence_m: 0.5,
            fine_correspondence_m: 0.1,
            max_iterations: 50,
            huber_m: 0.02,
            min_pairs: 250,
            max_partners: 4,
            icp_variance_factor: 1.0,
            degeneracy_ratio: 0.0,
            line_ratio: 0.0,
            corner_ratio: DEFAULT_CORNER_RATIO,
            max_matches_per_scan: fusion::multiview::MultiviewConfig::default().max_matches_per_scan,
        }
    }
}

/// Output formats of the merged cloud (`[output] formats`).
#[derive(Debug, Clone, PartialEq)]
pub struct Output {
    /// File extensions, e.g. `["ply", "las"]` (default `["ply"]`).
    pub formats: Vec<String>,
    /// Write `mission.rrd` for the Rerun viewer (`rerun`, default true).
    pub rerun: bool,
    /// Write `rosbag2/`, the run as a rosbag2 of standard ROS 2 messages
    /// (`ros2_bag`, default false; [`crate::ros2::export`]).
    pub ros2_bag: bool,
}

/// Pipe inspection of the fused cloud (`[pipe]`, seed 000 §5): a tube is
/// fitted from the nominal one and every point's deviation from it mapped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipePlan {
    /// The nominal tube the fit starts from (`axis_from_m`, `axis_to_m`,
    /// `radius_m`), world frame.
    pub nominal: fusion::pipe::Pipe,
    /// A point deviating more than this is anomalous (`threshold_m`,
    /// default 0.02).
    pub threshold_m: f64,
    /// Anomalous points closer than this belong to one anomaly (`link_m`,
    /// default 0.05).
    pub link_m: f64,
    /// Smaller groups are dropped as noise (`min_points`, default 20).
    pub min_points: usize,
}

/// Cloud formats `[output] formats` accepts.
pub const OUTPUT_FORMATS: [&str; 7] = ["ply", "las", "laz", "copc", "e57", "pcd", "xyz"];

/// Where in the file each value came from, to point errors found later
/// (e.g. by the planner) at the right line.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Spans {
    /// `[plan]` table.
    pub plan: Range<usize>,
    /// Each `route_m` waypoint.
    pub route_m: Vec<Range<usize>>,
    /// `stride_m`.
    pub stride_m: Range<usize>,
    /// Each `formation_m` offset (each the `formation` table when generated).
    pub formation_m: Vec<Range<usize>>,
    /// The value of `formation_m` or `formation`.
    pub formation_value: Range<usize>,
    /// The values of `strategy` and `hops`, where given.
    pub strategy: Option<Range<usize>>,
    /// The value of `hops`, where given.
    pub hops: Option<Range<usize>>,
    /// The value of `[backend] scene_file`, where given.
    pub scene_file: Option<Range<usize>>,
    /// `[scan] stations`, when given.
    pub scan_stations: Option<Range<usize>>,
    /// Each `[[control]]` table's `position_m`.
    pub control: Vec<Range<usize>>,
    /// `[plan] control_at`, when given.
    pub control_at: Option<Range<usize>>,
}

/// A validated mission.
#[derive(Debug, Clone)]
pub struct Mission {
    /// The file it came from.
    pub source: Source,
    /// `mission.name`.
    pub name: String,
    /// Child names, team order.
    pub children: Vec<String>,
    /// The parent's total station; `None` for a robot alone (no children),
    /// which positions itself by odometry.
    pub total_station: Option<Instrument>,
    /// The dance.
    pub plan: Plan,
    /// Tolerances.
    pub acceptance: Acceptance,
    /// Where the devices come from (`[backend]`): the simulator's scene,
    /// seed, odometry and retry settings, or the serial ports of real
    /// instruments.
    pub backend: Backend,
    /// The scanner's settings.
    pub scan: ScanPlan,
    /// How the scans are fused.
    pub fusion: FusionPlan,
    /// The outputs.
    pub output: Output,
    /// The coordinate reference system of the route, the control and the
    /// outputs (`[site] crs` or `local_frame`).
    pub crs: scanner::io::Crs,
    /// The pipe inspection, when `[pipe]` is given.
    pub pipe: Option<PipePlan>,
    /// The control points (`[[control]]`).
    pub control: Vec<Control>,
    /// Spans for later diagnostics.
    pub spans: Spans,
}

/// Failure to load a mission.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MissionError {
    /// The file could not be read.
    #[error("cannot read mission file {file}")]
    Io {
        /// The path.
        file: String,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// The file has problems.
    #[error("mission file {file}: {problems}")]
    Invalid {
        /// The path.
        file: String,
        /// Every problem found.
        problems: Diagnostics,
    },
}

impl MissionError {
    /// The problems of `mission`'s file found after parsing (e.g. by the planner).
    pub fn invalid(mission: &Mission, problems: Diagnostics) -> Self {
        MissionError::Invalid { file: mission.source.file.display().to_string(), problems }
    }
}

impl Mission {
    /// What the merged cloud's points are relative to: the route's first
    /// point rounded as [`crate::output::cloud_origin`] rounds it.
    pub fn cloud_origin(&self) -> nalgebra::Vector3<f64> {
        crate::output::cloud_origin(&self.plan.route_m.first().map_or_else(nalgebra::Vector3::zeros, |p| p.coords))
    }

    /// The scene of `[backend]`: the simulator's world, on serial ports the
    /// site model the plan is checked against.
    pub fn scene(&self) -> &Arc<cps::geom::Scene> {
        &self.backend.scene_model
    }

    /// "the parent" or `child "name"`, for sentences.
    pub fn robot_name(&self, r: planner::Robot) -> String {
        match r {
            planner::Robot::Parent => "the parent".to_string(),
            planner::Robot::Child(j) => self.children.get(j).map_or(format!("child {j}"), |n| format!("child \"{n}\"")),
        }
    }

    /// "parent" or the child's name, as in the recording's entity paths and
    /// the JSON reports.
    pub fn robot_label(&self, r: planner::Robot) -> String {
        match r {
            planner::Robot::Parent => "parent".to_string(),
            planner::Robot::Child(j) => self.children.get(j).cloned().unwrap_or_else(|| format!("child{j}")),
        }
    }

    /// "parent" and the children's names, in team order.
    pub fn robot_labels(&self) -> Vec<String> {
        std::iter::once("parent".to_string()).chain(self.children.iter().cloned()).collect()
    }

    /// A diagnostic at `span` of this mission's file.
    pub fn diagnostic(&self, span: &Range<usize>, field: &str, message: impl Into<String>) -> Diagnostic {
        self.source.diagnostic(span, field, message)
    }
}
