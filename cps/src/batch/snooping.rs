//! Data snooping's next removals, found without re-adjusting: Baarda's
//! iteration removes the observation with the largest |w|, adjusts again
//! and tests again; here each removal is a rank-one downdate of the
//! linearised adjustment, so the sequence is found at the cost of one
//! sparse solve and one pass over the observations a removal (issue 35:
//! 10,000 stations re-adjusted 18 times, two or three factorisations and
//! the statistics of 120,000 observations each). The caller then adjusts
//! once without all of them and tests the result exactly.
//!
//! Removing scalar i from a group with covariance C leaves the group's
//! other scalars R; the group's information splits as
//! AᵀC⁻¹A = A_RᵀC_R⁻¹A_R + h hᵀ / s with the conditional observation
//! h = A_i − c_Rᵀ C_R⁻¹ A_R, s = C_ii − c_Rᵀ C_R⁻¹ c_R (c_R = C[R, i]),
//! and its misclosure v_c = v_i − c_Rᵀ C_R⁻¹ v_R. With u = h/√s and
//! t = v_c/√s the normal matrix loses u uᵀ and the right-hand side u t:
//! by Sherman–Morrison, with y = Q u (Q the current inverse) and
//! d = 1 − uᵀy (zero when the removal leaves an unknown undetermined),
//! Q' = Q + y yᵀ/d and the solution moves by y (uᵀδ − t)/d, δ its
//! departure from the adjustment. Q u is the factor's solve of u plus the
//! earlier removals' terms; every group's A Q Aᵀ and residual follow from
//! A y, and its w as in [`super::statistics`].

// Small dense algebra on fixed arrays of at most 4×7 reads best indexed.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use super::model::{Group, Layout, Network};
use super::solve::Solution;
use super::sparse::SelectedInverse;
use super::statistics::{UNCHECKED, WEAKLY_CHECKED};
use crate::error::Result;

/// A removal found: the group (index into the groups), the scalar's
/// position in it, and its w and residual (adjusted − observed) then.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Found {
    /// Index into the groups.
    pub group: usize,
    /// The scalar's position in the group.
    pub pos: usize,
    /// Its w when found.
    pub w: f64,
    /// Its residual then (adjusted − observed).
    pub residual: f64,
}

/// Below this, d = 1 − uᵀQu: the removal would leave an unknown
/// undetermined (the caller's adjustment says so exactly).
const DETERMINED: f64 = 1e-9;

/// Most scalars and columns a group has (a reading: 3 scalars, a station's
/// 4 and a point's 3 columns; a station prior: 4 and 4).
const K: usize = 4;
const M: usize = 7;

/// One group linearised at the adjustment, with its part of the current
/// state.
struct Linear {
    k: usize,
    m: usize,
    /// The group's positions of the rows.
    pos: [usize; K],
    columns: [usize; M],
    a: [[f64; M]; K],
    c: [[f64; K]; K],
    /// C⁻¹.
    p: [[f64; K]; K],
    /// A Q Aᵀ, Q the current inverse.
    aqa: [[f64; K]; K],
    /// The misclosure at the adjustment (observed − computed, after its
    /// last step).
    v: [f64; K],
    /// The residual now: v − A δ.
    r: [f64; K],
}

/// One scalar's test: (|w|, group, row, w, residual).
type Worst = Option<(f64, usize, usize, f64, f64)>;

impl Linear {
    /// The largest |w| of the rows others check, as statistics computes it.
    fn worst(&self, g: usize) -> Worst {
        let k = self.k;
        let mut qvv = [[0.0; K]; K];
        for i in 0..k {
            for j in 0..k {
                qvv[i][j] = self.c[i][j] - self.aqa[i][j];
            }
        }
        let pq = mul(&self.p, &qvv, k);
        let pqp = mul(&pq, &self.p, k);
        let mut best: Worst = None;
        for i in 0..k {
            // (Q_vv P)_ii = (P Q_vv)_ii for symmetric Q_vv and P.
            let redundancy = pq[i][i].clamp(0.0, 1.0);
            if redundancy <= UNCHECKED || pqp[i][i] <= 0.0 || redundancy < WEAKLY_CHECKED {
                continue;
            }
            let pr: f64 = (0..k).map(|j| self.p[i][j] * self.r[j]).sum();
            let w = -pr / pqp[i][i].sqrt();
            if best.is_none_or(|b| w.abs() > b.0) {
                best = Some((w.abs(), g, i, w, -self.r[i]));
            }
        }
        best
    }

    /// The conditional observation of row `i` given the others: (u, t) over
    /// the group's columns, or `None` when its conditional variance is
    /// not positive.
    fn conditional(&self, i: usize) -> Option<([f64; M], f64)> {
        let (k, m) = (self.k, self.m);
        let rest: Vec<usize> = (0..k).filter(|&j| j != i).collect();
        let (mut h, mut s, mut vc) = (self.a[i], self.c[i][i], self.v[i]);
        if !rest.is_empty() {
            let cr = nalgebra::DMatrix::from_fn(rest.len(), rest.len(), |a, b| self.c[rest[a]][rest[b]]);
            let ci = nalgebra::DVector::from_iterator(rest.len(), rest.iter().map(|&j| self.c[j][i]));
            let sol = cr.cholesky()?.solve(&ci);
            s -= ci.dot(&sol);
            for (a, &j) in rest.iter().enumerate() {
                for (col, hc) in h.iter_mut().enumerate().take(m) {
                    *hc -= sol[a] * self.a[j][col];
                }
                vc -= sol[a] * self.v[j];
            }
        }
        if s.is_nan() || s <= 0.0 {
            return None;
        }
        let root = s.sqrt();
        h.iter_mut().take(m).for_each(|x| *x /= root);
        Some((h, vc / root))
    }

    /// Drops row `i` (its scalar removed).
    fn remove(&mut self, i: usize) {
        let k = self.k;
        let keep: Vec<usize> = (0..k).filter(|&j| j != i).collect();
        let pick = |src: &[[f64; K]; K]| {
            let mut out = [[0.0; K]; K];
            for (a, &x) in keep.iter().enumerate() {
                for (b, &y) in keep.iter().enumerate() {
                    out[a][b] = src[x][y];
                }
            }
            out
        };
        self.c = pick(&self.c);
        self.aqa = pick(&self.aqa);
        let (mut a, mut v, mut r, mut pos) = ([[0.0; M]; K], [0.0; K], [0.0; K], [0; K]);
        for (row, &x) in keep.iter().enumerate() {
            a[row] = self.a[x];
            v[row] = self.v[x];
            r[row] = self.r[x];
            pos[row] = self.pos[x];
        }
        (self.a, self.v, self.r, self.pos, self.k) = (a, v, r, pos, keep.len());
        self.p = invert(&self.c, self.k).unwrap_or([[0.0; K]; K]);
    }
}

fn mul(x: &[[f64; K]; K], y: &[[f64; K]; K], k: usize) -> [[f64; K]; K] {
    let mut out = [[0.0; K]; K];
    for i in 0..k {
        for j in 0..k {
            out[i][j] = (0..k).map(|l| x[i][l] * y[l][j]).sum();
        }
    }
    out
}

fn invert(c: &[[f64; K]; K], k: usize) -> Option<[[f64; K]; K]> {
    let inv = nalgebra::DMatrix::from_fn(k, k, |i, j| c[i][j]).try_inverse()?;
    let mut out = [[0.0; K]; K];
    for i in 0..k {
        for j in 0..k {
            out[i][j] = inv[(i, j)];
        }
    }
    Some(out)
}

/// The removals iterative snooping makes from the adjustment `solution`
/// of `groups` (`inverse` its selected inverse), starting with `first`
/// (the largest |w| of its exact statistics, beyond `w_critical`): each
/// next one the largest |w| beyond `w_critical` after the ones before, by
/// rank-one downdates (module docs). Stops before a removal that would
/// leave an unknown undetermined; `first` alone when a group does not fit
/// the downdate's small fixed sizes.
pub fn removals(
    network: &Network,
    groups: &[Group],
    layout: &Layout,
    solution: &Solution,
    inverse: &SelectedInverse<'_>,
    first: Found,
    w_critical: f64,
) -> Result<Vec<Found>> {
    let mut found = vec![first];
    let linear: Result<Option<Vec<Linear>>> = groups
        .par_iter()
        .map(|group| {
            let lin = solution.linearised(network, layout, group)?;
            let (k, m) = (lin.active.len(), lin.columns.len());
            if k > K || m > M {
                return Ok(None);
            }
            let mut l = Linear {
                k,
                m,
                pos: [0; K],
                columns: [0; M],
                a: [[0.0; M]; K],
                c: [[0.0; K]; K],
                p: [[0.0; K]; K],
                aqa: [[0.0; K]; K],
                v: [0.0; K],
                r: [0.0; K],
            };
            l.columns[..m].copy_from_slice(&lin.columns);
            for i in 0..k {
                l.pos[i] = lin.active[i];
                l.v[i] = lin.misclosure[i];
                for j in 0..m {
                    l.a[i][j] = lin.jacobian[(i, j)];
                }
                for j in 0..k {
                    l.c[i][j] = lin.covariance[(i, j)];
                }
            }
            l.r = l.v;
            let Some(p) = invert(&l.c, k) else { return Ok(None) };
            l.p = p;
            let q = |a: usize, b: usize| inverse.get(l.columns[a], l.columns[b]).unwrap_or(0.0);
            let mut aq = [[0.0; M]; K];
            for i in 0..k {
                for b in 0..m {
                    aq[i][b] = (0..m).map(|a| l.a[i][a] * q(a, b)).sum();
                }
            }
            for i in 0..k {
                for j in 0..k {
                    l.aqa[i][j] = (0..m).map(|b| aq[i][b] * l.a[j][b]).sum();
                }
            }
            Ok(Some(l))
        })
        .collect::<Result<Option<Vec<_>>>>();
    let Some(mut linear) = linear? else { return Ok(found) };
    let n = layout.len();
    // The earlier removals' y = Q u and d, and δ.
    let mut earlier: Vec<(Vec<f64>, f64)> = Vec::new();
    let mut delta = vec![0.0; n];
    let l = &linear[first.group];
    let mut next = Some((first.group, l.pos[..l.k].iter().position(|&p| p == first.pos)));
    while let Some((g, Some(row))) = next {
        let Some((u, t)) = linear[g].conditional(row) else {
            // Not this one (the last found; the caller's first is tried
            // exactly, which says why).
            if found.len() > 1 {
                found.pop();
            }
            break;
        };
        let u: Vec<(usize, f64)> = (0..linear[g].m).map(|j| (linear[g].columns[j], u[j])).collect();
        let mut dense = vec![0.0; n];
        for &(col, x) in &u {
            dense[col] += x;
        }
        let mut y = solution.factor.solve(&dense);
        // Q u = Q₀ u + Σ y_i (y_iᵀ u) / d_i over the earlier removals.
        for (yi, di) in &earlier {
            let coef = u.iter().map(|&(col, x)| x * yi[col]).sum::<f64>() / di;
            y.iter_mut().zip(yi).for_each(|(a, b)| *a += b * coef);
        }
        let d = 1.0 - u.iter().map(|&(col, x)| x * y[col]).sum::<f64>();
        if d.is_nan() || d <= DETERMINED {
            // Not this one (the last found; the caller's first is tried
            // exactly, which says why).
            if found.len() > 1 {
                found.pop();
            }
            break;
        }
        let coef = (u.iter().map(|&(col, x)| x * delta[col]).sum::<f64>() - t) / d;
        delta.iter_mut().zip(&y).for_each(|(a, b)| *a += b * coef);
        let worst = linear
            .par_iter_mut()
            .enumerate()
            .map(|(h, l)| {
                let mut ay = [0.0; K];
                for (i, a) in ay.iter_mut().enumerate().take(l.k) {
                    *a = (0..l.m).map(|j| l.a[i][j] * y[l.columns[j]]).sum();
                }
                for i in 0..l.k {
                    for j in 0..l.k {
                        l.aqa[i][j] += ay[i] * ay[j] / d;
                    }
                    l.r[i] -= ay[i] * coef;
                }
                if h == g {
                    l.remove(row);
                }
                l.worst(h)
            })
            .reduce(|| None, |a: Worst, b: Worst| if b.is_some_and(|b| a.is_none_or(|a| b.0 > a.0)) { b } else { a });
        earlier.push((y, d));
        next = None;
        if let Some((abs, h, i, w, residual)) = worst
            && abs > w_critical
        {
            found.push(Found { group: h, pos: linear[h].pos[i], w, residual });
            next = Some((h, Some(i)));
        }
    }
    Ok(found)
}
