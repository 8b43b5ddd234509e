//! The statistics of an adjusted network as geodetic practice has them
//! (Baarda; Teunissen, *Testing theory*): per observation the residual, the
//! redundancy number, the w-statistic generalised for correlated
//! observations, the minimal detectable bias and its effect; vᵀPv for the
//! global test.
//!
//! With C the covariance of a group of observations (one reading's r, φ,
//! ψ; a prior's coordinates), P = C⁻¹, A its Jacobian and Q the unknowns'
//! covariance over A's columns: Q_vv = C − A Q Aᵀ, r_i = (Q_vv P)_ii
//! (summing to the redundancy over all observations), w_i =
//! (P v)_i / √(P Q_vv P)_ii, MDB_i = √(λ0 / (P Q_vv P)_ii) — for
//! uncorrelated observations w_i = v_i / (σ_i √r_i) and MDB_i =
//! σ_i √(λ0 / r_i) — and the bias-to-noise ratio √(λ0 (1 − r_i) / r_i), the
//! largest effect an undetected bias of MDB_i has on any function of the
//! unknowns, in units of that function's σ.

use nalgebra::{DMatrix, DVector};

use super::model::{Group, Layout, Network, Source};
use super::solve::Solution;
use super::sparse::SelectedInverse;
use crate::error::Result;

/// Below this redundancy number nothing checks an observation: its w and
/// MDB are not defined (a blunder there leaves no trace).
pub const UNCHECKED: f64 = 1e-9;

/// Below this redundancy number an observation is checked by (almost)
/// nothing: reported as such, its w shown but never acted on — data
/// snooping does not remove it, for the network would lose what only it
/// determines, and its MDB is too large to mean anything.
pub const WEAKLY_CHECKED: f64 = 0.01;

/// One scalar observation's statistics.
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarStats {
    /// Which group.
    pub source: Source,
    /// Which scalar of it (0 r / x, 1 φ / y, 2 ψ / z, 3 θ).
    pub component: usize,
    /// Its a-priori standard deviation (m or rad).
    pub sigma: f64,
    /// Adjusted minus observed (m or rad).
    pub residual: f64,
    /// Redundancy number in [0, 1].
    pub redundancy: f64,
    /// Baarda's w (standard normal without a blunder); `None` unchecked.
    pub w: Option<f64>,
    /// Minimal detectable bias (m or rad); `None` unchecked.
    pub mdb: Option<f64>,
    /// Bias-to-noise ratio; `None` unchecked.
    pub bnr: Option<f64>,
    /// How far an error of MDB in it moves its station horizontally, metres
    /// (readings).
    pub station_shift_m: Option<f64>,
}

/// The statistics of every active scalar and vᵀPv, with `lambda0` the
/// non-centrality of the tests; each group linearised again at the
/// solution's last point as it is needed.
pub fn statistics(
    network: &Network,
    groups: &[Group],
    layout: &Layout,
    station_of: &dyn Fn(&Source) -> Option<usize>,
    solution: &Solution,
    inverse: &SelectedInverse<'_>,
    lambda0: f64,
) -> Result<(Vec<ScalarStats>, f64)> {
    let mut out = Vec::new();
    let mut vtpv = 0.0;
    for group in groups {
        let lin = solution.linearised(network, layout, group)?;
        let k = lin.active.len();
        if k == 0 {
            continue;
        }
        let c = &lin.covariance;
        let Some(p) = c.clone().try_inverse() else { continue };
        let m = lin.columns.len();
        let q = DMatrix::from_fn(m, m, |a, b| inverse.get(lin.columns[a], lin.columns[b]).unwrap_or(0.0));
        let a = &lin.jacobian;
        let qvv = c - a * &q * a.transpose();
        let qvv_p = &qvv * &p;
        let pqp = &p * &qvv * &p;
        // v = observed − adjusted (first order); the report's residual is
        // adjusted − observed.
        let v = &lin.misclosure;
        let pv: DVector<f64> = &p * v;
        vtpv += v.dot(&pv);
        // The station the group was observed from, and its columns.
        let station_cols: Vec<(usize, usize)> = station_of(&group.source)
            .map(|s| {
                layout.stations[s]
                    .iter()
                    .enumerate()
                    .filter_map(|(coordinate, col)| col.map(|col| (coordinate, col)))
                    .collect()
            })
            .unwrap_or_default();
        for (i, &pos) in lin.active.iter().enumerate() {
            let r = qvv_p[(i, i)].clamp(0.0, 1.0);
            let checked = r > UNCHECKED && pqp[(i, i)] > 0.0;
            let mdb = checked.then(|| (lambda0 / pqp[(i, i)]).sqrt());
            let shift = mdb.filter(|_| !station_cols.is_empty()).map(|mdb| {
                // Δx = Q Aᵀ P e_i · MDB over the group's columns.
                let g: DVector<f64> = a.transpose() * p.column(i) * mdb;
                let mut d = [0.0; 2];
                for &(coordinate, col) in &station_cols {
                    if coordinate < 2 {
                        d[coordinate] = (0..m).map(|b| inverse.get(col, lin.columns[b]).unwrap_or(0.0) * g[b]).sum();
                    }
                }
                d[0].hypot(d[1])
            });
            out.push(ScalarStats {
                source: group.source,
                component: group.component(pos),
                sigma: group.covariance(network, pos, pos).sqrt(),
                residual: -v[i],
                redundancy: r,
                // w takes the sign of the residual as reported.
                w: checked.then(|| -pv[i] / pqp[(i, i)].sqrt()),
                mdb,
                bnr: checked.then(|| (lambda0 * (1.0 - r).max(0.0) / r).sqrt()),
                station_shift_m: shift,
            });
        }
    }
    Ok((out, vtpv))
}

/// The covariance between two unknowns' coordinate sets (rows `a`, columns
/// `b`; `None` columns — fixed coordinates — give zeros), from the
/// selected inverse.
pub fn block<const R: usize, const C: usize>(
    inverse: &SelectedInverse<'_>,
    a: &[Option<usize>; R],
    b: &[Option<usize>; C],
) -> nalgebra::SMatrix<f64, R, C> {
    nalgebra::SMatrix::from_fn(|i, j| match (a[i], b[j]) {
        (Some(x), Some(y)) => inverse.get(x, y).unwrap_or(0.0),
        _ => 0.0,
    })
}
