//! `cps-survey match INPUT…`: registers a user's own scans into one frame
//! ([`fusion::scanset`]) and writes their poses (`poses.json`, 3DTK
//! `.frames`), the merged cloud, the link table and `match.rrd`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use fusion::icp::{Kernel, Method};
use fusion::scanset::{Mode, SetConfig, SetResult};
use nalgebra::{Isometry3, Matrix6, Vector3};
use serde::Serialize;

use super::Outcome;
use super::register::MethodArg;
use crate::run::report::directions;
use crate::scans::inputs::InputScan;
use crate::view::recording::{Recorder, Viewer};

/// How the set is registered (`--mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// Each scan against the earlier scan with the most overlap.
    Pairwise,
    /// Each scan against the union of the earlier ones.
    Incremental,
    /// The seed's simultaneous matching.
    Simultaneous,
    /// Every overlapping pair matched and adjusted as a pose graph.
    Graph,
}

/// Where the scans start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InitArg {
    /// Global registration on local features, no guess needed.
    Global,
}

/// The cell of global registration's descriptors, as a fraction of the
/// scans' radius.
const GLOBAL_CELL_OF_RADIUS: f64 = 1.0 / 40.0;

/// `match`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct MatchArgs {
    /// Scans: a 3DTK directory (scanNNN.3d + scanNNN.pose), a multi-scan
    /// E57 (its poses the start), a rosbag2 (a directory with
    /// metadata.yaml, or an .mcap: PointCloud2 with poses from /tf or
    /// --odom), or scan files of any supported format.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// How the set is registered.
    #[arg(long, value_enum, default_value = "graph")]
    pub mode: ModeArg,
    /// JSON [{"file": "…", "world_from_scan": [[4×4 row-major]]}] for scans
    /// that carry no pose (default identity; the first scan defines the
    /// frame).
    #[arg(long, value_name = "FILE")]
    pub init_poses: Option<PathBuf>,
    /// `global`: find each scan's start from the scans' shape alone (FPFH
    /// descriptors and RANSAC against the earlier scans), for scans that
    /// come with no guess — they may be turned any amount; the poses the
    /// inputs carry (3DTK, E57) are then not used.
    #[arg(long, value_enum)]
    pub init: Option<InitArg>,
    /// Coarse-to-fine stages "VOXEL/MAXDIST,…" in metres, or "auto": the
    /// building recipe 0.5/2,0.25/1,0.1/0.5,0.05/0.2 scaled so that its
    /// first voxel is an eleventh of the scans' radius (measured on them).
    /// A stage that leaves a scan fewer than 50 voxel cells is refused.
    #[arg(long, default_value = "auto")]
    pub schedule: String,
    /// Error metric.
    #[arg(long, value_enum, default_value = "point-to-plane")]
    pub method: MethodArg,
    /// Huber kernel width, metres (0: plain least squares). Default: 0.4 ×
    /// the last stage's voxel (2 cm at the recipe's 5 cm).
    #[arg(long)]
    pub huber: Option<f64>,
    /// graph: each scan is linked to at most this many earlier scans, those
    /// it overlaps most.
    #[arg(long, default_value_t = 10)]
    pub max_partners: usize,
    /// Directions a match cannot see — eigenvalue of its normal matrix
    /// (about the scan's centroid, rotation scaled by its radius) below
    /// this ratio of the largest — are held where the start put them and
    /// reported (0: off).
    #[arg(long, default_value_t = fusion::links::DEFAULT_DEGENERACY_RATIO)]
    pub degeneracy_ratio: f64,
    /// Drop points nearer than this to their scan's origin, metres.
    #[arg(long, default_value_t = 0.0)]
    pub min_range: f64,
    /// Drop points farther than this from their scan's origin, metres.
    #[arg(long, default_value_t = f64::INFINITY)]
    pub max_range: f64,
    /// Where the outputs go (created if missing).
    #[arg(long, default_value = "match")]
    pub out: PathBuf,
    /// Cloud formats, comma separated: ply, las, laz, copc, e57, pcd, xyz.
    #[arg(long, default_value = "ply", value_delimiter = ',')]
    pub formats: Vec<String>,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    pub json: bool,
    /// A rosbag2 input: the sensor_msgs/msg/PointCloud2 topic to read
    /// (default: the bag's only one).
    #[arg(long, value_name = "TOPIC")]
    pub topic: Option<String>,
    /// A rosbag2 input: one cloud every S seconds (default: every cloud).
    #[arg(long, value_name = "S")]
    pub every: Option<f64>,
    /// A rosbag2 input: one cloud every M metres of travel.
    #[arg(long, value_name = "M")]
    pub every_distance: Option<f64>,
    /// A rosbag2 input: the fixed frame of the start poses (default map,
    /// else odom).
    #[arg(long, value_name = "FRAME")]
    pub frame: Option<String>,
    /// A rosbag2 input: start poses from this nav_msgs/msg/Odometry topic
    /// instead of /tf.
    #[arg(long, value_name = "TOPIC")]
    pub odom: Option<String>,
    /// Also write the registered scans and poses as a rosbag2 directory
    /// (MCAP of standard ROS 2 messages) into DIR, which must not exist.
    #[arg(long = "ros2-bag", value_name = "DIR")]
    pub ros2_bag: Option<PathBuf>,
    /// The coordinate reference system of the start poses and so of every
    /// output: EPSG:NNNN, EPSG:H+V or WKT (in metres). Default: the one
    /// the E57 inputs name in their coordinateMetadata, else a local frame.
    #[arg(long, value_name = "CRS")]
    pub crs: Option<String>,
}

/// The rosbag2 options, checked: only with a bag among the inputs;
/// `--every` and `--every-distance` positive and not both.
fn bag_options(args: &MatchArgs) -> Result<crate::ros2::read::BagOptions> {
    let given = [
        ("--topic", args.topic.is_some()),
        ("--every", args.every.is_some()),
        ("--every-distance", args.every_distance.is_some()),
        ("--frame", args.frame.is_some()),
        ("--odom", args.odom.is_some()),
    ];
    if let Some((flag, _)) = given.iter().find(|(_, g)| *g)
        && !args.inputs.iter().any(|i| crate::ros2::read::is_bag(i))
    {
        bail!("{flag}: for a rosbag2 input (a directory with metadata.yaml, or an .mcap file); none is given");
    }
    if args.every.is_some() && args.every_distance.is_some() {
        bail!("--every and --every-distance: choose one");
    }
    for (flag, v) in [("--every", args.every), ("--every-distance", args.every_distance)] {
        if let Some(v) = v
            && !(v.is_finite() && v > 0.0)
        {
            bail!("{flag} {v}: expected a positive number");
        }
    }
    Ok(crate::ros2::read::BagOptions {
        topic: args.topic.clone(),
        every_s: args.every,
        every_distance_m: args.every_distance,
        frame: args.frame.clone(),
        odom: args.odom.clone(),
    })
}

/// The CRS of `match`'s outputs: `--crs`, else the one E57 inputs name,
/// else a local engineering frame. The error names the option or file.
fn output_crs(args: &MatchArgs) -> Result<scanner::io::Crs> {
    if let Some(text) = &args.crs {
        return scanner::io::Crs::parse(text).map_err(|e| anyhow::anyhow!("--crs: {e}"));
    }
    let mut named: Option<(PathBuf, String)> = None;
    for input in &args.inputs {
        if input.is_dir() || scanner::io::Format::from_path(input).ok() != Some(scanner::io::Format::E57) {
            continue;
        }
        let Some(text) = scanner::io::read_e57_crs(input)? else { continue };
        match &named {
            Some((first, known)) if *known != text => bail!(
                "{} and {} name different coordinate reference systems: give the outputs' with --crs",
                first.display(),
                input.display()
            ),
            Some(_) => {}
            None => named = Some((input.clone(), text)),
        }
    }
    match named {
        Some((file, text)) => scanner::io::Crs::parse(&text).map_err(|e| {
            anyhow::anyhow!("{}: coordinateMetadata: {e} (give the outputs' CRS with --crs)", file.display())
        }),
        None => Ok(scanner::io::Crs::local("cps-survey match local frame")),
    }
}

/// `match --json` and `poses.json`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub(crate) struct MatchReport {
    /// The mode.
    mode: String,
    /// The coordinate reference system of the poses and clouds.
    crs: crate::run::report::CrsReport,
    /// Every scan in input order.
    scans: Vec<ScanReport>,
    /// The final stage's matches, used or not.
    links: Vec<LinkReport>,
    /// ICP runs in all.
    matches: usize,
    /// The link graph's variance factor σ̂₀² (graph mode).
    variance_factor: Option<f64>,
    /// Registration time, seconds (reading the scans and writing excluded).
    seconds: f64,
    /// The length scales measured on the scans and the schedule used.
    settings: SettingsReport,
    /// Each stage of the schedule as it ran.
    stages: Vec<StageReport>,
    /// The registration from the starts again without the schedule's
    /// first stage, run when the schedule moved a scan further from its
    /// start than the second stage's correspondence distance (a coarse
    /// stage can drag good starts away on narrow overlaps); null when it
    /// did not run.
    restart: Option<RestartReport>,
    /// The verification: every pair of scans that overlaps at the final
    /// poses, matched once more from them at the finest stage.
    checks: Vec<CheckReport>,
    /// The verification's wall-clock time, seconds (within `seconds`).
    check_seconds: f64,
    /// With `--init global`: scans blind in some direction (indices into
    /// `scans`) — their start, found from the shape, says nothing along it,
    /// so the exit is 1.
    blind_without_start: Vec<usize>,
    /// Scans an inconsistent pair names (indices into `scans`; never the
    /// first, which holds the frame, when its partner is named): their
    /// poses are not where the data agree, and the exit is 1.
    untrusted: Vec<usize>,
}

/// One pair of the verification.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
struct CheckReport {
    /// The scan matched (index into `scans`).
    source: usize,
    /// The scan it was matched against.
    target: usize,
    /// Correspondences at the final poses.
    overlap: usize,
    /// How far the match moved the source's points from the final poses,
    /// metres (its centroid's displacement plus the turn times their RMS
    /// radius); null when the match failed.
    moved_m: Option<f64>,
    /// The match's turn from the final poses, degrees.
    angle_deg: Option<f64>,
    /// The motion against the match's own information (δᵀ·I·δ; the matches'
    /// information is optimistic on real scans: informative only).
    chi2: Option<f64>,
    /// `moved_m` as a fraction of the source points' RMS radius.
    relative_motion: Option<f64>,
    /// The motion along the directions the match sees well (eigenvalue at
    /// least 5 % of the largest, about the source's centroid, rotation
    /// scaled by the radius), metres: what judges the pair (a corridor
    /// pair matched alone slides along the axis the set's other links hold).
    seen_motion_m: Option<f64>,
    /// The match's point-to-plane RMS residual, metres; null when it failed.
    rmse_m: Option<f64>,
    /// What a right registration of the two scans leaves: the RMS of their
    /// noise floors (each scan's two random halves matched at the
    /// identity), metres.
    noise_m: f64,
    /// The match moved the points by at most the finest stage's voxel, or
    /// along what it sees well by at most 5 % of their RMS radius and
    /// turned them by at most 5°.
    consistent: bool,
}

/// One stage of the schedule as it ran.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
struct StageReport {
    /// Its voxel, metres.
    voxel_m: f64,
    /// Its correspondence distance, metres.
    max_correspondence_m: f64,
    /// ICP runs in it (graph mode's last stage: the links matched).
    matches: usize,
    /// Its wall-clock time, seconds.
    seconds: f64,
    /// False when a simultaneous queue was abandoned at its cap.
    settled: bool,
}

/// The second registration from the starts, without the schedule's first
/// stage.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
struct RestartReport {
    /// The scan the schedule moved furthest from its start, or that a
    /// stage of it moved away from its partner (index into `scans`).
    scan: usize,
    /// How far, metres (its centroid's displacement plus the turn times
    /// its points' RMS radius); null when the schedule failed.
    moved_m: Option<f64>,
    /// Why the schedule failed: a stage moved two scans apart that
    /// overlapped at their starts (the restart is then the result when it
    /// succeeds; when it fails too, the schedule's error is the command's).
    schedule_error: Option<String>,
    /// The restart's stages as they ran.
    stages: Vec<StageReport>,
    /// How badly the scans agree at the schedule's poses: the mean over
    /// every reduced point of the squared point-to-plane distance to the
    /// other scans, truncated at the finest correspondence distance (a
    /// point with no partner pays its square), m²; null when the schedule
    /// failed.
    schedule_disagreement_m2: Option<f64>,
    /// The same at the restart's poses; null when the restart failed.
    restart_disagreement_m2: Option<f64>,
    /// Why the restart failed.
    error: Option<String>,
    /// True when the restart's poses are the result: the schedule's
    /// disagreement is more than 1.5 times the restart's.
    kept: bool,
}

/// What the scans measured and the settings they were matched with.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
struct SettingsReport {
    /// The median distance from a point to its nearest neighbour over the
    /// scans' surfaces (one point per cell of a fiftieth of the radius),
    /// metres: the median over the scans.
    spacing_m: f64,
    /// The 90th percentile of a scan's points' distances from their
    /// centroid, metres: the median over the scans.
    radius_m: f64,
    /// Whether the schedule was derived from the scans (`--schedule auto`).
    auto_schedule: bool,
    /// The stages, [voxel, correspondence distance] in metres.
    schedule: Vec<[f64; 2]>,
    /// The Huber width, metres (0: least squares).
    huber_m: f64,
    /// σ of the start's step between scans, metres (0.2 × the first
    /// voxel).
    step_sigma_m: f64,
    /// ICP's convergence tolerance in translation, metres (0.002 × the
    /// last voxel).
    translation_tolerance_m: f64,
    /// `simultaneous`: a match that moves its scan by more than this
    /// (metres, 0.2 × the last voxel) or 0.05° re-queues its neighbours.
    moved_translation_m: f64,
    /// With `--init global`: how the starts were found.
    #[serde(skip_serializing_if = "Option::is_none")]
    global: Option<GlobalReport>,
}

/// `--init global`'s starts.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
struct GlobalReport {
    /// The descriptors' cell, metres (a fortieth of the radius).
    voxel_m: f64,
    /// Its wall-clock time, seconds (outside `seconds`).
    seconds: f64,
    /// Each later scan's match: against which earlier scan, with how many
    /// feature correspondences and inliers.
    matches: Vec<GlobalMatchReport>,
}

/// One scan's global match.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
struct GlobalMatchReport {
    /// The scan placed (index into `scans`).
    source: usize,
    /// The earlier scan it was placed against.
    target: usize,
    /// Mutual nearest neighbours in feature space.
    correspondences: usize,
    /// Of them, within 1.5 cells after the transform.
    inliers: usize,
}

/// One scan in a [`MatchReport`].
#[derive(Debug, Serialize, schemars::JsonSchema)]
struct ScanReport {
    /// The scan as given (`FILE.e57#NAME` for an E57's scans).
    file: String,
    /// Its name (the file's stem, or the E57 `data3D`'s name): its frames
    /// file, E57 `data3D` and recording entity.
    name: String,
    /// Its number: the input's own (3DTK `scanNNN`, the trailing digits of
    /// the name) when they tell the scans apart, else its input order; each
    /// of its points carries it (LAS `point_source_id`).
    number: u16,
    /// Its registered pose, 4×4 row-major, metres.
    world_from_scan: [[f64; 4]; 4],
    /// 6×6, order (ωx, ωy, ωz, x, y, z), radians and metres, left
    /// perturbation (as `register`'s) in the world's axes about the first
    /// scan's origin; zero for the first scan, which holds the frame.
    covariance: [[f64; 6]; 6],
    /// Directions the matches cannot see (unit vectors in the order and
    /// frame of the covariance): held where the start put them, their σ
    /// the start's.
    degenerate_directions: Vec<[f64; 6]>,
}

/// One match in a [`MatchReport`].
#[derive(Debug, Serialize, schemars::JsonSchema)]
struct LinkReport {
    /// The matched scan (index into `scans`).
    source: usize,
    /// The scans it was matched against.
    targets: Vec<usize>,
    /// Correspondences at the start of the match (graph mode).
    overlap: Option<usize>,
    /// Correspondences at the end, when ICP ran.
    correspondences: Option<usize>,
    /// RMS residual, metres, when ICP ran.
    rmse_m: Option<f64>,
    /// Whether ICP converged.
    converged: bool,
    /// ICP iterations of the match (0 when it did not run).
    iterations: usize,
    /// Whether the match is used.
    accepted: bool,
    /// Why not, when rejected.
    #[serde(skip_serializing_if = "Option::is_none")]
    reason: Option<String>,
    /// Directions this match cannot see (order of the covariance, the
    /// first target's frame).
    degenerate_directions: Vec<[f64; 6]>,
    /// For a link rejected as disagreeing with the others (graph mode):
    /// the shortest cycle of used links it contradicts.
    #[serde(skip_serializing_if = "Option::is_none")]
    cycle: Option<CycleReport>,
}

/// A cycle of used links a rejected link contradicts.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
struct CycleReport {
    /// The scans from the link's target round to its source along used
    /// links (indices into `scans`); the link closes the cycle.
    scans: Vec<usize>,
    /// How far the path and the link disagree: the turn, degrees.
    angle_deg: f64,
    /// … and the translation, metres.
    translation_m: f64,
}

impl crate::view::document::Document for MatchReport {
    const NAME: &'static str = "match";
    const VERSION: u32 = 1;
}

/// Runs `match`.
pub fn run(args: &MatchArgs, out: &mut dyn Write) -> Result<Outcome> {
    crate::scans::settings::check_range(args.min_range, args.max_range)?;
    let given =
        (args.schedule.trim() != "auto").then(|| crate::scans::settings::schedule(&args.schedule)).transpose()?;
    if let Some(h) = args.huber
        && !(h.is_finite() && h >= 0.0)
    {
        bail!("--huber {h}: expected a width ≥ 0 in metres (0: least squares)");
    }
    for (k, f) in args.formats.iter().enumerate() {
        if !crate::mission::OUTPUT_FORMATS.contains(&f.as_str()) {
            bail!("--formats {f}: expected some of {}", crate::mission::OUTPUT_FORMATS.join(", "));
        }
        if args.formats[..k].contains(f) {
            bail!("--formats {}: {f} is listed twice: expected each format once", args.formats.join(","));
        }
    }
    let bag = bag_options(args)?;
    if let Some(dir) = &args.ros2_bag
        && std::fs::symlink_metadata(dir).is_ok()
    {
        bail!("--ros2-bag {}: already exists; a bag is written into a new directory", dir.display());
    }
    if args.init.is_some() && args.init_poses.is_some() {
        bail!("--init global and --init-poses: give the starts, or have them found, not both");
    }
    if args.out.exists() && !args.out.is_dir() {
        bail!("--out {}: exists and is not a directory", args.out.display());
    }
    check_out(args)?;
    crate::view::recording::available()?;
    if !(args.degeneracy_ratio.is_finite() && (0.0..0.1).contains(&args.degeneracy_ratio)) {
        bail!("--degeneracy-ratio {}: expected a ratio in [0, 0.1) (0: off)", args.degeneracy_ratio);
    }
    if args.max_partners == 0 {
        bail!("--max-partners 0: expected at least 1");
    }
    let mut config = SetConfig { mode: mode(args.mode), ..SetConfig::default() };
    config.link.max_partners = args.max_partners;
    let icp = &mut config.link.multiview.icp;
    icp.degeneracy_ratio = (args.degeneracy_ratio > 0.0).then_some(args.degeneracy_ratio);
    if args.method == MethodArg::PointToPoint {
        icp.method = Method::PointToPoint;
        // Back faces need the target's normals, which point-to-point does not estimate.
        icp.reject_back_faces = false;
    }
    let min_points = config.link.multiview.min_pairs;
    let crs = output_crs(args)?;
    let scans = crate::scans::inputs::read(
        &args.inputs,
        args.init_poses.as_deref(),
        (args.min_range, args.max_range),
        min_points,
        &bag,
    )?;
    if scans.len() < 2 {
        bail!("{}: one scan: expected at least two to match", scans[0].file);
    }
    let points: Vec<&[nalgebra::Point3<f32>]> = scans.iter().map(|s| s.points.as_slice()).collect();
    let mut settings = scale_settings(args, given, &scans, &points, &mut config)?;
    let starts: Vec<Isometry3<f64>> = match args.init {
        None => scans.iter().map(|s| s.start).collect(),
        Some(InitArg::Global) => {
            let voxel_m = settings.radius_m * GLOBAL_CELL_OF_RADIUS;
            let started = Instant::now();
            let global = fusion::global::GlobalConfig::new(voxel_m);
            let (starts, found) = fusion::global::starts(&points, &global).map_err(|e| named(e, &scans))?;
            settings.global = Some(GlobalReport {
                voxel_m,
                seconds: started.elapsed().as_secs_f64(),
                matches: found
                    .iter()
                    .enumerate()
                    .filter_map(|(i, f)| {
                        f.as_ref().map(|(j, m)| GlobalMatchReport {
                            source: i,
                            target: *j,
                            correspondences: m.correspondences,
                            inliers: m.inliers,
                        })
                    })
                    .collect(),
            });
            starts
        }
    };
    rayon::broadcast(|_| ());
    let started = Instant::now();
    let bar = progress_bar(args.json);
    let result = fusion::scanset::register_set(&points, &starts, &config, &mut |stage, stages, done, total| {
        bar.set_message(format!("stage {stage}/{stages}"));
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    });
    bar.finish_and_clear();
    let result = result.map_err(|e| named(e, &scans))?;
    let seconds = started.elapsed().as_secs_f64();
    let mut report = report(args.mode, &crs, &scans, &result, seconds, settings);
    if args.init == Some(InitArg::Global) {
        // A start found from the scans' shape says nothing along what no
        // match sees: a scan blind there has no pose the data confirm.
        report.blind_without_start =
            (1..report.scans.len()).filter(|&i| !report.scans[i].degenerate_directions.is_empty()).collect();
    }
    let written = write_outputs(args, &crs, &scans, &result, &report)?;
    if args.json {
        crate::view::document::write_line(out, &report)?;
    } else {
        write_text(out, &scans, &report)?;
        writeln!(out, "outputs in {}: {}", args.out.display(), written.join(", "))?;
    }
    // A scan the final matches do not hold, or that the verification
    // names, has a pose no data confirm: the outputs are written, and the
    // exit says it (1).
    Ok(Outcome::passed(
        unlinked(&report).is_empty() && report.untrusted.is_empty() && report.blind_without_start.is_empty(),
    ))
}

fn mode(m: ModeArg) -> Mode {
    match m {
        ModeArg::Pairwise => Mode::Pairwise,
        ModeArg::Incremental => Mode::Incremental,
        ModeArg::Simultaneous => Mode::Simultaneous,
        ModeArg::Graph => Mode::Graph,
    }
}

fn progress_bar(hidden: bool) -> indicatif::ProgressBar {
    if hidden {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(0);
    if let Ok(style) = indicatif::ProgressStyle::with_template("matching {msg} [{bar:30}] {pos}/{len}") {
        bar.set_style(style);
    }
    bar
}

/// A fusion error with the scans' indices turned into their files.
fn named(e: fusion::FusionError, scans: &[InputScan]) -> anyhow::Error {
    let file = |i: usize| scans.get(i).map_or_else(|| format!("scan {i}"), |s| s.file.clone());
    match e {
        fusion::FusionError::NoOverlap { scan, pairs, needed, against, partner, stage } => {
            let partner = partner.map_or(against, file);
            match stage {
                Some(k) if k > 1 => anyhow::anyhow!(
                    "{} and {partner} do not overlap at stage {k} of the schedule: {pairs} correspondences, expected at least {needed}; they did at the start, so a match of stage {} moved them apart (a symmetric fit from rough starts? try --init global, or starts nearer the truth)",
                    file(scan),
                    k - 1
                ),
                _ => anyhow::anyhow!(
                    "{} and {partner} do not overlap at their start poses: {pairs} correspondences, expected at least {needed} (are the start poses within the schedule's first distance, and do the scans overlap? --init global finds starts from the scans alone)",
                    file(scan)
                ),
            }
        }
        fusion::FusionError::InScan { scan, source } => anyhow::anyhow!("{}: {source}", file(scan)),
        e => anyhow::Error::new(e).context("matching the scans"),
    }
}

fn matrix<const R: usize, const C: usize>(f: impl Fn(usize, usize) -> f64) -> [[f64; C]; R] {
    std::array::from_fn(|r| std::array::from_fn(|c| f(r, c)))
}

/// Occupied voxel cells a scan needs at every stage of a given schedule:
/// fewer and ICP has nothing to fit (the coarsest stage of a 0.5 m
/// schedule holds a 0.27 m object in 3 cells).
const MIN_CELLS: usize = 50;

/// The scans' length scales, and the schedule and metre-valued settings
/// they call for, set into `config`: the schedule given or derived
/// ([`fusion::scale::SetScale::schedule`]), each stage checked to leave
/// every scan at least [`MIN_CELLS`] voxel cells (else refused naming the
/// stage, the scan and the spacing found, before any match); the Huber
/// width given or scaled, the step σ and the convergence tolerance scaled
/// to the schedule ([`fusion::scale::ScaledSettings`]).
fn scale_settings(
    args: &MatchArgs,
    given: Option<Vec<fusion::icp::Stage>>,
    scans: &[InputScan],
    points: &[&[nalgebra::Point3<f32>]],
    config: &mut SetConfig,
) -> Result<SettingsReport> {
    use fusion::scale::{ScaledSettings, SetScale, occupied_cells};
    check_distinct(scans)?;
    let Some(scale) = SetScale::of(points) else {
        bail!("{}: no two distinct points in any scan: nothing to measure or match", scans[0].file);
    };
    let auto = given.is_none();
    let stages = given.unwrap_or_else(|| scale.schedule());
    for stage in &stages {
        for (s, p) in scans.iter().zip(points) {
            let cells = occupied_cells(p, stage.voxel_m);
            if cells < MIN_CELLS {
                bail!(
                    "--schedule {}: stage {}/{} leaves {} in {cells} voxel cells (its points lie {:.3e} m apart over the surface, the scans' radius is {:.3e} m): expected at least {MIN_CELLS}; give stages whose voxels suit the scans (the finest near the spacing), or --schedule auto",
                    args.schedule,
                    stage.voxel_m,
                    stage.max_correspondence_m,
                    s.file,
                    scale.spacing_m,
                    scale.radius_m
                );
            }
        }
    }
    let scaled = ScaledSettings::of(&stages).context("an empty schedule")?;
    let huber_m = args.huber.unwrap_or(scaled.huber_m);
    let icp = &mut config.link.multiview.icp;
    icp.kernel = if huber_m > 0.0 { Kernel::Huber { width_m: huber_m } } else { Kernel::None };
    icp.translation_tolerance_m = scaled.translation_tolerance_m;
    config.link.step_sigma_m = scaled.step_sigma_m;
    config.link.multiview.moved_translation_m = scaled.moved_translation_m;
    config.stages = stages;
    Ok(SettingsReport {
        spacing_m: scale.spacing_m,
        radius_m: scale.radius_m,
        auto_schedule: auto,
        schedule: config.stages.iter().map(|s| [s.voxel_m, s.max_correspondence_m]).collect(),
        huber_m,
        step_sigma_m: scaled.step_sigma_m,
        translation_tolerance_m: scaled.translation_tolerance_m,
        moved_translation_m: scaled.moved_translation_m,
        global: None,
    })
}

/// Refuses a scan whose points all lie at one position (nothing to match:
/// issue 34, U5 blamed its reduced count) and two scans that hold the same
/// points (the same file or E57 scan given twice: U3), naming them.
fn check_distinct(scans: &[InputScan]) -> Result<()> {
    use std::hash::{Hash, Hasher};
    let mut seen: std::collections::HashMap<u64, usize> = std::collections::HashMap::new();
    for (i, s) in scans.iter().enumerate() {
        if s.points.iter().all(|p| *p == s.points[0]) {
            bail!("{}: its {} points all lie at one position: expected a scan of surfaces", s.file, s.points.len());
        }
        let mut h = std::collections::hash_map::DefaultHasher::new();
        s.points.len().hash(&mut h);
        s.points.iter().for_each(|p| [p.x, p.y, p.z].map(f32::to_bits).hash(&mut h));
        let key = h.finish();
        if let Some(&j) = seen.get(&key)
            && scans[j].points == s.points
        {
            bail!("{} and {} hold the same points: expected each scan once", scans[j].file, s.file);
        }
        seen.insert(key, i);
    }
    Ok(())
}

fn report(
    mode: ModeArg,
    crs: &scanner::io::Crs,
    scans: &[InputScan],
    r: &SetResult,
    seconds: f64,
    settings: SettingsReport,
) -> MatchReport {
    use clap::ValueEnum;
    let numbers = crate::scans::inputs::scan_numbers(scans);
    MatchReport {
        // The name the command line takes.
        mode: mode.to_possible_value().map_or_else(String::new, |v| v.get_name().to_owned()),
        crs: crate::run::report::CrsReport::new(crs),
        scans: scans
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let m = r.world_from_scan[i].to_homogeneous();
                let c: Matrix6<f64> = r.covariance[i];
                ScanReport {
                    file: s.file.clone(),
                    name: s.name.clone(),
                    number: numbers[i],
                    world_from_scan: matrix(|a, b| m[(a, b)]),
                    covariance: matrix(|a, b| c[(a, b)]),
                    degenerate_directions: directions(&r.unobservable[i]),
                }
            })
            .collect(),
        links: r
            .links
            .iter()
            .map(|l| LinkReport {
                source: l.source,
                targets: l.targets.clone(),
                overlap: l.overlap,
                correspondences: l.result.as_ref().map(|m| m.inliers),
                rmse_m: l.result.as_ref().map(|m| m.rmse_m),
                converged: l.result.as_ref().is_some_and(|m| m.converged),
                iterations: l.result.as_ref().map_or(0, |m| m.iterations),
                accepted: l.rejected.is_none(),
                reason: l.rejected.clone(),
                degenerate_directions: l.result.as_ref().map_or_else(Vec::new, |m| directions(&m.unobservable)),
                cycle: l.cycle.as_ref().map(|c| CycleReport {
                    scans: c.scans.clone(),
                    angle_deg: c.angle_rad.to_degrees(),
                    translation_m: c.translation_m,
                }),
            })
            .collect(),
        matches: r.matches,
        variance_factor: r.variance_factor,
        seconds,
        settings,
        stages: stage_reports(&r.stages),
        restart: r.restart.as_ref().map(|x| RestartReport {
            scan: x.scan,
            moved_m: x.moved_m,
            schedule_error: x.schedule_error.clone(),
            stages: stage_reports(&x.stages),
            schedule_disagreement_m2: x.disagreement_m2.0,
            restart_disagreement_m2: x.disagreement_m2.1,
            error: x.error.clone(),
            kept: x.kept,
        }),
        checks: r
            .checks
            .iter()
            .map(|c| CheckReport {
                source: c.source,
                target: c.target,
                overlap: c.overlap,
                moved_m: c.moved_m,
                angle_deg: c.angle_rad.map(f64::to_degrees),
                chi2: c.chi2,
                relative_motion: c.relative_motion,
                seen_motion_m: c.seen_motion_m,
                rmse_m: c.rmse_m,
                noise_m: c.noise_m,
                consistent: c.consistent,
            })
            .collect(),
        check_seconds: r.check_seconds,
        untrusted: fusion::verify::untrusted(scans.len(), &r.checks),
        blind_without_start: Vec::new(),
    }
}

fn stage_reports(stages: &[fusion::scanset::StageRun]) -> Vec<StageReport> {
    stages
        .iter()
        .map(|s| StageReport {
            voxel_m: s.voxel_m,
            max_correspondence_m: s.max_correspondence_m,
            matches: s.matches,
            seconds: s.seconds,
            settled: s.settled,
        })
        .collect()
}

/// poses.json, frames/NAME.frames, links.csv, the clouds and match.rrd.
fn write_outputs(
    args: &MatchArgs,
    crs: &scanner::io::Crs,
    scans: &[InputScan],
    r: &SetResult,
    report: &MatchReport,
) -> Result<Vec<String>> {
    let dir = &args.out;
    let frames = dir.join("frames");
    remove_stale_outputs(dir, &args.formats)?;
    // A link in frames' place is replaced by match's own directory, never
    // followed.
    if std::fs::symlink_metadata(&frames).is_ok_and(|m| m.file_type().is_symlink()) {
        std::fs::remove_file(&frames).with_context(|| format!("removing the link {}", frames.display()))?;
    }
    std::fs::create_dir_all(&frames).with_context(|| format!("creating {}", frames.display()))?;
    crate::view::document::write_file(&dir.join("poses.json"), report)?;
    let mut names = std::collections::HashSet::new();
    for (i, s) in scans.iter().enumerate() {
        // Unique, file-system-safe names (E57 scans may share theirs).
        let mut name: String =
            s.name.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect();
        if !names.insert(name.clone()) {
            name = format!("{name}_{i}");
            names.insert(name.clone());
        }
        scanner::io::write_3dtk_frames(&frames.join(format!("{name}.frames")), &r.world_from_scan[i])?;
    }
    write_links(&dir.join("links.csv"), scans, report)?;
    let mut written = vec!["poses.json".to_string(), "frames/".into(), "links.csv".into()];
    let numbers: Vec<u16> = report.scans.iter().map(|s| s.number).collect();
    written.extend(write_clouds(dir, &args.formats, crs, scans, &numbers, r)?);
    let rrd = dir.join("match.rrd");
    // Recorded into a new file beside it (a link or file there removed,
    // not followed) and renamed into place when whole: a full disk leaves
    // no truncated recording, a link at match.rrd is replaced.
    let partial = dir.join("match.rrd.partial");
    scanner::io::remove_entry(&partial)?;
    let recorded = (|| -> Result<bool> {
        let mut rec = Recorder::new("match", Some(&partial), &Viewer::None, Vec::new())?;
        if !rec.enabled() {
            return Ok(false);
        }
        for (i, s) in scans.iter().enumerate() {
            rec.scan("before", &s.name, fusion::direct::transform(&s.points, &s.start))?;
            rec.scan("after", &s.name, fusion::direct::transform(&s.points, &r.world_from_scan[i]))?;
        }
        rec.finish()?;
        std::fs::rename(&partial, &rrd).with_context(|| format!("writing {}", rrd.display()))?;
        Ok(true)
    })();
    if !matches!(recorded, Ok(true)) {
        let _ = std::fs::remove_file(&partial);
    }
    if recorded.with_context(|| format!("writing {}", rrd.display()))? {
        written.push("match.rrd".into());
    }
    if let Some(bag) = &args.ros2_bag {
        let registered: Vec<crate::ros2::registered::Registered<'_>> = scans
            .iter()
            .zip(&report.scans)
            .enumerate()
            .map(|(i, (s, rs))| crate::ros2::registered::Registered {
                name: &rs.name,
                points: &s.points,
                intensity: s.intensity.as_deref(),
                world_from_scan: r.world_from_scan[i],
                covariance: r.covariance[i],
                gps_time_s: s.gps_time_s,
            })
            .collect();
        let about = r.world_from_scan.first().map_or_else(nalgebra::Vector3::zeros, |t| t.translation.vector);
        crate::ros2::registered::write(bag, &registered, &about, &format!("cps-survey match; crs {}", crs.name))?;
        written.push(bag.display().to_string());
    }
    Ok(written)
}

fn write_links(path: &Path, scans: &[InputScan], report: &MatchReport) -> Result<()> {
    let mut text = String::from("source,targets,overlap,correspondences,rmse_m,converged,accepted,reason\n");
    let quote = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
    for l in &report.links {
        let targets: Vec<&str> = l.targets.iter().map(|&t| scans[t].file.as_str()).collect();
        let opt = |v: Option<String>| v.unwrap_or_default();
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{}\n",
            quote(&scans[l.source].file),
            quote(&targets.join(";")),
            opt(l.overlap.map(|v| v.to_string())),
            opt(l.correspondences.map(|v| v.to_string())),
            opt(l.rmse_m.map(|v| format!("{v:.6}"))),
            l.converged,
            l.accepted,
            quote(l.reason.as_deref().unwrap_or("")),
        ));
    }
    scanner::io::replace_file(path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))
}

/// The merged cloud in every format, a scan at a time, relative to the
/// first pose's position rounded to the kilometre (64-bit coordinates when
/// that is not zero).
fn write_clouds(
    dir: &Path,
    formats: &[String],
    crs: &scanner::io::Crs,
    scans: &[InputScan],
    numbers: &[u16],
    r: &SetResult,
) -> Result<Vec<String>> {
    let first = r.world_from_scan[0].translation.vector;
    let origin: Vector3<f64> = first.map(|v| (v / 1000.0).round() * 1000.0);
    let header = scanner::io::CloudHeader {
        origin,
        crs: Some(crs.clone()),
        points: Some(scans.iter().map(|s| s.points.len()).sum()),
        // What every input scan carries (intensity, colour, point times
        // of one base) or any (its time).
        intensity: scans.iter().all(|s| s.intensity.is_some()),
        source: true,
        timed: scans.iter().any(|s| s.gps_time_s.is_some()),
        color: scans.iter().all(|s| s.color.is_some()),
        time: point_time_base(scans),
    };
    let mut writers = Vec::with_capacity(formats.len());
    for format in formats {
        let name = crate::run::outputs::cloud_file(format);
        let path = dir.join(&name);
        writers.push((
            name,
            scanner::io::CloudWriter::create(&path, scanner::io::Format::from_path(&path)?, header.clone())?,
        ));
    }
    // Each scan moved into the world once, into every file.
    for (i, s) in scans.iter().enumerate() {
        let pose = r.world_from_scan[i];
        let relative = Isometry3::from_parts((pose.translation.vector - origin).into(), pose.rotation);
        let n = s.points.len();
        let part = scanner::io::PointCloud {
            points: fusion::direct::transform(&s.points, &relative),
            source: Some(vec![numbers[i]; n]),
            intensity: s.intensity.clone().filter(|_| header.intensity),
            color: s.color.clone().filter(|_| header.color),
            time: s.time.as_ref().filter(|_| header.time.is_some()).map(|(t, _)| t.clone()),
            time_base: header.time.unwrap_or_default(),
            origin,
            scans: vec![scanner::io::ScanInfo {
                name: s.name.clone(),
                points: 0..n,
                world_from_scan: pose,
                gps_time_s: s.gps_time_s,
            }],
            ..scanner::io::PointCloud::default()
        };
        for (_, writer) in &mut writers {
            writer.push(&part)?;
        }
    }
    let mut files = Vec::with_capacity(writers.len());
    for (name, writer) in writers {
        writer.finish()?;
        files.push(name);
    }
    Ok(files)
}

/// The base of the scans' point times, when every scan has times and all
/// count from the same epoch (else the merged cloud carries none).
fn point_time_base(scans: &[InputScan]) -> Option<scanner::io::TimeBase> {
    let bases: Option<Vec<_>> = scans.iter().map(|s| s.time.as_ref().map(|(_, b)| *b)).collect();
    let bases = bases?;
    bases.first().copied().filter(|b| bases.iter().all(|c| c == b))
}

fn write_text(out: &mut dyn Write, scans: &[InputScan], report: &MatchReport) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<32} {:>10} {:>10} {:>10} {:>9} {:>9}  unseen",
        "scan", "x m", "y m", "z m", "σ xyz mm", "σ rot °"
    )?;
    for (s, r) in scans.iter().zip(&report.scans) {
        let m = &r.world_from_scan;
        let c = &r.covariance;
        let (rot, pos) = ((c[0][0] + c[1][1] + c[2][2]).max(0.0).sqrt(), (c[3][3] + c[4][4] + c[5][5]).max(0.0).sqrt());
        writeln!(
            out,
            "{:<32} {:>10.4} {:>10.4} {:>10.4} {:>9.2} {:>9.4}  {}",
            s.name,
            m[0][3],
            m[1][3],
            m[2][3],
            pos * 1e3,
            rot.to_degrees(),
            r.degenerate_directions.len()
        )?;
    }
    let accepted = report.links.iter().filter(|l| l.accepted).count();
    writeln!(
        out,
        "{} links, {accepted} used; {} ICP runs; {:.3} s",
        report.links.len(),
        report.matches,
        report.seconds
    )?;
    let stages = |stages: &[StageReport]| -> String {
        let each: Vec<String> = stages
            .iter()
            .map(|s| {
                let cap = if s.settled { "" } else { ", abandoned at its cap" };
                format!("{:.3}/{:.3} m: {} runs, {:.3} s{cap}", s.voxel_m, s.max_correspondence_m, s.matches, s.seconds)
            })
            .collect();
        each.join("; ")
    };
    writeln!(out, "stages: {}", stages(&report.stages))?;
    if let Some(r) = &report.restart {
        let why = match (r.moved_m, &r.schedule_error) {
            (Some(m), _) => format!("the schedule moved {} {m:.3} m from its start", scans[r.scan].name),
            (None, e) => format!("the schedule failed ({})", e.as_deref().unwrap_or("")),
        };
        let outcome = match (r.restart_disagreement_m2, r.schedule_disagreement_m2, &r.error) {
            (Some(after), Some(before), _) => format!(
                "the scans disagree {after:.3e} m² a point there against {before:.3e} at the schedule's poses: {}",
                if r.kept { "its poses kept" } else { "the schedule's poses kept" }
            ),
            (_, _, Some(e)) => format!("it failed ({e}): the schedule's poses kept"),
            _ => "its poses kept".into(),
        };
        writeln!(out, "restart: {why}; from the starts without the first stage ({}), {outcome}", stages(&r.stages))?;
    }
    for i in unlinked(report) {
        writeln!(
            out,
            "  not trusted: {} has no accepted link at the last stage: it keeps the coarser stages' pose, blind in every direction",
            scans[i].name
        )?;
    }
    for &i in &report.blind_without_start {
        writeln!(
            out,
            "  not trusted: {}: blind in {} direction(s), and a start found by --init global says nothing along them",
            scans[i].name,
            report.scans[i].degenerate_directions.len()
        )?;
    }
    let tolerance = report.stages.last().map_or(0.0, |s| s.voxel_m);
    for &i in &report.untrusted {
        let against: Vec<String> = report
            .checks
            .iter()
            .filter(|c| !c.consistent && (c.source == i || c.target == i))
            .filter_map(|c| {
                let other = if c.source == i { c.target } else { c.source };
                Some(format!("{} ({:.3} m, {:.2}°)", scans[other].name, c.moved_m?, c.angle_deg.unwrap_or_default()))
            })
            .collect();
        writeln!(
            out,
            "  not trusted: {}: matched again from the final poses it moves beyond {tolerance:.3} m and 5 % of its \
             radius against {}: the poses are not where the data agree (a symmetric fit from rough starts?)",
            scans[i].name,
            against.join(", ")
        )?;
    }
    for l in report.links.iter().filter(|l| !l.accepted) {
        let targets: Vec<&str> = l.targets.iter().map(|&t| scans[t].name.as_str()).collect();
        let cycle = l.cycle.as_ref().map_or_else(String::new, |c| {
            let names: Vec<&str> = c.scans.iter().map(|&i| scans[i].name.as_str()).collect();
            format!(
                "; it contradicts the cycle {} → {} (the used links from {} to {} and this one disagree by {:.3}°, {:.3} m)",
                names.join(" → "),
                names.first().copied().unwrap_or_default(),
                names.first().copied().unwrap_or_default(),
                names.last().copied().unwrap_or_default(),
                c.angle_deg,
                c.translation_m
            )
        });
        writeln!(
            out,
            "  rejected {} → {}: {}{cycle}",
            scans[l.source].name,
            targets.join(", "),
            l.reason.as_deref().unwrap_or("")
        )?;
    }
    Ok(())
}

/// In graph mode, the scans (after the first, which holds the frame) that
/// no accepted link of the last stage reaches.
fn unlinked(report: &MatchReport) -> Vec<usize> {
    if report.mode != "graph" {
        return Vec::new();
    }
    (1..report.scans.len())
        .filter(|&i| !report.links.iter().any(|l| l.accepted && (l.source == i || l.targets.contains(&i))))
        .collect()
}

/// Refuses, before any work, an `--out` that is not `match`'s to write
/// into: a run directory (its cloud is the run's, under the run's lock),
/// or a directory that holds one of the inputs (an input named like an
/// output would be overwritten).
fn check_out(args: &MatchArgs) -> Result<()> {
    let out = &args.out;
    if out.join("journal.jsonl").exists() {
        bail!(
            "--out {}: a run directory (it holds journal.jsonl): match writes its outputs into a directory of its own",
            out.display()
        );
    }
    // An output's name taken by something match cannot replace (a
    // directory where a file goes, a file where frames/ goes) is refused
    // now, not after the registration (with a `.partial` left).
    let files = ["poses.json", "links.csv", "match.rrd"].map(String::from);
    let clouds = args.formats.iter().map(|f| crate::run::outputs::cloud_file(f));
    if let Some((name, meta)) = crate::run::outputs::taken(out, files.into_iter().chain(clouds)) {
        bail!(
            "--out {}: {name} is {}: expected match's output file there (or nothing)",
            out.display(),
            if meta.is_dir() { "a directory" } else { "not a file" }
        );
    }
    let frames = out.join("frames");
    if std::fs::symlink_metadata(&frames).is_ok_and(|m| !m.is_dir() && !m.file_type().is_symlink()) {
        bail!("--out {}: frames is a file: expected match's frames/ directory there (or nothing)", out.display());
    }
    let Ok(out_real) = out.canonicalize() else { return Ok(()) }; // not there yet: nothing in it
    for input in &args.inputs {
        let Ok(real) = input.canonicalize() else { continue }; // reading names it
        let holds = if real.is_dir() { real == out_real } else { real.parent() == Some(out_real.as_path()) };
        if holds {
            bail!(
                "--out {}: holds the input {}: expected a directory apart from the scans (its outputs would \
                 overwrite what they were made from)",
                out.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// A previous `match`'s outputs in `dir` that this one will not rewrite
/// — clouds of other formats, frames of other scans — are removed, so no
/// stale result stands beside the new ones. Only `match`'s own names.
fn remove_stale_outputs(dir: &Path, formats: &[String]) -> Result<()> {
    for format in crate::mission::OUTPUT_FORMATS.iter().filter(|f| !formats.iter().any(|g| g == *f)) {
        let path = dir.join(crate::run::outputs::cloud_file(format));
        if std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_file() || m.file_type().is_symlink()) {
            std::fs::remove_file(&path).with_context(|| format!("removing the stale {}", path.display()))?;
        }
    }
    let frames = dir.join("frames");
    if std::fs::symlink_metadata(&frames).is_ok_and(|m| m.is_dir()) {
        for entry in std::fs::read_dir(&frames).with_context(|| format!("reading {}", frames.display()))? {
            let path = entry.with_context(|| format!("reading {}", frames.display()))?.path();
            if path.extension().is_some_and(|e| e == "frames") {
                std::fs::remove_file(&path).with_context(|| format!("removing the stale {}", path.display()))?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(file: &str) -> InputScan {
        InputScan::empty(file, file)
    }

    #[test]
    fn no_overlap_blames_the_starts_only_at_the_first_stage() {
        let scans = [scan("a.ply"), scan("b.ply")];
        let error = |stage| fusion::FusionError::NoOverlap {
            scan: 1,
            pairs: 12,
            needed: 251,
            against: "the best earlier scan (0)".into(),
            partner: Some(0),
            stage,
        };
        let first = named(error(Some(1)), &scans).to_string();
        assert!(
            first.starts_with("b.ply and a.ply do not overlap at their start poses: 12 correspondences"),
            "{first}"
        );
        let later = named(error(Some(3)), &scans).to_string();
        assert!(
            later.starts_with("b.ply and a.ply do not overlap at stage 3 of the schedule")
                && later.contains("a match of stage 2 moved them apart")
                && !later.contains("start poses:"),
            "{later}"
        );
    }
}
