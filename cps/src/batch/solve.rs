//! Gauss–Newton on the whole network: every group linearised and whitened
//! by its covariance's Cholesky factor into the sparse normal equations,
//! which are factorised once per iteration ([`super::sparse`]); the
//! estimate moves until every increment is below 1e-10 m and 1e-12 rad.

use nalgebra::{DMatrix, Point3};

use super::model::{Group, Layout, Linearised, Network, Unknown};
use super::sparse::{Factor, FactorError, SymmetricBuilder};
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
    /// Every group at the last linearisation point, with `misclosure`
    /// replaced by the residual of the linear model after the last step
    /// (observed − adjusted, first order).
    pub linearised: Vec<Linearised>,
    /// The factor of the last normal equations.
    pub factor: Factor,
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
    mut stations: Vec<ParentPose>,
    mut points: Vec<Point3<f64>>,
) -> Result<Solution> {
    let n = layout.len();
    let mut iterations = 0;
    loop {
        let linearised: Vec<Linearised> =
            groups.iter().map(|g| network.linearise(g, layout, &stations, &points)).collect::<Result<_>>()?;
        // One entry per (column, row ≤ column) pair of each group, and the
        // neighbouring stations' coupling.
        let entries: usize = linearised.iter().map(|l| l.columns.len() * (l.columns.len() + 1) / 2).sum::<usize>()
            + 16 * layout.stations.len();
        let mut normal = SymmetricBuilder::with_capacity(n, entries);
        let mut rhs = vec![0.0; n];
        for lin in &linearised {
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
        let factor = normal.factor().map_err(|e| undetermined(e, layout))?;
        let dx = factor.solve(&rhs);
        iterations += 1;
        let (mut max_m, mut max_rad) = (0.0f64, 0.0f64);
        for (col, u) in layout.unknowns.iter().enumerate() {
            let d = dx[col];
            if !d.is_finite() {
                return Err(CpsError::Diverged { what: "batch adjustment".into(), iterations });
            }
            match *u {
                Unknown::Station { station, coordinate } => {
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
                    points[point][coordinate] += d;
                    max_m = max_m.max(d.abs());
                }
            }
        }
        let converged = max_m < TOLERANCE_M && max_rad < TOLERANCE_RAD;
        if converged || iterations >= max_iterations {
            let linearised = linearised
                .into_iter()
                .map(|mut lin| {
                    let step = nalgebra::DVector::from_iterator(lin.columns.len(), lin.columns.iter().map(|&c| dx[c]));
                    lin.misclosure -= &lin.jacobian * step;
                    lin
                })
                .collect();
            return Ok(Solution { stations, points, iterations, converged, linearised, factor });
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
