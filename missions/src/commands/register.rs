//! `cps-survey register SOURCE TARGET`: ICP between two scan files.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};

use fusion::icp::{IcpConfig, IcpResult, Kernel, Method, Stage, align_coarse_to_fine};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};

use crate::documents::register::RegisterReport;

/// The error metric on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MethodArg {
    /// Closed-form point-to-point (Horn).
    PointToPoint,
    /// Point-to-plane with PCA normals of the target.
    PointToPlane,
}

/// `register`'s options.
#[derive(Debug, Clone, clap::Args)]
pub struct RegisterArgs {
    /// The scan to move (any supported format: .3d, .ply, .pcd, .xyz, .las, .e57).
    pub source: PathBuf,
    /// The scan to align to.
    pub target: PathBuf,
    /// Initial target_from_source: "x y z roll pitch yaw" in metres and
    /// degrees, R = Rz(yaw)·Ry(pitch)·Rx(roll). Default identity.
    #[arg(long, allow_hyphen_values = true, conflicts_with = "init_file")]
    pub init: Option<String>,
    /// Initial target_from_source as a 4×4 row-major matrix file.
    #[arg(long)]
    pub init_file: Option<PathBuf>,
    /// Error metric.
    #[arg(long, value_enum, default_value = "point-to-plane")]
    pub method: MethodArg,
    /// Reduced-points cell of both clouds, metres.
    #[arg(long, default_value_t = 0.1)]
    pub voxel: f64,
    /// Maximum correspondence distance, metres.
    #[arg(long, default_value_t = 1.0)]
    pub max_dist: f64,
    /// Coarse-to-fine schedule "VOXEL/MAXDIST,…" in metres (replaces
    /// --voxel and --max-dist), e.g. "0.5/2,0.25/1,0.1/0.5,0.05/0.2".
    #[arg(long, conflicts_with_all = ["voxel", "max_dist"])]
    pub schedule: Option<String>,
    /// Iteration cap (per stage), 1 to 10,000.
    #[arg(long, default_value_t = 50, value_parser = iterations)]
    pub iterations: usize,
    /// Converged when an update moves less than this, metres.
    #[arg(long, default_value_t = 1e-5)]
    pub tolerance_m: f64,
    /// Converged when an update turns less than this, degrees.
    #[arg(long, default_value_t = 1e-5_f64.to_degrees())]
    pub tolerance_deg: f64,
    /// Huber kernel width, metres (robust ICP); default plain least squares.
    #[arg(long)]
    pub huber: Option<f64>,
    /// Drop points nearer than this to their scan's origin, metres.
    #[arg(long, default_value_t = 0.0)]
    pub min_range: f64,
    /// Drop points farther than this from their scan's origin, metres.
    #[arg(long, default_value_t = f64::INFINITY)]
    pub max_range: f64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `--iterations`: a cap that ends (18446744073709551615 with zero
/// tolerances never did).
fn iterations(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if (1..=10_000).contains(&n) => Ok(n),
        _ => Err(format!("{s} is out of range; expected a whole number of iterations from 1 to 10000")),
    }
}

/// Runs `register`: reads both scans, aligns and writes the report.
pub fn run(args: &RegisterArgs, out: &mut dyn Write) -> anyhow::Result<super::Outcome> {
    let stages = stages(args)?;
    let init = initial_guess(args)?;
    let config = IcpConfig {
        method: match args.method {
            MethodArg::PointToPoint => Method::PointToPoint,
            MethodArg::PointToPlane => Method::PointToPlane,
        },
        max_iterations: args.iterations,
        translation_tolerance_m: args.tolerance_m,
        rotation_tolerance_rad: args.tolerance_deg.to_radians(),
        kernel: args.huber.map_or(Kernel::None, |k| Kernel::Huber { width_m: k }),
        ..IcpConfig::default()
    };
    crate::scans::settings::check_range(args.min_range, args.max_range)?;
    let source = load(&args.source, args.min_range, args.max_range)?;
    let target = load(&args.target, args.min_range, args.max_range)?;
    // Start the worker threads now: spawning the pool is neither
    // preprocessing nor registration, and a program that registers many
    // scans pays it once.
    rayon::broadcast(|_| ());
    let start = Instant::now();
    let result = align_coarse_to_fine(&source, &target, &init, &stages, &config)
        .with_context(|| format!("registering {} to {}", args.source.display(), args.target.display()))?;
    let seconds = start.elapsed().as_secs_f64();
    if args.json {
        crate::documents::write_line(out, &report(&result, seconds))?;
    } else {
        write_text(out, &result, seconds)?;
    }
    Ok(super::Outcome::Success)
}

fn stages(args: &RegisterArgs) -> anyhow::Result<Vec<Stage>> {
    match &args.schedule {
        Some(text) => crate::scans::settings::schedule(text),
        None => Ok(vec![Stage { voxel_m: args.voxel, max_correspondence_m: args.max_dist }]),
    }
}

fn initial_guess(args: &RegisterArgs) -> anyhow::Result<Isometry3<f64>> {
    if let Some(path) = &args.init_file {
        let m = scanner::io::read_matrix4(path)?;
        return crate::scans::settings::rigid(&m).with_context(|| format!("{}: the initial guess", path.display()));
    }
    let Some(text) = &args.init else { return Ok(Isometry3::identity()) };
    let v: Vec<f64> = text.split_whitespace().map(str::parse).collect::<Result<_, _>>().map_err(|_| {
        anyhow::anyhow!("--init \"{text}\": expected six numbers \"x y z roll pitch yaw\" (metres, degrees)")
    })?;
    match v[..] {
        [x, y, z, roll, pitch, yaw] if v.iter().all(|f| f.is_finite()) => Ok(Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_euler_angles(roll.to_radians(), pitch.to_radians(), yaw.to_radians()),
        )),
        _ => bail!("--init \"{text}\": expected six finite numbers \"x y z roll pitch yaw\" (metres, degrees)"),
    }
}

fn load(path: &Path, min_m: f64, max_m: f64) -> anyhow::Result<Vec<Point3<f32>>> {
    let points = crate::scans::settings::within_range(scanner::io::read(path)?.points, min_m, max_m);
    if points.is_empty() {
        bail!("{}: no points between {min_m} m and {max_m} m from the scan origin", path.display());
    }
    Ok(points)
}

fn report(r: &IcpResult, seconds: f64) -> RegisterReport {
    let m = r.target_from_source.to_homogeneous();
    let covariance = r.covariance().map_or_else(Vec::new, |c| crate::documents::records::rows(&c).to_vec());
    RegisterReport {
        target_from_source: crate::documents::records::rows(&m),
        converged: r.converged,
        iterations: r.iterations,
        inliers: r.inliers,
        rmse_m: r.rmse_m,
        seconds,
        covariance,
    }
}

fn write_text(out: &mut dyn Write, r: &IcpResult, seconds: f64) -> std::io::Result<()> {
    let m = r.target_from_source.to_homogeneous();
    writeln!(out, "target_from_source")?;
    for i in 0..4 {
        writeln!(out, "  {:12.6} {:12.6} {:12.6} {:12.6}", m[(i, 0)], m[(i, 1)], m[(i, 2)], m[(i, 3)])?;
    }
    let (roll, pitch, yaw) = r.target_from_source.rotation.euler_angles();
    let t = r.target_from_source.translation.vector;
    writeln!(
        out,
        "x y z          {:.4} {:.4} {:.4} m\nroll pitch yaw {:.4} {:.4} {:.4} °",
        t.x,
        t.y,
        t.z,
        roll.to_degrees(),
        pitch.to_degrees(),
        yaw.to_degrees()
    )?;
    writeln!(out, "converged      {} after {} iterations", if r.converged { "yes" } else { "NO" }, r.iterations)?;
    writeln!(out, "inliers        {}", r.inliers)?;
    writeln!(out, "RMSE           {:.4} m", r.rmse_m)?;
    if let Some(c) = r.covariance() {
        let s = |i: usize| c[(i, i)].max(0.0).sqrt();
        writeln!(
            out,
            "σ rotation     {:.4} {:.4} {:.4} °  (about x y z, target frame)",
            s(0).to_degrees(),
            s(1).to_degrees(),
            s(2).to_degrees()
        )?;
        writeln!(out, "σ translation  {:.4} {:.4} {:.4} m", s(3), s(4), s(5))?;
    }
    writeln!(out, "time           {:.1} ms (preprocessing + registration)", seconds * 1e3)
}
