//! Where the rest of a network puts a point when its given coordinates are
//! left out — a control point's misclosure — from the one adjustment of the
//! whole network, by an update instead of an adjustment per point (issue
//! 35: 41 control points on a 2 km traverse took 2.96 s, against 0.08 s
//! with two).
//!
//! - A point held **fixed**: freeing it adds its three coordinates as
//!   unknowns. At the adjustment the rest is optimal (its gradient zero),
//!   so one Newton step of the enlarged system moves the point by
//!   Δp = S⁻¹·g, S = N_pp − N_rpᵀ·N_rr⁻¹·N_rp (its sightings' information
//!   less what the rest already explains: three solves with the factor),
//!   g = Σ J_pᵀ·W·v its sightings' pull; its covariance is S⁻¹.
//! - A point **weighted** by Σ: leaving its prior out is a rank-3 downdate,
//!   x' = x̂ + Q_pp·(Σ − Q_pp)⁻¹·(x̂_p − given), Q' = Q_pp + Q_pp·(Σ −
//!   Q_pp)⁻¹·Q_pp (Q_pp by three solves).
//! - A free point is where the adjustment put it.
//!
//! Either is exact for the linearised model at the adjustment: the
//! re-adjustment it replaces differs by the second order of the point's
//! move over its sight lines (micrometres; tested against it). A point
//! partly fixed, or whose prior data snooping partly removed, is adjusted
//! again without its prior as before. Where the rest cannot hold the
//! network without the point (a start resected on two points), S or
//! Σ − Q_pp is singular: no position (`None`).

use nalgebra::{DMatrix, Matrix3, Point3, SymmetricEigen, Vector3};

use super::model::{Layout, Network, Source};
use super::{AdjustOptions, solve};
use crate::error::Result;
use crate::observation::observe_with_jacobians;

/// A point's position and covariance from the rest of the network.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Freed {
    /// Where the rest puts it.
    pub position: Point3<f64>,
    /// Its covariance (x, y, z).
    pub covariance: Matrix3<f64>,
}

/// An eigenvalue below this fraction of the largest marks a direction the
/// rest does not determine.
const SINGULAR: f64 = 1e-9;

/// For each of `points`, where the rest of `network` (the scalars
/// `left_out` left out, as data snooping removed them) puts it without its
/// given coordinates — `None` where the rest cannot hold the network
/// without them. One adjustment and an update a point (module docs); the
/// adjustment starts from `adjusted` when given (the same network's, with
/// the same scalars left out: one step then confirms it).
pub fn freed_points(
    network: &Network,
    options: &AdjustOptions,
    left_out: &[(Source, usize)],
    points: &[usize],
    adjusted: Option<&super::Adjustment>,
) -> Result<Vec<Option<Freed>>> {
    network.validate()?;
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let layout = Layout::new(network);
    let groups = network.groups_without(left_out);
    let solution = match adjusted {
        Some(a) if a.stations.len() == network.stations.len() && a.points.len() == network.points.len() => {
            solve::solve_from(network, &layout, &groups, options.max_iterations, a.stations.clone(), a.points.clone())?
        }
        _ => solve::solve(network, &layout, &groups, options.max_iterations)?,
    };
    let n = layout.len();
    // The columns of N⁻¹ for the given right-hand sides (three solves).
    let solve3 = |columns: [Vec<f64>; 3]| columns.map(|b| solution.factor.solve(&b));
    // The 3 × 3 block of N⁻¹ at columns `c`.
    let q_block = |c: [usize; 3]| {
        let q = solve3(c.map(|k| {
            let mut e = vec![0.0; n];
            e[k] = 1.0;
            e
        }));
        Matrix3::from_fn(|i, j| q[j][c[i]])
    };
    let mut out = Vec::with_capacity(points.len());
    for &p in points {
        let point = &network.points[p];
        let prior_group = groups.iter().find(|g| g.source == Source::PointPrior(p));
        let cols = layout.points[p];
        let freed = match (point.prior, all(&cols)) {
            (None, Some(c)) => Some(Freed { position: solution.points[p], covariance: q_block(c) }),
            (None, None) => return Err(undetermined_point(p)),
            (Some(_), _) if cols.iter().all(Option::is_none) => {
                // Fixed: its sightings against the rest.
                let given = point.position;
                let mut n_pp = Matrix3::zeros();
                let mut g = Vector3::zeros();
                let mut n_rp = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
                for group in &groups {
                    let Source::Reading(k) = group.source else { continue };
                    let nr = &network.readings[k];
                    if nr.point != p {
                        continue;
                    }
                    let active: Vec<usize> = group.active_positions().collect();
                    if active.is_empty() {
                        continue;
                    }
                    let (computed, jac) = observe_with_jacobians(&solution.stations[nr.station], &given)?;
                    let full = nr.reading.minus(&computed);
                    let m = active.len();
                    let rows: Vec<usize> = active.iter().map(|&a| group.component(a)).collect();
                    let cov = DMatrix::from_fn(m, m, |i, j| group.covariance(network, active[i], active[j]));
                    let Some(w) = cov.try_inverse() else { continue };
                    let v = nalgebra::DVector::from_iterator(m, rows.iter().map(|&r| full[r]));
                    let jp = DMatrix::from_fn(m, 3, |i, c| jac.wrt_child[(rows[i], c)]);
                    let js = DMatrix::from_fn(m, 4, |i, c| jac.wrt_parent[(rows[i], c)]);
                    let wjp = &w * &jp;
                    let add = jp.transpose() * &wjp;
                    n_pp += Matrix3::from_fn(|i, j| add[(i, j)]);
                    let pull = jp.transpose() * (&w * &v);
                    g += Vector3::new(pull[0], pull[1], pull[2]);
                    let coupling = js.transpose() * &wjp;
                    for (c, col) in layout.stations[nr.station].iter().enumerate() {
                        if let Some(col) = col {
                            for (k3, column) in n_rp.iter_mut().enumerate() {
                                column[*col] += coupling[(c, k3)];
                            }
                        }
                    }
                }
                let x = solve3(n_rp.clone());
                let s =
                    Matrix3::from_fn(|i, j| n_pp[(i, j)] - n_rp[i].iter().zip(&x[j]).map(|(a, b)| a * b).sum::<f64>());
                let s = 0.5 * (s + s.transpose());
                let scale = SymmetricEigen::new(n_pp).eigenvalues.max();
                match s.try_inverse() {
                    Some(inv) if SymmetricEigen::new(s).eigenvalues.min() > SINGULAR * scale => {
                        Some(Freed { position: given + inv * g, covariance: inv })
                    }
                    _ => None,
                }
            }
            (Some(prior), Some(c)) if prior_group.is_some_and(|g| g.active_positions().count() == g.len()) => {
                // Weighted: the rank-3 downdate.
                let q_pp = q_block(c);
                let q_pp = 0.5 * (q_pp + q_pp.transpose());
                let m = prior - q_pp;
                let m = 0.5 * (m + m.transpose());
                let scale = SymmetricEigen::new(prior).eigenvalues.max();
                match m.try_inverse() {
                    Some(inv) if SymmetricEigen::new(m).eigenvalues.min() > SINGULAR * scale => {
                        let x = solution.points[p];
                        Some(Freed {
                            position: x + q_pp * inv * (x - point.position),
                            covariance: q_pp + q_pp * inv * q_pp,
                        })
                    }
                    _ => None,
                }
            }
            (Some(_), _) => readjusted(network, options, left_out, p),
        };
        out.push(freed);
    }
    Ok(out)
}

/// The point's position and covariance from the network adjusted again
/// without its prior (the general case); `None` when that fails.
fn readjusted(network: &Network, options: &AdjustOptions, left_out: &[(Source, usize)], p: usize) -> Option<Freed> {
    let mut without = network.clone();
    without.points[p].prior = None;
    let options = AdjustOptions { snooping: false, ..*options };
    let a = super::adjust_without(&without, &options, left_out).ok()?;
    Some(Freed { position: a.points[p], covariance: a.point_covariance(p) })
}

/// The three columns when every coordinate is an unknown.
fn all(cols: &[Option<usize>; 3]) -> Option<[usize; 3]> {
    Some([cols[0]?, cols[1]?, cols[2]?])
}

/// A free point without columns cannot happen in a validated network.
fn undetermined_point(p: usize) -> crate::CpsError {
    crate::CpsError::DegenerateGeometry { what: format!("point {p} has no unknowns"), condition: f64::INFINITY }
}
