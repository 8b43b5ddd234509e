//! The team state: parent pose, child prism positions and their **joint**
//! covariance with every cross-term.
//!
//! State vector order (DESIGN §4): parent (x, y, z, θ), then each child's
//! (x, y, z) in team order — dimension 4 + 3N. Metres and radians.

use nalgebra::{DMatrix, Matrix3, Matrix4, Point3};

use crate::error::{CpsError, Result};
use crate::fix::{FixOptions, ParentFix, SightedChild, fix_parent, symmetrise};
use crate::instrument::Instrument;
use crate::observation::{ParentPose, Reading};
use crate::placement::{Placement, place};

/// Offset of the parent block in the state vector.
pub const PARENT: usize = 0;

/// Offset of child `j`'s block in the state vector.
pub const fn child_offset(j: usize) -> usize {
    4 + 3 * j
}

/// Parent pose, children and joint covariance, updated by the dance.
#[derive(Debug, Clone, PartialEq)]
pub struct TeamState {
    parent: ParentPose,
    children: Vec<Option<Point3<f64>>>,
    covariance: DMatrix<f64>,
}

impl TeamState {
    /// A team whose parent stands at `parent` with covariance `parent_cov`
    /// (order x, y, z, θ; zero for a known start) and whose `n_children`
    /// children are not yet placed.
    pub fn new(parent: ParentPose, parent_cov: Matrix4<f64>, n_children: usize) -> Result<Self> {
        for v in parent.to_vector().iter() {
            crate::error::ensure_finite(|| "start pose".into(), *v)?;
        }
        check_covariance("start covariance", &parent_cov)?;
        let n = child_offset(n_children);
        let mut covariance = DMatrix::zeros(n, n);
        covariance.fixed_view_mut::<4, 4>(PARENT, PARENT).copy_from(&parent_cov);
        Ok(Self { parent, children: vec![None; n_children], covariance })
    }

    /// The parent's current estimate.
    pub fn parent(&self) -> ParentPose {
        self.parent
    }

    /// Child `j`'s position, `None` if never placed.
    pub fn child(&self, j: usize) -> Option<Point3<f64>> {
        self.children.get(j).copied().flatten()
    }

    /// Number of children in the team.
    pub fn n_children(&self) -> usize {
        self.children.len()
    }

    /// The joint covariance (4 + 3N square; order in the module docs).
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.covariance
    }

    /// The parent's 4×4 covariance (x, y, z, θ).
    pub fn parent_covariance(&self) -> Matrix4<f64> {
        self.covariance.fixed_view::<4, 4>(PARENT, PARENT).into_owned()
    }

    /// Child `j`'s 3×3 covariance (x, y, z).
    pub fn child_covariance(&self, j: usize) -> Matrix3<f64> {
        let o = child_offset(j);
        self.covariance.fixed_view::<3, 3>(o, o).into_owned()
    }

    fn check_child(&self, j: usize) -> Result<()> {
        if j >= self.children.len() {
            return Err(CpsError::UnknownChild { child: j, team: self.children.len() });
        }
        Ok(())
    }

    /// Child `j` has moved and the standing parent measured it (eqs 17–24):
    /// its position becomes p + r(…) and its covariance
    /// G_p Σ_pp G_pᵀ + G_m Σ_m G_mᵀ; its cross-covariance with every other
    /// state s becomes G_p·cov(p, s). Fails (state unchanged) on a bad reading
    /// or a range outside the instrument's.
    pub fn place_child(&mut self, j: usize, reading: &Reading, instrument: &Instrument) -> Result<Placement> {
        self.check_child(j)?;
        instrument.check_range(j, reading.slope_m)?;
        let placed = place(&self.parent, reading, j)?;
        let g_p = &placed.wrt_parent;
        let g_m = &placed.wrt_reading;
        let n = self.covariance.ncols();
        let o = child_offset(j);
        // Rows cov(c, s) = G_p cov(p, s) for every s (the child's own block is
        // overwritten below).
        let rows = g_p * self.covariance.fixed_rows::<4>(PARENT);
        let own = g_p * self.parent_covariance() * g_p.transpose()
            + g_m * instrument.reading_covariance(reading) * g_m.transpose();
        for s in 0..n {
            for k in 0..3 {
                self.covariance[(o + k, s)] = rows[(k, s)];
                self.covariance[(s, o + k)] = rows[(k, s)];
            }
        }
        let own = 0.5 * (own + own.transpose());
        self.covariance.fixed_view_mut::<3, 3>(o, o).copy_from(&own);
        self.children[j] = Some(placed.position);
        Ok(placed)
    }

    /// The parent has moved and measured the children `readings` (child
    /// index, reading): it fixes itself by weighted least squares (eqs 7–16).
    /// Its block becomes Σ_0 and its cross-covariance with every child s
    /// becomes F·cov(C, s). Fails (state unchanged) on degenerate input.
    pub fn fix_parent(
        &mut self,
        readings: &[(usize, Reading)],
        instrument: &Instrument,
        options: &FixOptions,
    ) -> Result<ParentFix> {
        let mut sighted = Vec::with_capacity(readings.len());
        for &(j, reading) in readings {
            self.check_child(j)?;
            let position = self.child(j).ok_or(CpsError::ChildNotPlaced { child: j })?;
            sighted.push(SightedChild { child: j, position, reading });
        }
        let m = 3 * sighted.len();
        let offsets: Vec<usize> = sighted.iter().map(|c| child_offset(c.child)).collect();
        let n = self.covariance.ncols();
        // cov(C, s) for every state s: the sighted children's rows.
        let mut c_rows = DMatrix::zeros(m, n);
        for (k, &o) in offsets.iter().enumerate() {
            c_rows.rows_mut(3 * k, 3).copy_from(&self.covariance.rows(o, 3));
        }
        let children_cov = DMatrix::from_fn(m, m, |a, b| c_rows[(a, offsets[b / 3] + b % 3)]);
        let fix = fix_parent(&sighted, &children_cov, instrument, options)?;
        // cov(p, s) = F cov(C, s); the old parent's columns are replaced.
        let mut cross = &fix.f_map * &c_rows;
        cross.columns_mut(PARENT, 4).fill(0.0);
        for s in 0..n {
            for k in 0..4 {
                self.covariance[(PARENT + k, s)] = cross[(k, s)];
                self.covariance[(s, PARENT + k)] = cross[(k, s)];
            }
        }
        self.covariance.fixed_view_mut::<4, 4>(PARENT, PARENT).copy_from(&fix.covariance);
        symmetrise(&mut self.covariance);
        self.parent = fix.pose;
        Ok(fix)
    }
}

fn check_covariance(what: &str, m: &Matrix4<f64>) -> Result<()> {
    if let Some(bad) = m.iter().find(|v| !v.is_finite()) {
        return Err(CpsError::NonFinite { what: what.into(), value: *bad });
    }
    let asym = (m - m.transpose()).amax();
    if asym > 1e-12 * m.amax().max(f64::MIN_POSITIVE) {
        return Err(CpsError::NotPositiveDefinite { what: format!("{what} (not symmetric)") });
    }
    let min_eig = m.symmetric_eigenvalues().min();
    if min_eig < -1e-12 * m.amax() {
        return Err(CpsError::NotPositiveDefinite { what: format!("{what} (eigenvalue {min_eig:e})") });
    }
    Ok(())
}
