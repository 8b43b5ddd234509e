//! `cps-survey predict MISSION`: the covariance after every dance cycle of
//! a mission's plan, every child's after its placement and every scan
//! station's — a table or JSON, a plot, a plan recording.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;

use super::{Outcome, check_output};
use crate::mission::Mission;
use crate::planning::Planned;

/// `predict`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct PredictArgs {
    /// The mission file (TOML).
    pub mission: PathBuf,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Also draw σ_xy and σ_θ versus distance and a top view with the 95 %
    /// ellipses (SVG).
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// Also write the plan to a Rerun recording (route, stations, moves,
    /// sight lines, predicted ellipsoids per step).
    #[arg(long, value_name = "FILE.rrd")]
    pub rrd: Option<PathBuf>,
}

/// Runs `predict`: exit 1 when the prediction misses
/// `max_final_sigma_xy_m`.
pub fn run(args: &PredictArgs, out: &mut dyn Write) -> Result<Outcome> {
    if let Some(file) = &args.plot {
        check_output("--plot", file, "svg", crate::view::plot::SVG_HINT)?;
    }
    if let Some(file) = &args.rrd {
        check_output("--rrd", file, "rrd", "")?;
        crate::view::recording::available()?;
    }
    let mission = Mission::load(&args.mission)?;
    let planned = Planned::new(&mission)?;
    if args.json {
        crate::view::json::prediction(out, &mission, &planned)?;
    } else {
        crate::view::tables::prediction(out, &mission, &planned)?;
    }
    if let Some(file) = &args.plot {
        let plan = crate::view::plot::PlotPlan::of("as written", &planned, &[]);
        let title = format!("cps-survey predict — mission {}", mission.name);
        let summary = crate::view::plot::write_svg(file, &title, &[plan], planned.checked_scene())?;
        if !args.json {
            crate::view::plot::plotted(out, file, &summary)?;
        }
    }
    if let Some(file) = &args.rrd {
        crate::view::recording::write_plan_rrd(&mission, file, &[("plan", &planned, &[])])?;
        if !args.json {
            writeln!(out, "recorded the plan in {} (view it with `rerun {}`)", file.display(), file.display())?;
        }
    }
    Ok(Outcome::passed(crate::planning::accepted(&mission, &planned)))
}
