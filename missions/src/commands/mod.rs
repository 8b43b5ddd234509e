//! One file per subcommand: its arguments (clap) and its `run`, which
//! builds what the command needs once — the mission, its plan — and hands
//! it to the rooms that do the work ([`crate::planning`], [`crate::run`])
//! and show it ([`crate::view`]).

pub mod adjust;
pub mod emulate;
pub mod export;
pub mod fuse;
pub mod match_set;
pub mod montecarlo;
pub mod plan;
pub mod predict;
pub mod register;
pub mod run;
pub mod schemas;
pub mod validate;

use std::path::Path;

/// How a command that ran ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Everything passed (exit 0).
    Success,
    /// Ran, but failed the mission's acceptance tolerances (exit 1).
    AcceptanceFailed,
}

impl Outcome {
    /// Success when `passed`, else an acceptance failure.
    pub fn passed(passed: bool) -> Self {
        if passed { Outcome::Success } else { Outcome::AcceptanceFailed }
    }
}

/// `predict`'s and `plan`'s views of a plan.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct PlanViews {
    /// Also draw σ_xy and σ_θ versus distance and a top view with the 95 %
    /// ellipses (with `plan`: the violations, and the optimized plan) (SVG).
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<std::path::PathBuf>,
    /// Also write the plan to a Rerun recording: route, stations, moves and
    /// sight lines (red where they break a constraint), predicted ellipsoids
    /// per step (with `plan`: the violations, and the optimized plan).
    #[arg(long, value_name = "FILE.rrd")]
    pub rrd: Option<std::path::PathBuf>,
}

impl PlanViews {
    /// Checks both files before anything is computed (and that this build
    /// can record).
    pub fn check(&self) -> anyhow::Result<()> {
        if let Some(file) = &self.plot {
            check_output("--plot", file, "svg", crate::view::plot::SVG_HINT)?;
        }
        if let Some(file) = &self.rrd {
            check_output("--rrd", file, "rrd", "")?;
            crate::view::recording::available()?;
        }
        Ok(())
    }
}

/// Says where a plan recording went.
pub fn recorded_plan(out: &mut dyn std::io::Write, file: &Path) -> std::io::Result<()> {
    writeln!(out, "recorded the plan in {} (view it with `rerun {}`)", file.display(), file.display())
}

/// Checks, before anything is computed or printed, that an output file
/// `path` given to `flag` ends in `.extension` and that its directory
/// exists.
pub fn check_output(flag: &str, path: &Path, extension: &str, hint: &str) -> anyhow::Result<()> {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case(extension) => {}
        _ => anyhow::bail!("{flag} {}: expected a file ending in .{extension}{hint}", path.display()),
    }
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !dir.is_dir() {
        anyhow::bail!("{flag} {}: the directory {} does not exist", path.display(), dir.display());
    }
    Ok(())
}
