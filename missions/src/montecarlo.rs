//! `cps-survey montecarlo`: seeded simulated executions of a mission's
//! positioning (no scanning) against the prediction — per station the
//! empirical and predicted horizontal variance, their ratio and the mean
//! NEES with its 95 % χ² interval.

use std::io::Write;

use anyhow::{Context, Result};
use planner::montecarlo::{CycleStatistics, monte_carlo, nees_interval};
use serde_json::json;

use crate::mission::Mission;

/// Degrees of freedom of the NEES (x, y, z, θ).
const NEES_DIM: usize = 4;

/// A Monte Carlo run of a mission's positioning.
#[derive(Debug, Clone)]
pub struct MonteCarlo {
    /// Trials run.
    pub trials: usize,
    /// Seed of trial streams (the mission's `[backend] seed`).
    pub seed: u64,
    /// Per station after the start.
    pub stations: Vec<CycleStatistics>,
    /// 95 % interval of the mean NEES for this many trials.
    pub nees_interval: (f64, f64),
}

impl MonteCarlo {
    /// The final station's statistics.
    pub fn last(&self) -> Option<&CycleStatistics> {
        self.stations.last()
    }

    /// Whether the final station's mean NEES lies in its interval.
    pub fn consistent(&self) -> bool {
        self.last().is_some_and(|s| (self.nees_interval.0..=self.nees_interval.1).contains(&s.nees_mean))
    }
}

/// Runs `trials` executions of `mission`'s dance.
pub fn run(mission: &Mission, trials: usize) -> Result<MonteCarlo> {
    if trials < 2 {
        anyhow::bail!("--trials {trials}: expected at least 2 (an empirical covariance needs several trials)");
    }
    let dance = crate::predict::dance(mission)?;
    let seed = mission.backend.seed;
    let Some(instrument) = &mission.total_station else {
        anyhow::bail!(
            "mission \"{}\" has no children: montecarlo simulates the CPS dance, and a robot alone has none",
            mission.name
        );
    };
    let stations = monte_carlo(&dance, instrument, &mission.plan.start_covariance, trials, seed)
        .with_context(|| format!("Monte Carlo of mission \"{}\"", mission.name))?;
    Ok(MonteCarlo { trials, seed, stations, nees_interval: nees_interval(NEES_DIM, trials) })
}

/// The table: one row per station, then the verdict.
pub fn write_table(out: &mut dyn Write, mission: &Mission, mc: &MonteCarlo) -> std::io::Result<()> {
    writeln!(out, "mission \"{}\": {} trials (seed {}), positioning only", mission.name, mc.trials, mc.seed)?;
    writeln!(out, "{:>7} {:>13} {:>13} {:>7} {:>9}", "station", "pred σxy_mm", "emp σxy_mm", "ratio", "NEES")?;
    for s in &mc.stations {
        writeln!(
            out,
            "{:>7} {:>13.3} {:>13.3} {:>7.3} {:>9.3}",
            s.cycle,
            1e3 * cps::sigma_xy2(&s.predicted).sqrt(),
            1e3 * cps::sigma_xy2(&s.empirical).sqrt(),
            s.ratio_xy(),
            s.nees_mean
        )?;
    }
    let (lo, hi) = mc.nees_interval;
    writeln!(
        out,
        "final mean NEES {:.3}, 95 % interval [{lo:.3}, {hi:.3}] for {} trials: {}",
        mc.last().map_or(f64::NAN, |s| s.nees_mean),
        mc.trials,
        if mc.consistent() { "consistent with the prediction" } else { "NOT consistent with the prediction" }
    )
}

/// One JSON object: the final station's figures and every station's.
pub fn write_json(out: &mut dyn Write, mission: &Mission, mc: &MonteCarlo) -> Result<()> {
    let last = mc.last().context("the mission has no dance cycle")?;
    let value = json!({
        "mission": mission.name,
        "seed": mc.seed,
        "trials": mc.trials,
        "predicted_sigma_xy2_m2": cps::sigma_xy2(&last.predicted),
        "empirical_sigma_xy2_m2": cps::sigma_xy2(&last.empirical),
        "ratio": last.ratio_xy(),
        "nees_mean": last.nees_mean,
        "nees_interval": [mc.nees_interval.0, mc.nees_interval.1],
        "consistent": mc.consistent(),
        "stations": mc.stations.iter().map(|s| json!({
            "index": s.cycle,
            "predicted_sigma_xy2_m2": cps::sigma_xy2(&s.predicted),
            "empirical_sigma_xy2_m2": cps::sigma_xy2(&s.empirical),
            "ratio": s.ratio_xy(),
            "nees_mean": s.nees_mean,
        })).collect::<Vec<_>>(),
    });
    writeln!(out, "{value}")?;
    Ok(())
}
