//! A sparse symmetric positive definite matrix — the normal equations of a
//! network — factorised by faer's simplicial Cholesky after its approximate
//! minimum degree ordering, solved, and partly inverted: Takahashi's
//! recurrences give every entry of the inverse on the factor's pattern
//! (which holds every pair of unknowns coupled in the matrix) in
//! Σ_j |col_j|² operations, so covariances of stations, points and the
//! pairs observed together cost no dense inverse and memory stays linear in
//! the network.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholeskyRaw, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Par, Side};

/// The lower triangle of a symmetric matrix, as summed entries.
#[derive(Debug, Clone)]
pub struct SymmetricBuilder {
    n: usize,
    /// (column, row, value) with row ≥ column: 16 bytes an entry (a
    /// 100,000-cycle route adds some 17 million).
    entries: Vec<(u32, u32, f64)>,
}

/// Why a factorisation failed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FactorError {
    /// The matrix is not positive definite: unknown `column` (original
    /// order) is not determined by the others (its pivot is `pivot`
    /// relative to its diagonal).
    Singular {
        /// The unknown, in the caller's order.
        column: usize,
        /// Its pivot relative to its diagonal entry (≤ the tolerance).
        pivot: f64,
    },
    /// faer could not allocate or order the matrix.
    Internal,
}

/// Pivots below this fraction of their diagonal entry (a loss of all but
/// about 5 digits) mark an unknown the matrix does not determine.
pub const PIVOT_TOLERANCE: f64 = 1e-11;

impl SymmetricBuilder {
    /// An n × n matrix of zeros.
    pub fn new(n: usize) -> Self {
        Self::with_capacity(n, 0)
    }

    /// An n × n matrix of zeros with room for `entries` additions.
    pub fn with_capacity(n: usize, entries: usize) -> Self {
        Self { n, entries: Vec::with_capacity(entries) }
    }

    /// Adds `v` at (i, j) and (j, i).
    pub fn add(&mut self, i: usize, j: usize, v: f64) {
        let (r, c) = if i >= j { (i, j) } else { (j, i) };
        debug_assert!(r < self.n && self.n <= u32::MAX as usize);
        self.entries.push((c as u32, r as u32, v));
    }

    /// Makes (i, j) part of the pattern (a structural zero), so that the
    /// inverse's entry there is computed.
    pub fn couple(&mut self, i: usize, j: usize) {
        self.add(i, j, 0.0);
    }

    /// Factorises the matrix: AMD ordering, simplicial LLᵀ.
    pub fn factor(mut self) -> Result<Factor, FactorError> {
        let n = self.n;
        // Bucketed by column (a counting sort), then each column's few
        // entries by row: linear in the entries where a comparison sort of
        // all of them took a tenth of a 10,000-cycle prediction.
        let mut start = vec![0usize; n + 1];
        for &(c, _, _) in &self.entries {
            start[c as usize + 1] += 1;
        }
        for c in 0..n {
            start[c + 1] += start[c];
        }
        let mut bucketed: Vec<(u32, f64)> = vec![(0, 0.0); self.entries.len()];
        let mut next = start.clone();
        for &(c, r, v) in &self.entries {
            bucketed[next[c as usize]] = (r, v);
            next[c as usize] += 1;
        }
        drop(std::mem::take(&mut self.entries));
        let mut col_ptr = vec![0usize; n + 1];
        let mut row_idx: Vec<usize> = Vec::with_capacity(bucketed.len());
        let mut values: Vec<f64> = Vec::with_capacity(bucketed.len());
        for c in 0..n {
            let column = &mut bucketed[start[c]..start[c + 1]];
            column.sort_unstable_by_key(|&(r, _)| r);
            let mut last = None;
            for &(r, v) in column.iter() {
                if last == Some(r) {
                    if let Some(x) = values.last_mut() {
                        *x += v;
                    }
                    continue;
                }
                last = Some(r);
                row_idx.push(r as usize);
                values.push(v);
                col_ptr[c + 1] += 1;
            }
        }
        drop(bucketed);
        for c in 0..n {
            col_ptr[c + 1] += col_ptr[c];
        }
        let diagonal: Vec<f64> = (0..n)
            .map(|c| {
                let range = col_ptr[c]..col_ptr[c + 1];
                range.clone().find(|&k| row_idx[k] == c).map_or(0.0, |k| values[k])
            })
            .collect();
        let symbolic_a = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SIMPLICIAL,
            ..Default::default()
        };
        let symbolic = factorize_symbolic_cholesky(symbolic_a, Side::Lower, SymmetricOrdering::Amd, params)
            .map_err(|_| FactorError::Internal)?;
        let SymbolicCholeskyRaw::Simplicial(simplicial) = symbolic.raw() else {
            return Err(FactorError::Internal);
        };
        let (perm_fwd, perm_inv) = match symbolic.perm() {
            Some(p) => {
                let (fwd, inv) = p.arrays();
                (fwd.to_vec(), inv.to_vec())
            }
            None => ((0..n).collect(), (0..n).collect()),
        };
        let mut l_values = vec![0.0f64; symbolic.len_val()];
        let a = SparseColMatRef::new(symbolic_a, &values);
        let scratch = symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
        let mut buffer = MemBuffer::try_new(scratch).map_err(|_| FactorError::Internal)?;
        let result = symbolic.factorize_numeric_llt(
            &mut l_values,
            a,
            Side::Lower,
            Default::default(),
            Par::Seq,
            MemStack::new(&mut buffer),
            Default::default(),
        );
        let l_col_ptr = simplicial.col_ptr().to_vec();
        let l_row_idx = simplicial.row_idx().to_vec();
        if let Err(e) = result {
            // The permuted column that failed, back to the caller's order.
            // faer counts the failed pivot from 1.
            let faer::linalg::solvers::LltError::NonPositivePivot { index } = e;
            let column = perm_fwd.get(index.saturating_sub(1)).copied().unwrap_or(0);
            return Err(FactorError::Singular { column, pivot: 0.0 });
        }
        let factor = Factor { n, perm_fwd, perm_inv, col_ptr: l_col_ptr, row_idx: l_row_idx, values: l_values };
        // A positive but vanishing pivot: the unknown is as good as undetermined.
        for j in 0..n {
            let original = factor.perm_fwd[j];
            let d = diagonal[original];
            let pivot = factor.values[factor.col_ptr[j]].powi(2);
            if d.is_nan() || d <= 0.0 || pivot < PIVOT_TOLERANCE * d {
                return Err(FactorError::Singular { column: original, pivot: if d > 0.0 { pivot / d } else { 0.0 } });
            }
        }
        Ok(factor)
    }
}

/// The Cholesky factor L of P A Pᵀ (simplicial, columns sorted, the
/// diagonal first in each), with the permutation.
#[derive(Debug, Clone)]
pub struct Factor {
    n: usize,
    /// Permuted position → original index.
    perm_fwd: Vec<usize>,
    /// Original index → permuted position.
    perm_inv: Vec<usize>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    values: Vec<f64>,
}

impl Factor {
    /// The dimension.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Entries of L (its fill).
    pub fn nnz(&self) -> usize {
        self.values.len()
    }

    /// Solves A x = b (both in the original order).
    pub fn solve(&self, b: &[f64]) -> Vec<f64> {
        let mut x: Vec<f64> = (0..self.n).map(|j| b[self.perm_fwd[j]]).collect();
        // L y = P b.
        for j in 0..self.n {
            let (start, end) = (self.col_ptr[j], self.col_ptr[j + 1]);
            x[j] /= self.values[start];
            let xj = x[j];
            for k in start + 1..end {
                x[self.row_idx[k]] -= self.values[k] * xj;
            }
        }
        // Lᵀ z = y.
        for j in (0..self.n).rev() {
            let (start, end) = (self.col_ptr[j], self.col_ptr[j + 1]);
            let mut s = x[j];
            for k in start + 1..end {
                s -= self.values[k] * x[self.row_idx[k]];
            }
            x[j] = s / self.values[start];
        }
        let mut out = vec![0.0; self.n];
        for (j, v) in x.into_iter().enumerate() {
            out[self.perm_fwd[j]] = v;
        }
        out
    }

    /// Position of L's entry (row, col) in `values`, if in the pattern.
    fn find(&self, row: usize, col: usize) -> Option<usize> {
        let (start, end) = (self.col_ptr[col], self.col_ptr[col + 1]);
        self.row_idx[start..end].binary_search(&row).ok().map(|k| start + k)
    }

    /// Every entry of A⁻¹ on L's pattern (Takahashi, Erisman and Tinney):
    /// from the last column to the first, with S_j the rows below the
    /// diagonal of column j,
    /// Z_ij = −(1/L_jj) Σ_{k∈S_j} L_kj Z_ik for i ∈ S_j and
    /// Z_jj = 1/L_jj² − (1/L_jj) Σ_{k∈S_j} L_kj Z_kj. S_j is a clique of
    /// the filled graph, so every Z_ik needed lies on the pattern.
    pub fn selected_inverse(&self) -> SelectedInverse<'_> {
        let mut z = vec![0.0f64; self.values.len()];
        let mut rows: Vec<usize> = Vec::new();
        let mut zcol: Vec<f64> = Vec::new();
        for j in (0..self.n).rev() {
            let (start, end) = (self.col_ptr[j], self.col_ptr[j + 1]);
            let ljj = self.values[start];
            rows.clear();
            rows.extend_from_slice(&self.row_idx[start + 1..end]);
            zcol.clear();
            for &i in &rows {
                let mut s = 0.0;
                for (kk, &k) in rows.iter().enumerate() {
                    let lkj = self.values[start + 1 + kk];
                    // Z_ik = Z_(max, min) on the lower pattern.
                    let (r, c) = if i >= k { (i, k) } else { (k, i) };
                    if let Some(p) = self.find(r, c) {
                        s += lkj * z[p];
                    }
                }
                zcol.push(-s / ljj);
            }
            let mut diag = 1.0 / (ljj * ljj);
            for (kk, zij) in zcol.iter().enumerate() {
                diag -= self.values[start + 1 + kk] * zij / ljj;
            }
            z[start] = diag;
            z[start + 1..end].copy_from_slice(&zcol);
        }
        SelectedInverse { factor: self, z }
    }
}

/// The entries of A⁻¹ on the factor's pattern.
#[derive(Debug, Clone)]
pub struct SelectedInverse<'a> {
    factor: &'a Factor,
    z: Vec<f64>,
}

impl SelectedInverse<'_> {
    /// (A⁻¹)_ab in the original order, when (a, b) is on the pattern (every
    /// pair coupled in A, and every pair made part of it with
    /// [`SymmetricBuilder::couple`]).
    pub fn get(&self, a: usize, b: usize) -> Option<f64> {
        let f = self.factor;
        let (pa, pb) = (f.perm_inv[a], f.perm_inv[b]);
        let (r, c) = if pa >= pb { (pa, pb) } else { (pb, pa) };
        f.find(r, c).map(|k| self.z[k])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use rand::{Rng, SeedableRng};

    /// A random sparse SPD matrix: a chain plus random couplings, made
    /// diagonally dominant.
    fn random(n: usize, rng: &mut impl Rng) -> DMatrix<f64> {
        let mut a = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            for j in [i + 1, i + 3, rng.random_range(0..n)] {
                if j < n && j != i {
                    let v: f64 = rng.random_range(-1.0..1.0);
                    a[(i, j)] += v;
                    a[(j, i)] += v;
                }
            }
        }
        for i in 0..n {
            let s: f64 = (0..n).map(|j| a[(i, j)].abs()).sum();
            a[(i, i)] = s + 1.0;
        }
        a
    }

    #[test]
    fn solve_and_selected_inverse_match_a_dense_inverse() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for n in [1, 2, 7, 60] {
            let a = random(n, &mut rng);
            let mut b = SymmetricBuilder::new(n);
            for i in 0..n {
                for j in 0..=i {
                    if a[(i, j)] != 0.0 {
                        b.add(i, j, a[(i, j)] / 2.0);
                        b.add(i, j, a[(i, j)] / 2.0);
                    }
                }
            }
            let far = (0, n - 1);
            b.couple(far.0, far.1);
            let f = b.factor().expect("SPD");
            let inv = a.clone().try_inverse().expect("invertible");
            let rhs: Vec<f64> = (0..n).map(|i| i as f64 - 3.0).collect();
            let x = f.solve(&rhs);
            let ax = &a * nalgebra::DVector::from_vec(x);
            for i in 0..n {
                assert!((ax[i] - rhs[i]).abs() < 1e-10, "n {n} row {i}");
            }
            let s = f.selected_inverse();
            let mut checked = 0;
            for i in 0..n {
                for j in 0..n {
                    if a[(i, j)] != 0.0 || (i, j) == far || (j, i) == far {
                        let z = s.get(i, j).expect("on the pattern");
                        assert!((z - inv[(i, j)]).abs() < 1e-12 * inv.amax().max(1.0), "({i}, {j})");
                        checked += 1;
                    }
                }
            }
            assert!(checked >= n);
        }
    }

    #[test]
    fn an_undetermined_unknown_is_named() {
        // Unknown 2 appears in nothing.
        let mut b = SymmetricBuilder::new(4);
        for (i, j, v) in [(0, 0, 2.0), (1, 0, 0.5), (1, 1, 2.0), (3, 3, 1.0), (2, 2, 0.0)] {
            b.add(i, j, v);
        }
        let e = b.factor().map(|_| ()).expect_err("singular");
        assert!(matches!(e, FactorError::Singular { column: 2, .. }), "{e:?}");
        // Two unknowns that only ever appear as their sum.
        let mut b = SymmetricBuilder::new(2);
        for (i, j) in [(0, 0), (1, 0), (1, 1)] {
            b.add(i, j, 1.0);
        }
        assert!(matches!(b.factor(), Err(FactorError::Singular { .. })));
    }
}
