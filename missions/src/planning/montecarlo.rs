//! Seeded simulated executions of a mission's positioning (no scanning)
//! against the prediction: per station the empirical and predicted
//! horizontal variance, their ratio and the mean NEES with its 95 % χ²
//! interval (`cps-survey montecarlo`).

use anyhow::{Context, Result};
use planner::montecarlo::{CycleStatistics, monte_carlo, nees_interval};

use super::Planned;
use crate::mission::Mission;

/// The most trials `montecarlo` runs.
pub const MAX_TRIALS: usize = 100_000;

/// Degrees of freedom of the NEES (x, y, z, θ).
const NEES_DIM: usize = 4;

/// A Monte Carlo run of a mission's positioning.
#[derive(Debug, Clone)]
pub struct MonteCarlo {
    /// Trials run.
    pub trials: usize,
    /// Seed of trial streams (the mission's `[backend] seed`).
    pub seed: u64,
    /// The filter, per station after the start.
    pub stations: Vec<CycleStatistics>,
    /// 95 % interval of the mean NEES for this many trials.
    pub nees_interval: (f64, f64),
    /// With control points: the batch adjustment of every trial, per
    /// station, against the planned adjustment's covariance.
    pub adjusted: Vec<CycleStatistics>,
    /// The interval every adjusted station's mean NEES must lie in: 95 %
    /// for all of them together (each at 1 − 0.05 / stations, Bonferroni).
    pub adjusted_interval: (f64, f64),
}

impl MonteCarlo {
    /// The final station's statistics.
    pub fn last(&self) -> Option<&CycleStatistics> {
        self.stations.last()
    }

    /// Whether the final station's mean NEES lies in its interval, and
    /// every adjusted station's in theirs.
    pub fn consistent(&self) -> bool {
        let within = |s: &CycleStatistics, (lo, hi): (f64, f64)| (lo..=hi).contains(&s.nees_mean);
        self.last().is_some_and(|s| within(s, self.nees_interval))
            && self.adjusted.iter().all(|s| within(s, self.adjusted_interval))
    }
}

/// Runs `trials` executions of `mission`'s dance.
pub fn simulate(mission: &Mission, planned: &Planned, trials: usize) -> Result<MonteCarlo> {
    if trials < 2 {
        anyhow::bail!("--trials {trials}: expected at least 2 (an empirical covariance needs several trials)");
    }
    if trials > MAX_TRIALS {
        anyhow::bail!(
            "--trials {trials}: expected at most {MAX_TRIALS} (1000 pin the NEES to ±4 %; the time grows with the trials)"
        );
    }
    let seed = mission.backend.seed;
    let Some(instrument) = &mission.total_station else {
        anyhow::bail!(
            "mission \"{}\" has no children: montecarlo simulates the CPS dance, and a robot alone has none",
            mission.name
        );
    };
    let result = monte_carlo(&planned.dance, instrument, &mission.plan.start_covariance, trials, seed)
        .with_context(|| format!("Monte Carlo of mission \"{}\"", mission.name))?;
    // The mean of n NEES of a d-dimensional error is χ²_{dn} / n.
    let dof = (NEES_DIM * trials) as f64;
    let level = 0.05 / result.adjusted.len().max(1) as f64;
    let adjusted_interval = (
        cps::stats::chi2_quantile(level / 2.0, dof) / trials as f64,
        cps::stats::chi2_quantile(1.0 - level / 2.0, dof) / trials as f64,
    );
    Ok(MonteCarlo {
        trials,
        seed,
        stations: result.filter,
        nees_interval: nees_interval(NEES_DIM, trials),
        adjusted: result.adjusted,
        adjusted_interval,
    })
}
