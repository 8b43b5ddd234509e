//! Gauss–Newton on the whole network: every group linearised and whitened
//! by its covariance's Cholesky factor into the sparse normal equations,
//! which are factorised once per iteration ([`super::sparse`]); the
//! estimate moves until every increment is below 1e-10 m and 1e-12 rad.

use nalgebra::{DMatrix, Point3};

use super::model::{Group, Layout, Linearised, Network, Unknown};
use super::sparse::{Analysis, Factor, FactorError, SymmetricBuilder};
use crate::error::{CpsError, Result};
use crate::observation::ParentPose;

/// Increments below these end the iteration (metres, radians).
pub const TOLERANCE_M: f64 = 1e-10;
/// … and radians.
pub const TOLERANCE_RAD: f64 = 1e-12;

/// The solution of one adjustment.
#[derive(Debug, Clone)]
pub struct Solution {
    /// Adjusted stations.
    pub stations: Vec<ParentPose>,
    /// Adjusted points.
    pub points: Vec<Point3<f64>>,
    /// Gauss–Newton iterations done.
    pub iterations: usize,
    /// Whether the increments fell below the tolerances.
    pub converged: bool,
    /// The factor of the last normal equations.
    pub factor: Factor,
    /// The last linearisation point (stations, points) and the step taken
    /// from it: every group's linearisation is recomputed from them when
    /// the statistics need it ([`Solution::linearised`]) rather than kept
    /// — a 100,000-cycle network's groups took 230 MB.
    last_stations: Vec<ParentPose>,
    last_points: Vec<Point3<f64>>,
    step: Vec<f64>,
}

impl Solution {
    /// `group` at the last linearisation point, with `misclosure` replaced
    /// by the residual of the linear model after the last step (observed −
    /// adjusted, first order).
    pub fn linearised(&self, network: &Network, layout: &Layout, group: &Group) -> Result<Linearised> {
        let mut lin = network.linearise(group, layout, &self.last_stations, &self.last_points)?;
        let step = nalgebra::DVector::from_iterator(lin.columns.len(), lin.columns.iter().map(|&c| self.step[c]));
        lin.misclosure -= &lin.jacobian * step;
        Ok(lin)
    }
}

/// Adjusts `network` with the observation `groups` (their active
/// scalars) in at most `max_iterations` steps, from the network's
/// approximate values.
pub fn solve(network: &Network, layout: &Layout, groups: &[Group], max_iterations: usize) -> Result<Solution> {
    let stations: Vec<ParentPose> = network.stations.iter().map(|s| s.pose).collect();
    let points: Vec<Point3<f64>> = network.points.iter().map(|p| p.position).collect();
    solve_from(network, layout, groups, max_iterations, stations, points)
}

/// [`solve`] from the given values (an earlier solution's: data snooping
/// re-adjusts from there in a step or two).
pub fn solve_from(
    network: &Network,
    layout: &Layout,
    groups: &[Group],
    max_iterations: usize,
    stations: Vec<ParentPose>,
    points: Vec<Point3<f64>>,
) -> Result<Solution> {
    solve_with(network, layout, groups, max_iterations, stations, points, &mut None)
}

/// [`solve_from`] reusing `analysis`, the ordering and factor pattern of an
/// earlier adjustment of the same network (data snooping's), and leaving
/// this one's there.
pub fn solve_with(
    network: &Network,
    layout: &Layout,
    groups: &[Group],
    max_iterations: usize,
    mut stations: Vec<ParentPose>,
    mut points: Vec<Point3<f64>>,
    analysis: &mut Option<Analysis>,
) -> Result<Solution> {
    let n = layout.len();
    let mut iterations = 0;
    let mut columns = Vec::new();
    loop {
        // One entry per (column, row ≤ column) pair of each group, and the
        // neighbouring stations' coupling, counted by column of the lower
        // triangle so that each goes straight to its place.
        let mut counts = vec![0usize; n];
        for g in groups {
            network.columns_into(g, layout, &mut columns);
            for (a, &ca) in columns.iter().enumerate() {
                for &cb in columns.iter().take(a + 1) {
                    counts[ca.min(cb)] += 1;
                }
            }
        }
        for pair in layout.stations.windows(2) {
            for a in pair[0].iter().flatten() {
                for b in pair[1].iter().flatten() {
                    counts[(*a).min(*b)] += 1;
                }
            }
        }
        let mut normal = SymmetricBuilder::with_column_counts(&counts);
        drop(counts);
        let mut rhs = vec![0.0; n];
        // Each group linearised, whitened and added, then let go.
        for g in groups {
            let lin = network.linearise(g, layout, &stations, &points)?;
            let Some(chol) = lin.covariance.clone().cholesky() else {
                return Err(CpsError::NotPositiveDefinite { what: "an observation's covariance".into() });
            };
            let l = chol.l();
            let jw = l.solve_lower_triangular(&lin.jacobian).unwrap_or_else(|| DMatrix::zeros(0, 0));
            let vw = l.solve_lower_triangular(&lin.misclosure).unwrap_or_else(|| nalgebra::DVector::zeros(0));
            if jw.nrows() != lin.jacobian.nrows() || vw.len() != lin.misclosure.len() {
                return Err(CpsError::NotPositiveDefinite { what: "an observation's covariance".into() });
            }
            for (a, &ca) in lin.columns.iter().enumerate() {
                rhs[ca] += jw.column(a).dot(&vw);
                for (b, &cb) in lin.columns.iter().enumerate().take(a + 1) {
                    normal.add(ca, cb, jw.column(a).dot(&jw.column(b)));
                }
            }
        }
        // Neighbouring stations' covariance is wanted (relative ellipses):
        // make their pairs part of the pattern.
        for pair in layout.stations.windows(2) {
            for a in pair[0].iter().flatten() {
                for b in pair[1].iter().flatten() {
                    normal.couple(*a, *b);
                }
            }
        }
        let factor = normal.factor_with(analysis).map_err(|e| undetermined(e, layout))?;
        let dx = factor.solve(&rhs);
        iterations += 1;
        let (last_stations, last_points) = (stations.clone(), points.clone());
        let (mut max_m, mut max_rad) = (0.0f64, 0.0f64);
        for (col, u) in layout.unknowns.iter().enumerate() {
            let d = dx[col];
            if !d.is_finite() {
                return Err(CpsError::Diverged { what: "batch adjustment".into(), iterations });
            }
            match *u {
                Unknown::Station { station, coordinate } => {
                    let (station, coordinate) = (station as usize, usize::from(coordinate));
                    let mut v = stations[station].to_vector();
                    v[coordinate] += d;
                    stations[station] = ParentPose::from_vector(&v);
                    if coordinate == 3 {
                        max_rad = max_rad.max(d.abs());
                    } else {
                        max_m = max_m.max(d.abs());
                    }
                }
                Unknown::Point { point, coordinate } => {
                    points[point as usize][usize::from(coordinate)] += d;
                    max_m = max_m.max(d.abs());
                }
            }
        }
        // Or the step is negligible against the estimate's own precision:
        // dxᵀ N dx (= dxᵀ rhs, the step's squared Mahalanobis length)
        // below 10⁻¹² an unknown — a millionth of a σ. Far along an open
        // traverse (σ of metres, coordinates of 10⁵ m) the steps' rounding
        // stays at 10⁻⁸ m, above the absolute tolerances, and a 100 km
        // network ran all 20 iterations "not converged" (each of data
        // snooping's re-adjustments too).
        let mahalanobis2 = dx.iter().zip(&rhs).map(|(d, r)| d * r).sum::<f64>().abs();
        let converged = (max_m < TOLERANCE_M && max_rad < TOLERANCE_RAD) || mahalanobis2 < 1e-12 * n as f64;
        if converged || iterations >= max_iterations {
            return Ok(Solution {
                stations,
                points,
                iterations,
                converged,
                factor,
                last_stations,
                last_points,
                step: dx,
            });
        }
    }
}

/// The error for a singular factorisation, naming the unknown.
fn undetermined(e: FactorError, layout: &Layout) -> CpsError {
    match e {
        // Positive but vanishing: determined, beyond double precision (issue
        // 35: a 1,000 km traverse was told "no observation determines").
        FactorError::Singular { column, pivot } if pivot > 0.0 => CpsError::NumericallySingular {
            what: layout.unknowns.get(column).map_or_else(|| format!("unknown {column}"), |u| format!("the {u}")),
            pivot,
            condition: 1.0 / pivot,
        },
        FactorError::Singular { column, .. } => CpsError::DegenerateGeometry {
            what: match layout.unknowns.get(column) {
                Some(u) => format!("no observation determines the {u}"),
                None => "the readings do not determine every unknown".into(),
            },
            condition: f64::INFINITY,
        },
        FactorError::Internal => CpsError::DegenerateGeometry {
            what: "the sparse factorisation of the normal equations failed".into(),
            condition: f64::NAN,
        },
    }
}
