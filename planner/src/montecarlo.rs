//! Monte Carlo of the real non-linear procedure: noisy readings → children
//! placed from the *estimated* parent → Gauss–Newton fix, repeated over
//! seeded trials and compared with [`crate::predict`].

use nalgebra::{Matrix4, SymmetricEigen, Vector4};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use cps::{Instrument, ParentPose, Reading, TeamState, observe, wrap_angle};

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

/// One simulated execution of the dance: the team truly stands at the
/// nominal positions, the parent's start estimate is drawn from
/// `start_covariance`, readings are noisy, and the estimates are produced by
/// the same procedure a real run uses. Returns the parent estimate after each
/// cycle.
pub fn execute(
    dance: &Dance,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
    rng: &mut impl Rng,
) -> Result<Vec<ParentPose>, PlanError> {
    let start = dance.station_pose(0);
    let start_estimate = ParentPose::from_vector(&(start.to_vector() + sample_pose_error(start_covariance, rng)));
    let mut team = TeamState::new(start_estimate, *start_covariance, dance.n_children())
        .map_err(|source| PlanError::Model { cycle: 0, source })?;
    let mut estimates = Vec::with_capacity(dance.cycles.len());
    let read = |from: &ParentPose, to: &nalgebra::Point3<f64>| noisy_reading(from, to, instrument, rng);
    run_dance(dance, &mut team, instrument, false, read, |_, team, _| estimates.push(team.parent()))?;
    Ok(estimates)
}

/// Empirical accuracy of one cycle over all trials, against the prediction.
#[derive(Debug, Clone, PartialEq)]
pub struct CycleStatistics {
    /// Cycle number, 1-based.
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

/// Runs `trials` seeded executions and returns per-cycle statistics.
/// Trial `t` uses the ChaCha8 stream seeded with `seed` and stream `t`, so
/// results do not depend on evaluation order.
pub fn monte_carlo(
    dance: &Dance,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
    trials: usize,
    seed: u64,
) -> Result<Vec<CycleStatistics>, PlanError> {
    let prediction = crate::predict(dance, instrument, start_covariance)?;
    let k = dance.cycles.len();
    let mut second = vec![Matrix4::<f64>::zeros(); k];
    let mut nees = vec![0.0; k];
    let inverses: Vec<Option<Matrix4<f64>>> =
        prediction.cycles.iter().map(|c| c.covariance.cholesky().map(|ch| ch.inverse())).collect();
    for t in 0..trials {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(t as u64);
        let estimates = execute(dance, instrument, start_covariance, &mut rng)?;
        for (i, est) in estimates.iter().enumerate() {
            let truth = dance.station_pose(dance.cycles[i].to);
            let mut e = est.to_vector() - truth.to_vector();
            e[3] = wrap_angle(e[3]);
            second[i] += e * e.transpose();
            if let Some(inv) = &inverses[i] {
                nees[i] += (e.transpose() * inv * e)[(0, 0)];
            }
        }
    }
    let n = trials.max(1) as f64;
    Ok(prediction
        .cycles
        .iter()
        .enumerate()
        .map(|(i, c)| CycleStatistics {
            cycle: c.cycle,
            predicted: c.covariance,
            empirical: second[i] / n,
            nees_mean: nees[i] / n,
        })
        .collect())
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
