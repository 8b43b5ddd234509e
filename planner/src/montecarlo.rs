//! Monte Carlo of the real non-linear procedure: noisy readings → children
//! placed from the *estimated* parent → Gauss–Newton fix, repeated over
//! seeded trials and compared with [`crate::predict()`].

use nalgebra::{Matrix4, SymmetricEigen, Vector4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use cps::{Instrument, ParentPose, Reading, TeamState, observe, wrap_angle};

use crate::dance::Sighted;

use crate::dance::{Dance, run_dance};
use crate::error::PlanError;

/// A reading from `from` to `to` with the instrument's noise added.
pub fn noisy_reading(
    from: &ParentPose,
    to: &nalgebra::Point3<f64>,
    instrument: &Instrument,
    rng: &mut impl Rng,
) -> cps::Result<Reading> {
    let truth = observe(from, to)?;
    let z = [(); 3].map(|()| rng.sample(StandardNormal));
    Ok(instrument.perturbed(&truth, z))
}

/// Draws a pose error with covariance `cov` (positive semi-definite).
fn sample_pose_error(cov: &Matrix4<f64>, rng: &mut impl Rng) -> Vector4<f64> {
    let eig = SymmetricEigen::new(*cov);
    let z = Vector4::from_fn(|i, _| eig.eigenvalues[i].max(0.0).sqrt() * rng.sample::<f64, _>(StandardNormal));
    eig.eigenvectors * z
}

/// One simulated execution of a dance.
#[derive(Debug, Clone, PartialEq)]
pub struct Trial {
    /// The start's estimate (drawn from the start covariance, or resected
    /// on the control points).
    pub start: ParentPose,
    /// The parent's estimate after each cycle.
    pub estimates: Vec<ParentPose>,
    /// Every reading, in [`crate::network::reading_order`].
    pub readings: Vec<Reading>,
}

/// One simulated execution of the dance: the team truly stands at the
/// nominal positions, the parent's start estimate is drawn from
/// `start_covariance`, each control prism truly stands off its given
/// coordinates by a draw of their covariance and of its centring, readings
/// are noisy, and the estimates are produced by the same procedure a real
/// run uses.
pub fn execute(
    dance: &Dance,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
    rng: &mut impl Rng,
) -> Result<Trial, PlanError> {
    let start = dance.station_pose(0);
    let start_estimate = ParentPose::from_vector(&(start.to_vector() + sample_pose_error(start_covariance, rng)));
    let prisms: Vec<nalgebra::Point3<f64>> = dance
        .control
        .iter()
        .map(|c| {
            let cov = c.prism_covariance(instrument);
            let error =
                sample_pose_error(&Matrix4::from_fn(|i, j| if i < 3 && j < 3 { cov[(i, j)] } else { 0.0 }), rng);
            c.position + error.xyz()
        })
        .collect();
    let mut team = TeamState::new(start_estimate, *start_covariance, dance.n_children())
        .map_err(|source| PlanError::Model { cycle: 0, source })?;
    let sighting = crate::control::sighting_instrument(instrument);
    let mut readings = Vec::new();
    let read = |from: &ParentPose, sighted: Sighted<'_>| {
        let reading = match sighted {
            Sighted::Child(to) => noisy_reading(from, to, instrument, rng),
            Sighted::Control(k) => noisy_reading(from, &prisms[k], &sighting, rng),
        }?;
        readings.push(reading);
        Ok(reading)
    };
    let mut estimates = Vec::with_capacity(dance.cycles.len());
    let mut resected = None;
    run_dance(dance, &mut team, instrument, false, read, |c, team, _| match c {
        None => resected = Some(team.parent()),
        Some(_) => estimates.push(team.parent()),
    })?;
    Ok(Trial { start: resected.unwrap_or(start_estimate), estimates, readings })
}

/// Empirical accuracy of one station over all trials, against the prediction.
#[derive(Debug, Clone, PartialEq)]
pub struct CycleStatistics {
    /// Cycle number, 1-based — the station reached by it (0: the start).
    pub cycle: usize,
    /// Predicted covariance (x, y, z, θ).
    pub predicted: Matrix4<f64>,
    /// Empirical second moment of the error about the truth (x, y, z, θ).
    pub empirical: Matrix4<f64>,
    /// Mean normalised estimation error squared eᵀP⁻¹e (4 degrees of freedom).
    pub nees_mean: f64,
}

impl CycleStatistics {
    /// Empirical over predicted σx² + σy².
    pub fn ratio_xy(&self) -> f64 {
        cps::sigma_xy2(&self.empirical) / cps::sigma_xy2(&self.predicted)
    }
}

/// What a Monte Carlo run finds.
#[derive(Debug, Clone, PartialEq)]
pub struct MonteCarloResult {
    /// The filter's estimate at every station after the start, against the
    /// filter's prediction.
    pub filter: Vec<CycleStatistics>,
    /// With control points: the batch adjustment of every trial's readings
    /// at every station whose adjusted covariance is regular (the start
    /// too when it is resected or uncertain), against the planned
    /// adjustment's covariance. Empty without control.
    pub adjusted: Vec<CycleStatistics>,
}

/// Accumulates errors of one station over the trials.
struct Accumulator {
    station: usize,
    predicted: Matrix4<f64>,
    inverse: Option<Matrix4<f64>>,
    second: Matrix4<f64>,
    nees: f64,
}

impl Accumulator {
    fn new(station: usize, predicted: Matrix4<f64>) -> Self {
        Self {
            station,
            predicted,
            inverse: predicted.cholesky().map(|c| c.inverse()),
            second: Matrix4::zeros(),
            nees: 0.0,
        }
    }

    fn add(&mut self, estimate: &ParentPose, truth: &ParentPose) {
        let mut e = estimate.to_vector() - truth.to_vector();
        e[3] = wrap_angle(e[3]);
        self.second += e * e.transpose();
        if let Some(inv) = &self.inverse {
            self.nees += (e.transpose() * inv * e)[(0, 0)];
        }
    }

    fn statistics(&self, trials: usize) -> CycleStatistics {
        let n = trials.max(1) as f64;
        CycleStatistics {
            cycle: self.station,
            predicted: self.predicted,
            empirical: self.second / n,
            nees_mean: self.nees / n,
        }
    }
}

/// Runs `trials` seeded executions and returns per-station statistics of
/// the filter and, with control points, of the batch adjustment. Trial `t`
/// uses the ChaCha8 stream seeded with `seed` and stream `t`, so results do
/// not depend on evaluation order.
pub fn monte_carlo(
    dance: &Dance,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
    trials: usize,
    seed: u64,
) -> Result<MonteCarloResult, PlanError> {
    let prediction = crate::predict(dance, instrument, start_covariance)?;
    let mut filter: Vec<Accumulator> =
        prediction.cycles.iter().map(|c| Accumulator::new(c.cycle, c.covariance)).collect();
    let adjust_options = cps::batch::AdjustOptions { snooping: false, ..cps::batch::AdjustOptions::default() };
    let model = |source| PlanError::Model { cycle: 0, source };
    let mut adjusted: Vec<Accumulator> = if dance.control.is_empty() {
        Vec::new()
    } else {
        let planned = crate::network::planned(dance, instrument, start_covariance).map_err(model)?;
        let a = cps::batch::adjust(&planned.network, &adjust_options).map_err(model)?;
        (0..dance.stations.len())
            .map(|k| Accumulator::new(k, a.station_covariance(k)))
            .filter(|acc| acc.inverse.is_some())
            .collect()
    };
    for t in 0..trials {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(t as u64);
        let trial = execute(dance, instrument, start_covariance, &mut rng)?;
        for (acc, est) in filter.iter_mut().zip(&trial.estimates) {
            acc.add(est, &dance.station_pose(acc.station));
        }
        if !adjusted.is_empty() {
            let stations: Vec<ParentPose> =
                std::iter::once(trial.start).chain(trial.estimates.iter().copied()).collect();
            let net = crate::network::build(dance, instrument, start_covariance, &stations, &trial.readings)
                .map_err(model)?;
            let a = cps::batch::adjust(&net.network, &adjust_options).map_err(model)?;
            for acc in &mut adjusted {
                acc.add(&a.stations[acc.station], &dance.station_pose(acc.station));
            }
        }
    }
    Ok(MonteCarloResult {
        filter: filter.iter().map(|a| a.statistics(trials)).collect(),
        adjusted: adjusted.iter().map(|a| a.statistics(trials)).collect(),
    })
}

/// Two-sided 95 % interval of the mean NEES of `trials` draws of a
/// `dim`-dimensional Gaussian error: χ²_{dim·trials}(0.025, 0.975) / trials
/// (Wilson–Hilferty approximation of the χ² quantiles).
pub fn nees_interval(dim: usize, trials: usize) -> (f64, f64) {
    let k = (dim * trials) as f64;
    let z = 1.959_963_984_540_054;
    let q = |z: f64| k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3);
    (q(-z) / trials as f64, q(z) / trials as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nees_interval_brackets_the_dimension() {
        let (lo, hi) = nees_interval(4, 1000);
        assert!(lo < 4.0 && hi > 4.0);
        // χ²_4000 has sd √8000 ≈ 89.4: the 95 % interval is about ±1.96·89.4/1000.
        assert!((hi - 4.0 - 0.1753).abs() < 0.005, "{hi}");
        assert!((4.0 - lo - 0.1753).abs() < 0.005, "{lo}");
    }
}
