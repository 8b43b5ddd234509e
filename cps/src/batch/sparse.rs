//! A sparse symmetric positive definite matrix — the normal equations of a
//! network — factorised by faer's simplicial Cholesky after its approximate
//! minimum degree ordering, solved, and partly inverted: Takahashi's
//! recurrences give every entry of the inverse on the factor's pattern
//! (which holds every pair of unknowns coupled in the matrix) in
//! Σ_j |col_j|² operations, so covariances of stations, points and the
//! pairs observed together cost no dense inverse and memory stays linear in
//! the network.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};

/// The lower triangle of a symmetric matrix, as summed entries, bucketed
/// by column as they are added: with the column counts known up front
/// ([`SymmetricBuilder::with_column_counts`]) each entry goes straight to
/// its place, 12 bytes an entry (a 100,000-cycle route adds some 13
/// million), and the matrix is compacted where it lies.
#[derive(Debug, Clone)]
pub struct SymmetricBuilder {
    n: usize,
    /// Column c's slots are `start[c]..start[c + 1]`; `next[c]` the first
    /// free one.
    start: Vec<usize>,
    next: Vec<usize>,
    rows: Vec<u32>,
    values: Vec<f64>,
    /// Entries beyond their column's count (none when the counts were
    /// right): (column, row, value).
    extra: Vec<(u32, u32, f64)>,
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
    /// faer could not allocate or order the matrix, or it is too large for
    /// 32-bit indices.
    Internal,
}

/// Pivots below this fraction of their diagonal entry (a loss of all but
/// about 5 digits) mark an unknown the matrix does not determine.
pub const PIVOT_TOLERANCE: f64 = 1e-11;

impl SymmetricBuilder {
    /// An n × n matrix of zeros.
    pub fn new(n: usize) -> Self {
        Self::with_column_counts(&vec![0; n])
    }

    /// An n × n matrix of zeros (n = `counts.len()`) with room for
    /// `counts[c]` additions in column c of the lower triangle (the
    /// smaller index of each pair added). More are taken too, at the cost
    /// of a copy.
    pub fn with_column_counts(counts: &[usize]) -> Self {
        let n = counts.len();
        let mut start = vec![0usize; n + 1];
        for (c, k) in counts.iter().enumerate() {
            start[c + 1] = start[c] + k;
        }
        let total = start[n];
        Self { n, next: start[..n].to_vec(), start, rows: vec![0; total], values: vec![0.0; total], extra: Vec::new() }
    }

    /// Adds `v` at (i, j) and (j, i).
    pub fn add(&mut self, i: usize, j: usize, v: f64) {
        let (r, c) = if i >= j { (i, j) } else { (j, i) };
        debug_assert!(r < self.n && self.n <= u32::MAX as usize);
        let slot = self.next[c];
        if slot < self.start[c + 1] {
            self.rows[slot] = r as u32;
            self.values[slot] = v;
            self.next[c] += 1;
        } else {
            self.extra.push((c as u32, r as u32, v));
        }
    }

    /// Makes (i, j) part of the pattern (a structural zero), so that the
    /// inverse's entry there is computed.
    pub fn couple(&mut self, i: usize, j: usize) {
        self.add(i, j, 0.0);
    }

    /// The entries beyond their counts put in their columns (a copy).
    fn take_extra(&mut self) {
        if self.extra.is_empty() {
            return;
        }
        let mut counts: Vec<usize> = (0..self.n).map(|c| self.next[c] - self.start[c]).collect();
        for &(c, _, _) in &self.extra {
            counts[c as usize] += 1;
        }
        let mut merged = Self::with_column_counts(&counts);
        for c in 0..self.n {
            for k in self.start[c]..self.next[c] {
                merged.add(self.rows[k] as usize, c, self.values[k]);
            }
        }
        for &(c, r, v) in &std::mem::take(&mut self.extra) {
            merged.add(r as usize, c as usize, v);
        }
        *self = merged;
    }

    /// The matrix in compressed columns (32-bit indices), each column's
    /// rows sorted and duplicates summed, compacted where it lies.
    fn compressed(mut self) -> (Vec<u32>, Vec<u32>, Vec<f64>) {
        self.take_extra();
        let n = self.n;
        let mut col_ptr = vec![0u32; n + 1];
        let mut w = 0usize;
        for c in 0..n {
            let (from, to) = (self.start[c], self.next[c]);
            sort_by_row(&mut self.rows[from..to], &mut self.values[from..to]);
            let column_start = w;
            for k in from..to {
                if w > column_start && self.rows[w - 1] == self.rows[k] {
                    self.values[w - 1] += self.values[k];
                } else {
                    self.rows[w] = self.rows[k];
                    self.values[w] = self.values[k];
                    w += 1;
                }
            }
            col_ptr[c + 1] = w as u32;
        }
        self.rows.truncate(w);
        self.values.truncate(w);
        self.rows.shrink_to_fit();
        self.values.shrink_to_fit();
        (col_ptr, self.rows, self.values)
    }

    /// Factorises the matrix: AMD ordering, simplicial LLᵀ, with 32-bit
    /// indices throughout. The permuted matrix is built here (its upper
    /// triangle, which faer's simplicial factorisation reads) and the
    /// original let go before the factor is allocated: faer's one-call
    /// path keeps both and a permuted copy in its scratch (issue 35: a
    /// 100,000-cycle network's peak).
    pub fn factor(self) -> Result<Factor, FactorError> {
        self.factor_with(&mut None)
    }

    /// [`factor`](Self::factor), reusing `analysis` — the ordering and the
    /// factor's pattern of an earlier matrix — when this one has the same
    /// pattern (the Gauss–Newton iterations of one network, and data
    /// snooping's re-adjustments: the ordering and the symbolic
    /// factorisation were a third of each), and leaving this one's there.
    pub fn factor_with(self, analysis: &mut Option<Analysis>) -> Result<Factor, FactorError> {
        use faer::sparse::linalg::amd;
        use faer::sparse::linalg::cholesky::simplicial;
        let n = self.n;
        if n > u32::MAX as usize / 2 || self.rows.len() + self.extra.len() > u32::MAX as usize {
            return Err(FactorError::Internal);
        }
        let (col_ptr, row_idx, values) = self.compressed();
        let key = {
            use std::hash::{Hash, Hasher};
            let mut h = std::collections::hash_map::DefaultHasher::new();
            col_ptr.hash(&mut h);
            row_idx.hash(&mut h);
            (n, row_idx.len(), h.finish())
        };
        let reused = analysis.take().filter(|a| a.key == key);
        // The approximate minimum degree ordering.
        let (perm_fwd, perm_inv): (std::sync::Arc<[u32]>, std::sync::Arc<[u32]>) = match &reused {
            Some(a) => (a.perm_fwd.clone(), a.perm_inv.clone()),
            None => {
                let mut perm_fwd = vec![0u32; n];
                let mut perm_inv = vec![0u32; n];
                let a = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
                // (Its rows sorted and distinct: no copy to sort them.)
                let mut buffer = MemBuffer::try_new(amd::order_scratch::<u32>(n, row_idx.len()))
                    .map_err(|_| FactorError::Internal)?;
                amd::order(&mut perm_fwd, &mut perm_inv, a, amd::Control::default(), MemStack::new(&mut buffer))
                    .map_err(|_| FactorError::Internal)?;
                (perm_fwd.into(), perm_inv.into())
            }
        };
        // P A Pᵀ's upper triangle, each column's rows sorted.
        let (p_col_ptr, p_row_idx, p_values) = {
            let mut counts = vec![0usize; n];
            for c in 0..n {
                for &r in &row_idx[col_ptr[c] as usize..col_ptr[c + 1] as usize] {
                    let (pr, pc) = (perm_inv[r as usize], perm_inv[c]);
                    counts[pr.max(pc) as usize] += 1;
                }
            }
            let mut next = Vec::with_capacity(n + 1);
            let mut total = 0u32;
            next.push(0u32);
            for k in &counts {
                total += *k as u32;
                next.push(total);
            }
            drop(counts);
            let p_col_ptr = next.clone();
            let mut p_row_idx = vec![0u32; row_idx.len()];
            let mut p_values = vec![0.0f64; row_idx.len()];
            for c in 0..n {
                for k in col_ptr[c] as usize..col_ptr[c + 1] as usize {
                    let (pr, pc) = (perm_inv[row_idx[k] as usize], perm_inv[c]);
                    let (row, col) = (pr.min(pc), pr.max(pc) as usize);
                    let slot = next[col] as usize;
                    p_row_idx[slot] = row;
                    p_values[slot] = values[k];
                    next[col] += 1;
                }
            }
            for c in 0..n {
                let (from, to) = (p_col_ptr[c] as usize, p_col_ptr[c + 1] as usize);
                sort_by_row(&mut p_row_idx[from..to], &mut p_values[from..to]);
            }
            (p_col_ptr, p_row_idx, p_values)
        };
        drop((values, row_idx, col_ptr));
        let upper = SymbolicSparseColMatRef::new_checked(n, n, &p_col_ptr, None, &p_row_idx);
        let symbolic = match reused {
            Some(a) => a.symbolic,
            None => std::sync::Arc::new({
                let mut etree = vec![0i32; n];
                let mut col_counts = vec![0u32; n];
                let mut buffer = MemBuffer::try_new(StackReq::any_of(&[
                    simplicial::prefactorize_symbolic_cholesky_scratch::<u32>(n, p_row_idx.len()),
                    simplicial::factorize_simplicial_symbolic_cholesky_scratch::<u32>(n),
                ]))
                .map_err(|_| FactorError::Internal)?;
                let stack = MemStack::new(&mut buffer);
                let etree =
                    simplicial::prefactorize_symbolic_cholesky::<u32>(&mut etree, &mut col_counts, upper, stack);
                simplicial::factorize_simplicial_symbolic_cholesky(upper, etree, &col_counts, stack)
                    .map_err(|_| FactorError::Internal)?
            }),
        };
        if symbolic.len_val() > u32::MAX as usize {
            return Err(FactorError::Internal);
        }
        let mut l_values = vec![0.0f64; symbolic.len_val()];
        let result = {
            let mut buffer = MemBuffer::try_new(simplicial::factorize_simplicial_numeric_llt_scratch::<u32, f64>(n))
                .map_err(|_| FactorError::Internal)?;
            simplicial::factorize_simplicial_numeric_llt(
                &mut l_values,
                SparseColMatRef::new(upper, &p_values),
                Default::default(),
                &symbolic,
                MemStack::new(&mut buffer),
            )
        };
        // P A Pᵀ's diagonal: each upper column's last entry, when on it.
        let diagonal: Vec<f64> = (0..n)
            .map(|j| {
                let (from, to) = (p_col_ptr[j] as usize, p_col_ptr[j + 1] as usize);
                if to > from && p_row_idx[to - 1] as usize == j { p_values[to - 1] } else { 0.0 }
            })
            .collect();
        drop((p_values, p_row_idx, p_col_ptr));
        if let Err(e) = result {
            // The permuted column that failed, back to the caller's order.
            // faer counts the failed pivot from 1.
            let faer::linalg::solvers::LltError::NonPositivePivot { index } = e;
            let column = perm_fwd.get(index.saturating_sub(1)).map_or(0, |&c| c as usize);
            return Err(FactorError::Singular { column, pivot: 0.0 });
        }
        *analysis =
            Some(Analysis { key, perm_fwd: perm_fwd.clone(), perm_inv: perm_inv.clone(), symbolic: symbolic.clone() });
        let factor = Factor { n, perm_fwd, perm_inv, symbolic, values: l_values };
        // A positive but vanishing pivot: the unknown is as good as undetermined.
        for (j, &d) in diagonal.iter().enumerate() {
            let original = factor.perm_fwd[j] as usize;
            let pivot = factor.values[factor.col_ptr()[j] as usize].powi(2);
            if d.is_nan() || d <= 0.0 || pivot < PIVOT_TOLERANCE * d {
                return Err(FactorError::Singular { column: original, pivot: if d > 0.0 { pivot / d } else { 0.0 } });
            }
        }
        Ok(factor)
    }
}

/// Sorts one column's few entries by row (insertion sort), moving each
/// value with its row.
fn sort_by_row(rows: &mut [u32], values: &mut [f64]) {
    for k in 1..rows.len() {
        let (r, v) = (rows[k], values[k]);
        let mut m = k;
        while m > 0 && rows[m - 1] > r {
            rows[m] = rows[m - 1];
            values[m] = values[m - 1];
            m -= 1;
        }
        rows[m] = r;
        values[m] = v;
    }
}

/// The Cholesky factor L of P A Pᵀ (simplicial, columns sorted, the
/// diagonal first in each), with the permutation.
#[derive(Debug, Clone)]
pub struct Factor {
    n: usize,
    /// Permuted position → original index.
    perm_fwd: std::sync::Arc<[u32]>,
    /// Original index → permuted position.
    perm_inv: std::sync::Arc<[u32]>,
    /// L's pattern (shared with the [`Analysis`] that made it).
    symbolic: std::sync::Arc<faer::sparse::linalg::cholesky::simplicial::SymbolicSimplicialCholesky<u32>>,
    values: Vec<f64>,
}

/// The ordering and the factor's pattern of a matrix, for the next matrix
/// of the same pattern ([`SymmetricBuilder::factor_with`]).
#[derive(Debug, Clone)]
pub struct Analysis {
    /// (dimension, entries, hash of the lower triangle's pattern).
    key: (usize, usize, u64),
    perm_fwd: std::sync::Arc<[u32]>,
    perm_inv: std::sync::Arc<[u32]>,
    symbolic: std::sync::Arc<faer::sparse::linalg::cholesky::simplicial::SymbolicSimplicialCholesky<u32>>,
}

impl Factor {
    fn col_ptr(&self) -> &[u32] {
        self.symbolic.col_ptr()
    }

    fn row_idx(&self) -> &[u32] {
        self.symbolic.row_idx()
    }

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
        let mut x: Vec<f64> = (0..self.n).map(|j| b[self.perm_fwd[j] as usize]).collect();
        // L y = P b.
        for j in 0..self.n {
            let (start, end) = (self.col_ptr()[j] as usize, self.col_ptr()[j + 1] as usize);
            x[j] /= self.values[start];
            let xj = x[j];
            for k in start + 1..end {
                x[self.row_idx()[k] as usize] -= self.values[k] * xj;
            }
        }
        // Lᵀ z = y.
        for j in (0..self.n).rev() {
            let (start, end) = (self.col_ptr()[j] as usize, self.col_ptr()[j + 1] as usize);
            let mut s = x[j];
            for k in start + 1..end {
                s -= self.values[k] * x[self.row_idx()[k] as usize];
            }
            x[j] = s / self.values[start];
        }
        let mut out = vec![0.0; self.n];
        for (j, v) in x.into_iter().enumerate() {
            out[self.perm_fwd[j] as usize] = v;
        }
        out
    }

    /// Position of L's entry (row, col) in `values`, if in the pattern.
    fn find(&self, row: u32, col: u32) -> Option<usize> {
        let (start, end) = (self.col_ptr()[col as usize] as usize, self.col_ptr()[col as usize + 1] as usize);
        self.row_idx()[start..end].binary_search(&row).ok().map(|k| start + k)
    }

    /// Every entry of A⁻¹ on L's pattern (Takahashi, Erisman and Tinney):
    /// from the last column to the first, with S_j the rows below the
    /// diagonal of column j,
    /// Z_ij = −(1/L_jj) Σ_{k∈S_j} L_kj Z_ik for i ∈ S_j and
    /// Z_jj = 1/L_jj² − (1/L_jj) Σ_{k∈S_j} L_kj Z_kj. S_j is a clique of
    /// the filled graph, so every Z_ik needed lies on the pattern.
    pub fn selected_inverse(&self) -> SelectedInverse<'_> {
        let mut z = vec![0.0f64; self.values.len()];
        // s_i = Σ_{k∈S_j} L_kj Z_ik for each i of S_j, by position in S_j.
        let mut sums: Vec<f64> = Vec::new();
        for j in (0..self.n).rev() {
            let (start, end) = (self.col_ptr()[j] as usize, self.col_ptr()[j + 1] as usize);
            let ljj = self.values[start];
            let rows = &self.row_idx()[start + 1..end];
            let l = &self.values[start + 1..end];
            sums.clear();
            sums.resize(rows.len(), 0.0);
            // Each pair (r ≥ c) of S_j once, from column c's pattern (which
            // holds every r of S_j below c: S_j is a clique), walked beside
            // S_j: Z_rc adds L_cj Z_rc to s_r and, off the diagonal,
            // L_rj Z_rc to s_c.
            for (a, &c) in rows.iter().enumerate() {
                let (cs, ce) = (self.col_ptr()[c as usize] as usize, self.col_ptr()[c as usize + 1] as usize);
                sums[a] += l[a] * z[cs];
                let mut p = cs + 1;
                for b in a + 1..rows.len() {
                    let r = rows[b];
                    while p < ce && self.row_idx()[p] < r {
                        p += 1;
                    }
                    if p < ce && self.row_idx()[p] == r {
                        let zrc = z[p];
                        sums[b] += l[a] * zrc;
                        sums[a] += l[b] * zrc;
                    }
                }
            }
            let mut diag = 1.0 / (ljj * ljj);
            for (a, s) in sums.iter().enumerate() {
                let zij = -s / ljj;
                diag -= l[a] * zij / ljj;
                z[start + 1 + a] = zij;
            }
            z[start] = diag;
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
