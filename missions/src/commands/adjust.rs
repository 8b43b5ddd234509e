//! `cps-survey adjust RUN_DIR`: the rigorous least-squares adjustment of a
//! run's whole network from its journal — every station, child placement
//! and control point from every reading — with the global test, data
//! snooping and reliability; `adjustment.txt` in the run directory, a
//! summary or one JSON object on the terminal.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use cps::batch::AdjustOptions;

use super::Outcome;

/// `adjust`'s arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct AdjustArgs {
    /// The run directory (holds mission.toml and journal.jsonl).
    pub run_dir: PathBuf,
    /// Print one JSON object instead of the summary.
    #[arg(long)]
    pub json: bool,
    /// Significance level of the global test, two-sided (1e-6 to 0.5).
    #[arg(long, value_name = "A", default_value_t = 0.05, value_parser = significance)]
    pub alpha: f64,
    /// Significance level of one w-test, data snooping (1e-6 to 0.5).
    #[arg(long, value_name = "A0", default_value_t = cps::stats::ALPHA0, value_parser = significance)]
    pub alpha0: f64,
    /// Power of one w-test against a bias of the MDB (0.5 to 0.999999).
    #[arg(long, value_name = "B", default_value_t = cps::stats::BETA0, value_parser = power)]
    pub power: f64,
    /// Test every observation but remove none.
    #[arg(long)]
    pub no_snooping: bool,
}

/// A probability in `[lo, hi]`: the statistics' quantiles are finite there
/// (at 1e-16 the global test's bound was null and every MDB NaN).
fn probability_in(s: &str, lo: f64, hi: f64, what: &str) -> Result<f64, String> {
    let p: f64 = s.trim().parse().map_err(|_| format!("\"{s}\" is not a number"))?;
    if !(lo..=hi).contains(&p) {
        return Err(format!("{s} is out of range; expected {what} from {lo} to {hi}"));
    }
    Ok(p)
}

fn significance(s: &str) -> Result<f64, String> {
    probability_in(s, 1e-6, 0.5, "a significance level")
}

fn power(s: &str) -> Result<f64, String> {
    probability_in(s, 0.5, 0.999_999, "a power")
}

impl AdjustArgs {
    /// The adjustment's options.
    pub fn options(&self) -> AdjustOptions {
        AdjustOptions {
            alpha: self.alpha,
            alpha0: self.alpha0,
            beta0: self.power,
            snooping: !self.no_snooping,
            ..AdjustOptions::default()
        }
    }
}

/// Runs `adjust`: exit 1 when the model fails (the global test fails and
/// data snooping does not find the cause).
pub fn run(args: &AdjustArgs, out: &mut dyn Write) -> Result<Outcome> {
    let dir = &args.run_dir;
    let _lock = crate::journal::directory::guard(dir, &format!("adjust {}", dir.display()))?;
    let run = crate::products::load::load_journal(dir)?;
    let path = dir.join("journal.jsonl");
    let net = crate::products::adjust::network(&run.mission, &run.planned, &run.journal, &path)?;
    let report = crate::products::adjust::adjust(&run.mission, &run.planned, &net, &args.options())?;
    let listing = dir.join("adjustment.txt");
    // Renamed into place: a full disk leaves the last listing whole, and a
    // hard-link snapshot of the run keeps its own.
    scanner::io::replace_file(&listing, crate::view::listing::listing(&run.mission, &report).as_bytes())
        .with_context(|| format!("writing {}", listing.display()))?;
    if args.json {
        crate::documents::write_line(out, &report)?;
    } else {
        crate::view::listing::summary(out, &report)?;
        writeln!(out, "the listing: {}", listing.display())?;
    }
    Ok(Outcome::passed(report.model_accepted))
}
