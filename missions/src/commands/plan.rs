//! `cps-survey plan MISSION`: the mission's schedule checked step by step
//! against the scene and the instruments, what its final error is made of,
//! and with `--optimize` the best formation, stride and strategy.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;

use super::{Outcome, check_output};
use crate::mission::Mission;
use crate::planning::Planned;
use crate::planning::analysis::{self, PlanReport};
use crate::view::plot::PlotPlan;

/// `plan`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct PlanArgs {
    /// The mission file (TOML).
    pub mission: PathBuf,
    /// Search [plan.search] for the best plan that keeps every constraint.
    #[arg(long)]
    pub optimize: bool,
    /// Write the chosen plan as a complete mission file.
    #[arg(long, value_name = "FILE", requires = "optimize")]
    pub out: Option<PathBuf>,
    /// Print one JSON object instead of the text report.
    #[arg(long)]
    pub json: bool,
    /// The plot and the plan recording (with the violations, and the
    /// optimized plan beside the written one).
    #[command(flatten)]
    pub views: super::PlanViews,
}

/// Runs `plan`: exit 1 when the plan (the chosen one with `--optimize`)
/// breaks a constraint or misses `[acceptance]`.
pub fn run(args: &PlanArgs, out: &mut dyn Write) -> Result<Outcome> {
    args.views.check()?;
    if let Some(file) = &args.out {
        check_output("--out", file, "toml", "")?;
    }
    let mission = Mission::load(&args.mission)?;
    let written = Planned::as_written(&mission)?;
    let report = analysis::analyse(&mission, written, args.optimize)?;
    if args.json {
        crate::view::json::plan(out, &mission, &report)?;
    } else {
        crate::view::tables::plan(out, &mission, &report)?;
    }
    if let Some(file) = &args.views.plot {
        let summary = plot(&mission, &report, file)?;
        if !args.json {
            crate::view::plot::plotted(out, file, &summary)?;
        }
    }
    if let Some(file) = &args.views.rrd {
        let mut plans = vec![("plan", &report.written, report.violations.as_slice())];
        if let Some(o) = &report.optimized {
            plans.push(("plan_optimized", &o.planned, &[]));
        }
        crate::view::recording::write_plan_rrd(&mission, file, &plans)?;
        if !args.json {
            super::recorded_plan(out, file)?;
        }
    }
    if let (Some(file), Some(o)) = (&args.out, &report.optimized) {
        crate::planning::edit::write_mission(&mission, o, file)?;
        if !args.json {
            writeln!(out, "wrote {}", file.display())?;
        }
    }
    Ok(Outcome::passed(analysis::accepted(&mission, &report)))
}

/// `--plot`: the plan as written, and the optimized one if any.
fn plot(mission: &Mission, report: &PlanReport, path: &std::path::Path) -> Result<crate::view::plot::PlotSummary> {
    let mut plans = vec![PlotPlan::of("as written", &report.written, &report.violations)];
    if let Some(o) = &report.optimized {
        plans.push(PlotPlan::of("optimized", &o.planned, &[]));
    }
    let title = format!("cps-survey plan — mission {}", mission.name);
    crate::view::plot::write_svg(path, &title, &plans, report.written.checked_scene())
}
