//! The rigorous least-squares adjustment of a whole CPS network: every
//! station (x, y, z, θ), every child placement and every control point
//! (free, weighted or held fixed, coordinate by coordinate) from every
//! reading with its covariance — and the statistics a surveyor signs off
//! with: σ0², the global test, redundancy numbers, Baarda's w, iterative
//! data snooping, minimal detectable biases and their effects.
//!
//! - [`model`]: the [`Network`] and its unknowns' layout;
//! - [`solve`]: Gauss–Newton on the sparse normal equations;
//! - [`sparse`]: the sparse Cholesky factor (faer, AMD order) and the
//!   selected inverse (Takahashi) that gives every covariance needed in
//!   memory linear in the network;
//! - [`statistics`]: the per-observation statistics.
//!
//! For the chain-shaped dance, an open traverse, the covariance of every
//! station equals the sequential filter's ([`crate::TeamState`]); control
//! points sighted along the route tie it back and improve every station.
//! Covariances and w use the a-priori variance factor (σ0 = 1): they are
//! not scaled by the a-posteriori σ0².

pub mod freed;
pub mod model;
pub mod snooping;
pub mod solve;
pub mod sparse;
pub mod statistics;

use nalgebra::{Matrix3, Matrix4, Point3};

pub use model::{Layout, Network, NetworkReading, Point, Source, Station, Unknown};
pub use statistics::ScalarStats;

use crate::error::{CpsError, Result};
use crate::observation::ParentPose;
use crate::stats::{chi2_quantile, noncentrality, normal_quantile};

/// How to adjust and test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdjustOptions {
    /// Gauss–Newton iteration cap (default 20).
    pub max_iterations: usize,
    /// Significance level of the global test, two-sided (default 0.05).
    pub alpha: f64,
    /// Significance level of one w-test (default 0.001).
    pub alpha0: f64,
    /// Power of one w-test against a bias of the MDB (default 0.80).
    pub beta0: f64,
    /// Iterative data snooping: remove the observation with the largest
    /// |w| above the critical value, adjust again, repeat (default true).
    pub snooping: bool,
}

impl Default for AdjustOptions {
    fn default() -> Self {
        Self {
            max_iterations: 20,
            alpha: 0.05,
            alpha0: crate::stats::ALPHA0,
            beta0: crate::stats::BETA0,
            snooping: true,
        }
    }
}

/// The global model test: vᵀPv against χ² with the redundancy as degrees
/// of freedom, two-sided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlobalTest {
    /// vᵀPv.
    pub statistic: f64,
    /// Degrees of freedom (the redundancy).
    pub dof: usize,
    /// Its significance level.
    pub alpha: f64,
    /// The α/2 quantile of χ²_dof (`None` without redundancy).
    pub lower: Option<f64>,
    /// The 1 − α/2 quantile.
    pub upper: Option<f64>,
    /// lower ≤ statistic ≤ upper (true without redundancy: nothing to test).
    pub passed: bool,
}

/// An observation data snooping removed, in the order removed.
#[derive(Debug, Clone, PartialEq)]
pub struct Removal {
    /// Which group.
    pub source: Source,
    /// Which scalar of it.
    pub component: usize,
    /// Its w when it was removed.
    pub w: f64,
    /// Its residual then (adjusted − observed).
    pub residual: f64,
}

/// The adjusted network.
#[derive(Debug, Clone)]
pub struct Adjustment {
    /// Adjusted stations.
    pub stations: Vec<ParentPose>,
    /// Adjusted points.
    pub points: Vec<Point3<f64>>,
    station_covariances: Vec<Matrix4<f64>>,
    point_covariances: Vec<Matrix3<f64>>,
    neighbour_covariances: Vec<Matrix4<f64>>,
    /// Gauss–Newton iterations of the final adjustment.
    pub iterations: usize,
    /// Whether it converged.
    pub converged: bool,
    /// Unknowns.
    pub unknowns: usize,
    /// Observations in the adjustment minus unknowns.
    pub redundancy: usize,
    /// vᵀPv / redundancy (0 without redundancy), after snooping's removals.
    pub sigma0_squared: f64,
    /// The global test of every observation, before data snooping removes
    /// any (the detection step of Teunissen's DIA procedure).
    pub global_test: GlobalTest,
    /// The same test of the adjustment after snooping's removals (none
    /// when nothing was removed). Removing the largest residuals biases it
    /// low: only its upper bound means something.
    pub after_snooping: Option<GlobalTest>,
    /// Every scalar observation still in the adjustment.
    pub observations: Vec<ScalarStats>,
    /// What data snooping removed, in order.
    pub removed: Vec<Removal>,
    /// Snooping stopped because removing the next observation would leave
    /// an unknown undetermined: that observation and why.
    pub snooping_stopped: Option<String>,
    /// The w-tests' critical value.
    pub w_critical: f64,
    /// Entries of the normal equations' Cholesky factor (its fill).
    pub factor_nnz: usize,
}

impl Adjustment {
    /// Whether the model holds: the global test passes, or it fails and
    /// data snooping found the cause — what is left passes the test's
    /// upper bound.
    pub fn model_accepted(&self) -> bool {
        match &self.after_snooping {
            None => self.global_test.passed,
            Some(after) => after.upper.is_none_or(|hi| after.statistic <= hi),
        }
    }

    /// Covariance of station `k` (x, y, z, θ); zero rows for fixed coordinates.
    pub fn station_covariance(&self, k: usize) -> Matrix4<f64> {
        self.station_covariances.get(k).copied().unwrap_or_else(Matrix4::zeros)
    }

    /// Covariance of point `p` (x, y, z).
    pub fn point_covariance(&self, p: usize) -> Matrix3<f64> {
        self.point_covariances.get(p).copied().unwrap_or_else(Matrix3::zeros)
    }

    /// cov(station k, station k + 1).
    pub fn neighbour_covariance(&self, k: usize) -> Matrix4<f64> {
        self.neighbour_covariances.get(k).copied().unwrap_or_else(Matrix4::zeros)
    }

    /// Covariance of station k + 1 relative to station k (their difference).
    pub fn relative_covariance(&self, k: usize) -> Matrix4<f64> {
        let c = self.neighbour_covariance(k);
        self.station_covariance(k) + self.station_covariance(k + 1) - c - c.transpose()
    }
}

/// The station a group was observed from.
fn station_of(network: &Network) -> impl Fn(&Source) -> Option<usize> + '_ {
    |s| match s {
        Source::Reading(k) => network.readings.get(*k).map(|r| r.station),
        _ => None,
    }
}

/// Adjusts `network`: Gauss–Newton to convergence, the statistics, and with
/// `options.snooping` iterative data snooping. An unknown no observation
/// determines is an error that names it.
pub fn adjust(network: &Network, options: &AdjustOptions) -> Result<Adjustment> {
    adjust_without(network, options, &[])
}

/// [`adjust`] with the scalar observations `left_out` (source, component)
/// left out from the start — e.g. those another adjustment's data snooping
/// removed; one that is not in the network is ignored.
pub fn adjust_without(network: &Network, options: &AdjustOptions, left_out: &[(Source, usize)]) -> Result<Adjustment> {
    network.validate()?;
    for (what, v, lo, hi) in [
        ("alpha", options.alpha, 0.0, 1.0),
        ("alpha0", options.alpha0, 0.0, 1.0),
        ("power beta0", options.beta0, 0.0, 1.0),
    ] {
        if !(v > lo && v < hi) {
            return Err(CpsError::OutOfRange {
                what: what.into(),
                value: v,
                expected: "strictly between 0 and 1".into(),
            });
        }
    }
    let layout = Layout::new(network);
    let mut groups = network.groups_without(left_out);
    let lambda0 = noncentrality(options.alpha0, options.beta0);
    let w_critical = normal_quantile(1.0 - options.alpha0 / 2.0);
    let station_of = station_of(network);
    let mut removed: Vec<Removal> = Vec::new();
    let mut snooping_stopped = None;
    let test = |vtpv: f64, redundancy: usize| {
        let (lower, upper) = if redundancy > 0 {
            let dof = redundancy as f64;
            (Some(chi2_quantile(options.alpha / 2.0, dof)), Some(chi2_quantile(1.0 - options.alpha / 2.0, dof)))
        } else {
            (None, None)
        };
        let passed = match (lower, upper) {
            (Some(lo), Some(hi)) => (lo..=hi).contains(&vtpv),
            _ => true,
        };
        GlobalTest { statistic: vtpv, dof: redundancy, alpha: options.alpha, lower, upper, passed }
    };
    let mut detection = None;
    let scalars: usize = groups.iter().map(|g| g.active_positions().count()).sum();
    if scalars < layout.len() {
        return Err(CpsError::DegenerateGeometry {
            what: format!("{scalars} observations for {} unknowns", layout.len()),
            condition: f64::INFINITY,
        });
    }
    // The ordering and factor pattern, shared by every re-adjustment.
    let mut analysis = None;
    let mut solution = solve::solve_with(
        network,
        &layout,
        &groups,
        options.max_iterations,
        network.stations.iter().map(|s| s.pose).collect(),
        network.points.iter().map(|p| p.position).collect(),
        &mut analysis,
    )?;
    loop {
        let scalars: usize = groups.iter().map(|g| g.active_positions().count()).sum();
        let inverse = solution.factor.selected_inverse();
        let (observations, vtpv) =
            statistics::statistics(network, &groups, &layout, &station_of, &solution, &inverse, lambda0)?;
        let redundancy = scalars - layout.len();
        // The model test of every observation, before snooping removes any.
        let detection = *detection.get_or_insert_with(|| test(vtpv, redundancy));
        // Snooping acts only on observations others check.
        let worst = observations
            .iter()
            .filter(|o| o.redundancy >= statistics::WEAKLY_CHECKED)
            .filter_map(|o| o.w.map(|w| (o, w)))
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()));
        if options.snooping
            && redundancy > 1
            && snooping_stopped.is_none()
            && let Some((o, w)) = worst.filter(|(_, w)| w.abs() > w_critical)
        {
            let g = groups.iter().position(|g| g.source == o.source).unwrap_or(0);
            let pos = groups[g].position(o.component).unwrap_or(0);
            // The removals snooping would make one by one, found by
            // downdates of this adjustment; then one adjustment without
            // them all, tested exactly on the next pass (the one-by-one
            // re-adjustments of a 10,000-station network took 3 s).
            let first = snooping::Found { group: g, pos, w, residual: o.residual };
            let mut batch = snooping::removals(network, &groups, &layout, &solution, &inverse, first, w_critical)?;
            // One by one, snooping removes while the redundancy exceeds 1.
            batch.truncate(redundancy - 1);
            let mut tried = None;
            let mut accepted = None;
            for batch in [&batch[..], &batch[..1]] {
                if tried == Some(batch.len()) {
                    continue;
                }
                tried = Some(batch.len());
                let mut trial = groups.clone();
                for f in batch {
                    trial[f.group].set_active(f.pos, false);
                }
                // Removing them must leave every unknown determined; the
                // adjustment without them starts from the one with them.
                let (stations, points) = (solution.stations.clone(), solution.points.clone());
                match solve::solve_with(
                    network,
                    &layout,
                    &trial,
                    options.max_iterations,
                    stations,
                    points,
                    &mut analysis,
                ) {
                    Ok(next) => {
                        let gone: Vec<Removal> = batch
                            .iter()
                            .map(|f| Removal {
                                source: groups[f.group].source,
                                component: groups[f.group].component(f.pos),
                                w: f.w,
                                residual: f.residual,
                            })
                            .collect();
                        accepted = Some((trial, next, gone));
                        break;
                    }
                    Err(CpsError::DegenerateGeometry { .. } | CpsError::NumericallySingular { .. }) => {}
                    Err(e) => return Err(e),
                }
            }
            if let Some((trial, next, gone)) = accepted {
                drop(inverse);
                removed.extend(gone);
                groups = trial;
                solution = next;
                continue;
            }
            snooping_stopped = Some(format!(
                "{:?} component {} has |w| = {:.2} but removing it leaves an unknown undetermined",
                o.source,
                o.component,
                w.abs()
            ));
        }
        let station_covariances = layout.stations.iter().map(|s| statistics::block::<4, 4>(&inverse, s, s)).collect();
        let point_covariances = layout.points.iter().map(|p| statistics::block::<3, 3>(&inverse, p, p)).collect();
        let neighbour_covariances =
            layout.stations.windows(2).map(|w| statistics::block::<4, 4>(&inverse, &w[0], &w[1])).collect();
        let factor_nnz = solution.factor.nnz();
        drop(inverse);
        return Ok(Adjustment {
            stations: solution.stations,
            points: solution.points,
            station_covariances,
            point_covariances,
            neighbour_covariances,
            iterations: solution.iterations,
            converged: solution.converged,
            unknowns: layout.len(),
            redundancy,
            sigma0_squared: if redundancy > 0 { vtpv / redundancy as f64 } else { 0.0 },
            global_test: detection,
            after_snooping: (!removed.is_empty()).then(|| test(vtpv, redundancy)),
            observations,
            removed,
            snooping_stopped,
            w_critical,
            factor_nnz,
        });
    }
}
