//! `cps-survey predict MISSION`: the covariance after every dance cycle of
//! a mission's plan, every child's after its placement and every scan
//! station's — a table or JSON, a plot, a plan recording.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;

use super::Outcome;
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
    /// The plot and the plan recording.
    #[command(flatten)]
    pub views: super::PlanViews,
}

/// Runs `predict`: exit 1 when the plan misses `[acceptance]`.
pub fn run(args: &PredictArgs, out: &mut dyn Write) -> Result<Outcome> {
    args.views.check()?;
    let mission = Mission::load(&args.mission)?;
    let planned = Planned::new(&mission)?;
    if args.json {
        crate::view::json::prediction(out, &mission, &planned)?;
    } else {
        crate::view::tables::prediction(out, &mission, &planned)?;
    }
    if let Some(file) = &args.views.plot {
        let plan = crate::view::plot::PlotPlan::of("as written", &planned, &[]);
        let title = format!("cps-survey predict — mission {}", mission.name);
        let summary = crate::view::plot::write_svg(file, &title, &[plan], planned.checked_scene())?;
        if !args.json {
            crate::view::plot::plotted(out, file, &summary)?;
        }
    }
    if let Some(file) = &args.views.rrd {
        crate::view::recording::write_plan_rrd(&mission, file, &[("plan", &planned, &[])])?;
        if !args.json {
            super::recorded_plan(out, file)?;
        }
    }
    Ok(Outcome::passed(crate::planning::accepted(&mission, &planned)))
}
