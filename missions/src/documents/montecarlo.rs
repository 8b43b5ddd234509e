//! `montecarlo --json`: the final station's figures and every station's.
// The keys are documented in docs/json.md, key by key.
#![allow(missing_docs)]

use serde::Serialize;

use super::Document;

#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct McStationJson {
    pub index: usize,
    pub predicted_sigma_xy2_m2: f64,
    pub empirical_sigma_xy2_m2: f64,
    pub ratio: f64,
    pub nees_mean: f64,
}

impl McStationJson {
    pub fn of(s: &planner::montecarlo::CycleStatistics) -> Self {
        Self {
            index: s.cycle,
            predicted_sigma_xy2_m2: cps::sigma_xy2(&s.predicted),
            empirical_sigma_xy2_m2: cps::sigma_xy2(&s.empirical),
            ratio: s.ratio_xy(),
            nees_mean: s.nees_mean,
        }
    }
}

/// `montecarlo --json`: the final station's figures and every station's.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct MonteCarloJson {
    pub mission: String,
    pub seed: u64,
    pub trials: usize,
    pub predicted_sigma_xy2_m2: f64,
    pub empirical_sigma_xy2_m2: f64,
    pub ratio: f64,
    pub nees_mean: f64,
    pub nees_interval: [f64; 2],
    pub consistent: bool,
    pub stations: Vec<McStationJson>,
    pub adjusted: Vec<McStationJson>,
    pub adjusted_interval: Option<[f64; 2]>,
}

impl Document for MonteCarloJson {
    const NAME: &'static str = "montecarlo";
    const VERSION: u32 = 1;
}
