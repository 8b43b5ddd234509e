//! `match`'s command line: the arguments, the rosbag2 options and the
//! output CRS they give.

use std::path::PathBuf;

use anyhow::{Result, bail};
use fusion::scanset::Mode;

use crate::commands::register::MethodArg;

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
pub(super) const GLOBAL_CELL_OF_RADIUS: f64 = 1.0 / 40.0;

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
    /// simultaneous: at most this many matches for each new scan's queue
    /// at each stage; a queue still moving scans then is abandoned and its
    /// stage reported as not settled (`stages[].settled`). Bounds the
    /// mode's time where its queue creeps (a pipe: docs/match.md).
    #[arg(long, default_value_t = fusion::multiview::MultiviewConfig::default().max_matches_per_scan)]
    pub max_matches_per_scan: usize,
    /// Directions a match cannot see — eigenvalue of its normal matrix
    /// (about the scan's centroid, rotation scaled by its radius) below
    /// this ratio of the largest — are held where the start put them and
    /// reported (0: off). Default 2e-3 — or 0.01 where the scans are found
    /// a pipe: every scan's points on a tube fitted to them, all round it
    /// (`settings.pipe`, docs/match.md).
    #[arg(long)]
    pub degeneracy_ratio: Option<f64>,
    /// Judge those directions without the points whose normal is not a
    /// surface's: their ten nearest neighbours along one scan line (the
    /// middle PCA eigenvalue below this ratio of the largest; PCA takes
    /// the line's own plane for the surface) or with no clear smallest
    /// direction (the smallest above 0.2 of the middle), unless their 40
    /// nearest are a line too (a pole, a wire) or a surface with the same
    /// normal. Sparse scan lines of a pipe (a rotating scanner's slices
    /// far apart) make its axis look seen that way and the scans slide
    /// along it; 0.1 holds it (docs/match.md). 0: off. Default 0.1 when
    /// --degeneracy-ratio is given or the scans are found a pipe, as a
    /// mission's `[fusion] line_ratio` with its `degeneracy_ratio`; else 0 (at the default threshold it
    /// held a street's weakly seen direction where a start 2° off put it).
    #[arg(long)]
    pub line_ratio: Option<f64>,
    /// Every scan's frame has its scanner at the origin (PLY, XYZ and LAS
    /// say nothing of where the scanner stood; 3DTK, E57 scans with a
    /// pose, PCD and ROS 2 clouds do): the verification then tests every
    /// scan's free space from there, not from the position its spacing
    /// gives.
    #[arg(long)]
    pub scanner_at_origin: bool,
    /// Do not estimate where the scanners stood for the scans that do not
    /// say (without --scanner-at-origin): by default each such scan's
    /// viewpoint is estimated from its point spacing, which grows with
    /// the range, and used by the free-space test where the range
    /// explains the spacing (docs/match.md, "Where the scanners stood").
    #[arg(long)]
    pub no_viewpoint_estimate: bool,
    /// At the finest stage, leave out pairs whose point lies beyond what
    /// the other scan sampled around its partner (where a wedge or sector
    /// of a scan ends): scans cut by their field of view register several
    /// times closer, but a corridor's scans, held along its axis by a few
    /// edges, farther (docs/match.md).
    #[arg(long)]
    pub only_covered: bool,
    /// Leave out, in the matches made both ways (graph mode's links, the
    /// covariances' calibration, the verification), each pair whose two
    /// points' own normals differ by more than this many degrees: where
    /// one scan samples a surface far more sparsely than another (a
    /// façade seen at grazing angles in a rotating scanner's slices), its
    /// points' normals stand across the surface and the scans slide along
    /// it — 18 lands the building example's scans within 50 mm and the
    /// corridor's within 2.1 mm (docs/match.md). 0: off, the default.
    #[arg(long, default_value_t = 0.0)]
    pub normal_agreement: f64,
    /// Leave out each point-to-plane pair whose target normal came from a
    /// neighbourhood that is not one plane: its smallest PCA eigenvalue
    /// above this share of its middle one (a corner, where a floor meets
    /// a wall among the normal's nearest points). Such normals lean
    /// towards the scanner that saw them, and a chain of scans from
    /// different viewpoints bends: 0.1 lands the simulated hall's 22 scans
    /// 1.3–1.5× closer and the corridor's 20 1.7× (docs/match.md). Judged
    /// where the scan is sparse (see --corner-everywhere); every mode; 0:
    /// off.
    #[arg(long, default_value_t = 0.1)]
    pub corner_ratio: f64,
    /// With --corner-ratio: judge every target point's neighbourhood, not
    /// only those whose ten nearest points reach beyond the stage's
    /// correspondence distance (where the scan is sparse, far from its
    /// scanner, and the normals lean most): near the scanner a small
    /// room's corners hold its scans along the walls (docs/match.md).
    #[arg(long)]
    pub corner_everywhere: bool,
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
    /// Also report the poses' joint covariance (`joint_covariance` in
    /// poses.json, 6N×6N for N scans): what two poses' errors share, from
    /// which the relative pose of any two scans gets its covariance.
    #[arg(long)]
    pub joint_covariance: bool,
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
pub(super) fn bag_options(args: &MatchArgs) -> Result<crate::ros2::read::BagOptions> {
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
pub(super) fn output_crs(args: &MatchArgs) -> Result<scanner::io::Crs> {
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

pub(super) fn mode(m: ModeArg) -> Mode {
    match m {
        ModeArg::Pairwise => Mode::Pairwise,
        ModeArg::Incremental => Mode::Incremental,
        ModeArg::Simultaneous => Mode::Simultaneous,
        ModeArg::Graph => Mode::Graph,
    }
}
