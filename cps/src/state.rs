//! The team state: parent pose, child prism positions and their **joint**
//! covariance with every cross-term.
//!
//! State vector order (DESIGN §4): parent (x, y, z, θ), then each child's
//! (x, y, z) in team order — dimension 4 + 3N — then each fixed point's
//! (a control point's prism, [`TeamState::add_fixed_point`]). Metres and
//! radians.
//!
//! **Clones.** [`TeamState::clone_parent`] appends a frozen copy of the
//! parent's current pose to the state (stochastic cloning): placements and
//! fixes carry every cross-term to it like to any other state, so the
//! clones of the stations where the parent scanned hold the **joint**
//! covariance of those stations — the correlation the leapfrog chain
//! creates between them, which a fusion of their scans needs. Their cost
//! grows with the square of the scan stations; [`TeamState::set_anchor`]
//! tracks instead how the state depends on the one at the last scan
//! station, from which [`crate::chain`] rebuilds the same joint covariance
//! in linear cost.

use nalgebra::{DMatrix, Matrix3, Matrix4, Point3};

use crate::error::{CpsError, Result};
use crate::fix::{FixOptions, ParentFix, SightedChild, fix_parent_mixed};
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
    /// The children's prisms, then the fixed points'.
    children: Vec<Option<Point3<f64>>>,
    /// How many of `children` are fixed points (at the end).
    fixed_points: usize,
    covariance: DMatrix<f64>,
    /// ∂(parent and children)/∂(state at the anchor), (4 + 3N) × m_anchor,
    /// once [`TeamState::set_anchor`] was called.
    anchor: Option<DMatrix<f64>>,
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
        Ok(Self { parent, children: vec![None; n_children], fixed_points: 0, covariance, anchor: None })
    }

    /// Adds a point that never moves — a control point's prism — at
    /// `position` with `covariance` (x, y, z; zero for a point held fixed),
    /// uncorrelated with everything so far; returns its index for
    /// [`TeamState::fix_parent`] (after the children's and earlier fixed
    /// points'). Clones keep their place after it.
    pub fn add_fixed_point(&mut self, position: Point3<f64>, covariance: Matrix3<f64>) -> Result<usize> {
        Ok(self.add_fixed_points(&[(position, covariance)])?[0])
    }

    /// Adds every point of `points` as [`TeamState::add_fixed_point`] adds
    /// one, in order, growing the covariance once: adding a survey's
    /// control one at a time copied the whole matrix each time (cubic in
    /// the number of points; 1,000 points took minutes). Nothing is added
    /// unless every point is valid.
    pub fn add_fixed_points(&mut self, points: &[(Point3<f64>, Matrix3<f64>)]) -> Result<Vec<usize>> {
        for (position, covariance) in points {
            for v in position.iter() {
                crate::error::ensure_finite(|| "fixed point position".into(), *v)?;
            }
            let as4 = Matrix4::from_fn(|i, j| if i < 3 && j < 3 { covariance[(i, j)] } else { 0.0 });
            check_covariance("fixed point covariance", &as4)?;
        }
        let at = child_offset(self.children.len());
        let (n, k) = (self.covariance.ncols(), 3 * points.len());
        let tail = n - at;
        let old = &self.covariance;
        let mut grown = DMatrix::zeros(n + k, n + k);
        grown.view_mut((0, 0), (at, at)).copy_from(&old.view((0, 0), (at, at)));
        grown.view_mut((0, at + k), (at, tail)).copy_from(&old.view((0, at), (at, tail)));
        grown.view_mut((at + k, 0), (tail, at)).copy_from(&old.view((at, 0), (tail, at)));
        grown.view_mut((at + k, at + k), (tail, tail)).copy_from(&old.view((at, at), (tail, tail)));
        let mut added = Vec::with_capacity(points.len());
        for (m, (position, covariance)) in points.iter().enumerate() {
            grown
                .fixed_view_mut::<3, 3>(at + 3 * m, at + 3 * m)
                .copy_from(&(0.5 * (covariance + covariance.transpose())));
            self.children.push(Some(*position));
            self.fixed_points += 1;
            added.push(self.children.len() - 1);
        }
        self.covariance = grown;
        Ok(added)
    }

    /// The parent's current estimate.
    pub fn parent(&self) -> ParentPose {
        self.parent
    }

    /// Child `j`'s position (or fixed point `j`'s, after the children),
    /// `None` if never placed.
    pub fn child(&self, j: usize) -> Option<Point3<f64>> {
        self.children.get(j).copied().flatten()
    }

    /// Number of children in the team (fixed points not counted).
    pub fn n_children(&self) -> usize {
        self.children.len() - self.fixed_points
    }

    /// Appends a clone of the parent's current pose (its block and every
    /// cross-term copied) and returns its index (0, 1, …). The clone never
    /// moves; later placements and fixes keep its cross-covariances.
    pub fn clone_parent(&mut self) -> usize {
        let n = self.covariance.ncols();
        let parent_rows = self.covariance.rows(PARENT, 4).into_owned();
        let mut grown = self.covariance.clone().resize(n + 4, n + 4, 0.0);
        for s in 0..n {
            for k in 0..4 {
                grown[(n + k, s)] = parent_rows[(k, s)];
                grown[(s, n + k)] = parent_rows[(k, s)];
            }
        }
        grown.fixed_view_mut::<4, 4>(n, n).copy_from(&self.parent_covariance());
        self.covariance = grown;
        self.clones() - 1
    }

    /// Takes the current state as the anchor: from here on the team tracks
    /// ∂(parent and children)/∂(state now), updated by every placement and
    /// fix like the covariance's rows ([`crate::chain`]). Clones are not
    /// part of the anchored state.
    pub fn set_anchor(&mut self) {
        let t = child_offset(self.n_children());
        let m = child_offset(self.children.len());
        self.anchor = Some(DMatrix::identity(t, m));
    }

    /// ∂(parent and children)/∂(state at the anchor), (4 + 3N) × m_anchor;
    /// `None` before [`TeamState::set_anchor`].
    pub fn from_anchor(&self) -> Option<&DMatrix<f64>> {
        self.anchor.as_ref()
    }

    /// Point `j`'s rows of ∂state/∂(state at the anchor): a child's tracked
    /// rows; a fixed point's own coordinates if the anchored state held it,
    /// else zero (added later, independent of it).
    fn anchor_rows(anchor: &DMatrix<f64>, j: usize) -> DMatrix<f64> {
        let o = child_offset(j);
        if o < anchor.nrows() {
            return anchor.rows(o, 3).into_owned();
        }
        DMatrix::from_fn(3, anchor.ncols(), |r, c| if c == o + r { 1.0 } else { 0.0 })
    }

    /// Number of clones ([`TeamState::clone_parent`]).
    pub fn clones(&self) -> usize {
        (self.covariance.ncols() - child_offset(self.children.len())) / 4
    }

    /// cov(clone a, clone b), 4×4 (order x, y, z, θ).
    pub fn clone_covariance(&self, a: usize, b: usize) -> Result<Matrix4<f64>> {
        let base = child_offset(self.children.len());
        for c in [a, b] {
            if c >= self.clones() {
                return Err(CpsError::UnknownClone { clone: c, clones: self.clones() });
            }
        }
        Ok(self.covariance.fixed_view::<4, 4>(base + 4 * a, base + 4 * b).into_owned())
    }

    /// cov(parent, clone a): the current parent's cross-covariance with an
    /// earlier station's clone, 4×4.
    pub fn parent_clone_covariance(&self, a: usize) -> Result<Matrix4<f64>> {
        if a >= self.clones() {
            return Err(CpsError::UnknownClone { clone: a, clones: self.clones() });
        }
        let base = child_offset(self.children.len());
        Ok(self.covariance.fixed_view::<4, 4>(PARENT, base + 4 * a).into_owned())
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
        if j >= self.n_children() {
            return Err(CpsError::UnknownChild { child: j, team: self.n_children() });
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
        if let Some(anchor) = &mut self.anchor {
            let rows = g_p * anchor.fixed_rows::<4>(PARENT);
            anchor.fixed_rows_mut::<3>(o).copy_from(&rows);
        }
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
        let mixed: Vec<(usize, Reading, &Instrument)> = readings.iter().map(|&(j, r)| (j, r, instrument)).collect();
        self.fix_parent_mixed(&mixed, options)
    }

    /// [`TeamState::fix_parent`] from children and fixed points, each
    /// sighting with its own noise model (a control prism's leaves its
    /// centring to the point's covariance).
    pub fn fix_parent_mixed(
        &mut self,
        readings: &[(usize, Reading, &Instrument)],
        options: &FixOptions,
    ) -> Result<ParentFix> {
        let fix = self.trial_fix(readings, options)?;
        // cov(C, s) for every state s: the sighted points' rows.
        let n = self.covariance.ncols();
        let mut c_rows = DMatrix::zeros(3 * readings.len(), n);
        for (k, &(j, _, _)) in readings.iter().enumerate() {
            c_rows.rows_mut(3 * k, 3).copy_from(&self.covariance.rows(child_offset(j), 3));
        }
        // cov(p, s) = F cov(C, s); the old parent's columns are replaced.
        let mut cross = &fix.f_map * &c_rows;
        cross.columns_mut(PARENT, 4).fill(0.0);
        for s in 0..n {
            for k in 0..4 {
                self.covariance[(PARENT + k, s)] = cross[(k, s)];
                self.covariance[(s, PARENT + k)] = cross[(k, s)];
            }
        }
        // Every write above mirrors itself and Σ_0 is symmetric, so the joint
        // covariance stays exactly symmetric.
        self.covariance.fixed_view_mut::<4, 4>(PARENT, PARENT).copy_from(&fix.covariance);
        if let Some(anchor) = &mut self.anchor {
            let mut sighted = DMatrix::zeros(3 * readings.len(), anchor.ncols());
            for (k, &(j, _, _)) in readings.iter().enumerate() {
                sighted.rows_mut(3 * k, 3).copy_from(&Self::anchor_rows(anchor, j));
            }
            anchor.fixed_rows_mut::<4>(PARENT).copy_from(&(&fix.f_map * sighted));
        }
        self.parent = fix.pose;
        Ok(fix)
    }

    /// The fix [`TeamState::fix_parent_mixed`] would make from `readings`,
    /// the state unchanged: what a field test tries before the team takes it
    /// ([`crate::screen::field_test`]). It reads only the sighted points'
    /// joint covariance (m × m), not their rows of the whole state.
    pub fn trial_fix(&self, readings: &[(usize, Reading, &Instrument)], options: &FixOptions) -> Result<ParentFix> {
        let mut sighted = Vec::with_capacity(readings.len());
        for &(j, reading, _) in readings {
            if j >= self.children.len() {
                return Err(CpsError::UnknownChild { child: j, team: self.n_children() });
            }
            let position = self.child(j).ok_or(CpsError::ChildNotPlaced { child: j })?;
            sighted.push(SightedChild { child: j, position, reading });
        }
        let offsets: Vec<usize> = sighted.iter().map(|c| child_offset(c.child)).collect();
        let m = 3 * sighted.len();
        let children_cov =
            DMatrix::from_fn(m, m, |a, b| self.covariance[(offsets[a / 3] + a % 3, offsets[b / 3] + b % 3)]);
        let instruments: Vec<&Instrument> = readings.iter().map(|r| r.2).collect();
        fix_parent_mixed(&sighted, &children_cov, &instruments, options)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observation::observe;
    use nalgebra::{DVector, Vector4};

    fn instrument() -> Instrument {
        Instrument { centring_target_m: 0.001, min_range_m: 0.5, ..Instrument::default() }
    }

    fn children_truth() -> Vec<Point3<f64>> {
        vec![Point3::new(8.0, 9.0, 0.3), Point3::new(9.0, -7.0, -0.2), Point3::new(20.0, 1.0, 0.5)]
    }

    /// A team after one full cycle (so every block and cross-term is non-zero).
    fn warmed_up() -> (TeamState, ParentPose) {
        let inst = instrument();
        let start = ParentPose::new(0.0, 0.0, 0.0, 0.1);
        let cov0 = Matrix4::from_diagonal(&Vector4::new(1e-4, 2e-4, 5e-5, 1e-7));
        let mut team = TeamState::new(start, cov0, 3).expect("valid");
        for (j, c) in children_truth().iter().enumerate() {
            team.place_child(j, &observe(&start, c).expect("obs"), &inst).expect("place");
        }
        let next = ParentPose::new(12.0, 1.0, 0.2, -0.2);
        let readings: Vec<_> =
            children_truth().iter().enumerate().map(|(j, c)| (j, observe(&next, c).expect("obs"))).collect();
        team.fix_parent(&readings, &inst, &FixOptions::default()).expect("fix");
        (team, next)
    }

    /// Central-difference Jacobian of `f` at `x`.
    fn jacobian(f: impl Fn(&DVector<f64>) -> DVector<f64>, x: &DVector<f64>, eps: &[f64]) -> DMatrix<f64> {
        let y0 = f(x);
        let mut j = DMatrix::zeros(y0.len(), x.len());
        for k in 0..x.len() {
            let (mut a, mut b) = (x.clone(), x.clone());
            a[k] += eps[k];
            b[k] -= eps[k];
            j.set_column(k, &((f(&a) - f(&b)) / (2.0 * eps[k])));
        }
        j
    }

    fn state_vector(team: &TeamState) -> DVector<f64> {
        let mut v = DVector::zeros(child_offset(team.n_children()));
        v.fixed_rows_mut::<4>(0).copy_from(&team.parent().to_vector());
        for j in 0..team.n_children() {
            v.fixed_rows_mut::<3>(child_offset(j)).copy_from(&team.child(j).expect("placed").coords);
        }
        v
    }

    fn relative_error(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
        (a - b).norm() / b.norm()
    }

    #[test]
    fn placement_propagates_the_joint_covariance_like_j_p_jt() {
        let (team, parent) = warmed_up();
        let inst = instrument();
        let target = Point3::new(30.0, 15.0, 1.0);
        let reading = observe(&parent, &target).expect("obs");
        // Augmented input (state, reading) → new state; independent of TeamState's algebra.
        let n = child_offset(3);
        let mut x = DVector::zeros(n + 3);
        x.rows_mut(0, n).copy_from(&state_vector(&team));
        x.fixed_rows_mut::<3>(n).copy_from(&reading.to_vector());
        let f = |x: &DVector<f64>| {
            let mut y = x.rows(0, n).into_owned();
            let p = ParentPose::from_vector(&x.fixed_rows::<4>(0).into_owned());
            let r = Reading { slope_m: x[n], azimuth_rad: x[n + 1], elevation_rad: x[n + 2] };
            let c = crate::placement::place(&p, &r, 1).expect("place").position;
            y.fixed_rows_mut::<3>(child_offset(1)).copy_from(&c.coords);
            y
        };
        let j = jacobian(f, &x, &vec![1e-5; n + 3]);
        let mut p_aug = DMatrix::zeros(n + 3, n + 3);
        p_aug.view_mut((0, 0), (n, n)).copy_from(team.covariance());
        p_aug.view_mut((n, n), (3, 3)).copy_from(&inst.reading_covariance(&reading));
        let expected = &j * p_aug * j.transpose();
        let mut placed = team.clone();
        placed.place_child(1, &reading, &inst).expect("place");
        let err = relative_error(placed.covariance(), &expected);
        assert!(err < 1e-7, "relative error {err:e}");
    }

    #[test]
    fn parent_fix_propagates_the_joint_covariance_like_j_p_jt() {
        let (team, _) = warmed_up();
        let inst = instrument();
        // Re-place children around the current parent, then move and fix.
        let mut team = team;
        let here = team.parent();
        let targets = [Point3::new(25.0, 10.0, 0.0), Point3::new(24.0, -9.0, 0.4), Point3::new(35.0, 2.0, -0.3)];
        for (j, c) in targets.iter().enumerate() {
            team.place_child(j, &observe(&here, c).expect("obs"), &inst).expect("place");
        }
        let next = ParentPose::new(27.0, 1.0, 0.1, 0.3);
        let readings: Vec<Reading> = targets.iter().map(|c| observe(&next, c).expect("obs")).collect();
        let n = child_offset(3);
        let mut x = DVector::zeros(n + 9);
        x.rows_mut(0, n).copy_from(&state_vector(&team));
        for (k, r) in readings.iter().enumerate() {
            x.fixed_rows_mut::<3>(n + 3 * k).copy_from(&r.to_vector());
        }
        // The filter's weights: the children's joint covariance Σ_C. At exact
        // readings the residuals vanish, so only the gain (not the weights'
        // own derivative) enters ∂p/∂(C, readings).
        let sigma_c = team.covariance().view((4, 4), (9, 9)).into_owned();
        // The black box: Gauss–Newton on perturbed children and readings.
        let f = |x: &DVector<f64>| {
            let sighted: Vec<SightedChild> = (0..3)
                .map(|k| SightedChild {
                    child: k,
                    position: Point3::from(x.fixed_rows::<3>(child_offset(k)).into_owned()),
                    reading: Reading {
                        slope_m: x[n + 3 * k],
                        azimuth_rad: x[n + 3 * k + 1],
                        elevation_rad: x[n + 3 * k + 2],
                    },
                })
                .collect();
            let opts =
                FixOptions { position_tolerance_m: 1e-13, heading_tolerance_rad: 1e-15, ..FixOptions::default() };
            let fix = crate::fix::fix_parent(&sighted, &sigma_c, &inst, &opts).expect("fix");
            let mut y = x.rows(0, n).into_owned();
            y.fixed_rows_mut::<4>(0).copy_from(&fix.pose.to_vector());
            y
        };
        let j = jacobian(f, &x, &vec![1e-6; n + 9]);
        let mut p_aug = DMatrix::zeros(n + 9, n + 9);
        p_aug.view_mut((0, 0), (n, n)).copy_from(team.covariance());
        for (k, r) in readings.iter().enumerate() {
            p_aug.view_mut((n + 3 * k, n + 3 * k), (3, 3)).copy_from(&inst.reading_covariance(r));
        }
        let expected = &j * p_aug * j.transpose();
        let mut fixed = team.clone();
        let sighted: Vec<(usize, Reading)> = readings.iter().copied().enumerate().collect();
        fixed.fix_parent(&sighted, &inst, &FixOptions::default()).expect("fix");
        let err = relative_error(fixed.covariance(), &expected);
        assert!(err < 1e-6, "relative error {err:e}");
        // The parent block alone (Σ_0) and its cross-terms (F·cov(C, s)).
        let err_parent = relative_error(&fixed.covariance().rows(0, 4).into_owned(), &expected.rows(0, 4).into_owned());
        assert!(err_parent < 1e-6, "parent rows: relative error {err_parent:e}");
    }

    #[test]
    fn errors_leave_the_state_unchanged() {
        let (mut team, _) = warmed_up();
        let before = team.clone();
        let inst = instrument();
        let bad = Reading { slope_m: f64::NAN, azimuth_rad: 0.0, elevation_rad: 0.0 };
        assert!(team.place_child(0, &bad, &inst).is_err());
        assert!(matches!(team.place_child(7, &bad, &inst), Err(CpsError::UnknownChild { child: 7, team: 3 })));
        let r = Reading { slope_m: 10.0, azimuth_rad: 0.0, elevation_rad: 0.0 };
        assert!(matches!(
            team.fix_parent(&[(0, r)], &inst, &FixOptions::default()),
            Err(CpsError::TooFewChildren { got: 1 })
        ));
        assert!(matches!(
            team.fix_parent(&[(0, r), (0, r)], &inst, &FixOptions::default()),
            Err(CpsError::DuplicateChild { child: 0 })
        ));
        assert_eq!(team, before);
        let mut fresh = TeamState::new(ParentPose::new(0.0, 0.0, 0.0, 0.0), Matrix4::zeros(), 2).expect("new");
        assert!(matches!(
            fresh.fix_parent(&[(0, r), (1, r)], &inst, &FixOptions::default()),
            Err(CpsError::ChildNotPlaced { child: 0 })
        ));
        let asym = Matrix4::new(1.0, 0.5, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        assert!(TeamState::new(ParentPose::new(0.0, 0.0, 0.0, 0.0), asym, 2).is_err());
    }

    /// Clones hold the joint covariance of the stations: a leapfrog chain
    /// of three cycles from an uncertain start, cloned at every station,
    /// against the empirical covariance of 4000 runs of the same chain
    /// with readings and start drawn from their distributions. Each
    /// cross-block entry must lie within 4 standard errors of its
    /// estimate; and the cross-terms are far from zero (the stations are
    /// strongly correlated).
    #[test]
    fn clones_carry_the_stations_joint_covariance_monte_carlo() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let inst = Instrument { sigma_hz_rad: 2e-5, sigma_v_rad: 2e-5, centring_target_m: 5e-4, ..instrument() };
        let stations: Vec<ParentPose> = (0..4).map(|k| ParentPose::new(10.0 * k as f64, 0.0, 0.0, 0.0)).collect();
        let cov0 = Matrix4::from_diagonal(&Vector4::new(4e-6, 9e-6, 1e-6, 1e-8));
        let formation = [nalgebra::Vector3::new(5.0, 6.0, 0.2), nalgebra::Vector3::new(5.0, -6.0, -0.2)];
        let run = |draw: &mut dyn FnMut() -> f64| -> (Vec<ParentPose>, TeamState) {
            let start = ParentPose::from_vector(
                &(stations[0].to_vector() + cov0.cholesky().expect("spd").l() * Vector4::from_fn(|_, _| draw())),
            );
            let mut team = TeamState::new(start, cov0, 2).expect("team");
            let mut noisy = |exact: Reading| inst.perturbed(&exact, [draw(), draw(), draw()]);
            let mut estimates = vec![team.parent()];
            team.clone_parent();
            for k in 0..3 {
                let children: Vec<Point3<f64>> = formation.iter().map(|f| stations[k].position + f).collect();
                for (j, c) in children.iter().enumerate() {
                    let exact = observe(&stations[k], c).expect("obs");
                    team.place_child(j, &noisy(exact), &inst).expect("place");
                }
                let readings: Vec<(usize, Reading)> = children
                    .iter()
                    .enumerate()
                    .map(|(j, c)| (j, noisy(observe(&stations[k + 1], c).expect("obs"))))
                    .collect();
                team.fix_parent(&readings, &inst, &FixOptions::default()).expect("fix");
                estimates.push(team.parent());
                team.clone_parent();
            }
            (estimates, team)
        };
        // The filter's joint covariance, from a run without noise.
        let (_, exact_team) = run(&mut || 0.0);
        assert_eq!(exact_team.clones(), 4);
        assert!(exact_team.clone_covariance(4, 0).is_err() && exact_team.parent_clone_covariance(4).is_err());
        let trials = 4000;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut errors: Vec<DVector<f64>> = Vec::with_capacity(trials);
        for _ in 0..trials {
            let (estimates, _) = run(&mut || StandardNormal.sample(&mut rng));
            let mut e = DVector::zeros(16);
            for (k, p) in estimates.iter().enumerate() {
                let mut d = p.to_vector() - stations[k].to_vector();
                d[3] = crate::observation::wrap_angle(d[3]);
                e.fixed_rows_mut::<4>(4 * k).copy_from(&d);
            }
            errors.push(e);
        }
        let mean = errors.iter().fold(DVector::zeros(16), |s, e| s + e) / trials as f64;
        let empirical = errors.iter().fold(DMatrix::zeros(16, 16), |s, e| s + (e - &mean) * (e - &mean).transpose())
            / (trials - 1) as f64;
        for (a, b) in [(0, 2), (1, 2), (1, 3), (2, 3), (3, 3)] {
            let predicted = exact_team.clone_covariance(a, b).expect("clones");
            for r in 0..4 {
                for c in 0..4 {
                    let (i, j) = (4 * a + r, 4 * b + c);
                    let (p, m) = (predicted[(r, c)], empirical[(i, j)]);
                    // Standard error of a covariance estimate (Gaussian).
                    let pa = exact_team.clone_covariance(a, a).expect("clone")[(r, r)];
                    let pb = exact_team.clone_covariance(b, b).expect("clone")[(c, c)];
                    let se = ((pa * pb + p * p) / trials as f64).sqrt();
                    assert!(
                        (m - p).abs() < 4.0 * se,
                        "cov(x{a}[{r}], x{b}[{c}]): predicted {p:e}, Monte Carlo {m:e} (se {se:e})"
                    );
                }
            }
        }
        // Neighbouring stations are strongly correlated along the route.
        let c13 = exact_team.clone_covariance(1, 3).expect("clones");
        let (v1, v3) = (exact_team.clone_covariance(1, 1).expect("c"), exact_team.clone_covariance(3, 3).expect("c"));
        let rho = c13[(1, 1)] / (v1[(1, 1)] * v3[(1, 1)]).sqrt();
        assert!(rho > 0.3, "correlation of y between stations 1 and 3: {rho}");
        // The last clone is the parent as it stands.
        assert_eq!(exact_team.parent_clone_covariance(3).expect("clone"), exact_team.parent_covariance());
    }

    /// A fixed point joins the state between the children and the clones,
    /// uncorrelated, and leaves every other block as it was; a fix from
    /// children and fixed points with one noise model equals the plain fix.
    #[test]
    fn fixed_points_join_the_state_and_the_fix() {
        let (mut team, _) = warmed_up();
        team.clone_parent();
        let before = team.clone();
        let cov = Matrix3::from_diagonal(&nalgebra::Vector3::new(1e-6, 2e-6, 0.0));
        let k = team.add_fixed_point(Point3::new(30.0, -5.0, 1.0), cov).expect("add");
        assert_eq!(k, 3);
        assert_eq!(team.n_children(), 3);
        assert_eq!(team.child(k), Some(Point3::new(30.0, -5.0, 1.0)));
        assert_eq!(team.child_covariance(k), cov);
        assert_eq!(team.clone_covariance(0, 0).expect("clone"), before.clone_covariance(0, 0).expect("clone"));
        assert_eq!(team.parent_clone_covariance(0).expect("clone"), before.parent_clone_covariance(0).expect("clone"));
        for j in 0..3 {
            assert_eq!(team.child_covariance(j), before.child_covariance(j));
        }
        let o = child_offset(k);
        assert!(team.covariance().rows(o, 3).iter().zip(0..).all(|(v, i)| *v == 0.0 || (i / 3 >= o && i / 3 < o + 3)));
        assert!(matches!(
            team.place_child(k, &Reading { slope_m: 5.0, azimuth_rad: 0.0, elevation_rad: 0.0 }, &instrument()),
            Err(CpsError::UnknownChild { .. })
        ));
        let inst = instrument();
        let here = ParentPose::new(26.0, 2.0, 0.2, 0.1);
        let readings: Vec<(usize, Reading)> =
            [0, 1, k].iter().map(|&j| (j, observe(&here, &team.child(j).expect("placed")).expect("obs"))).collect();
        let mut plain = team.clone();
        let a = plain.fix_parent(&readings, &inst, &FixOptions::default()).expect("fix");
        let mixed: Vec<(usize, Reading, &Instrument)> = readings.iter().map(|&(j, r)| (j, r, &inst)).collect();
        let b = team.fix_parent_mixed(&mixed, &FixOptions::default()).expect("fix");
        assert_eq!(a.pose, b.pose);
        assert_eq!(plain, team);
    }

    /// Many fixed points added at once are the same state as added one at
    /// a time (with clones after them), and a bad one adds none.
    #[test]
    fn fixed_points_added_at_once_equal_one_at_a_time() {
        let (mut team, _) = warmed_up();
        team.clone_parent();
        team.clone_parent();
        let points: Vec<(Point3<f64>, Matrix3<f64>)> = (0..7)
            .map(|i| {
                let f = f64::from(i);
                (
                    Point3::new(10.0 + f, -3.0 * f, 1.0),
                    Matrix3::from_diagonal(&nalgebra::Vector3::new(1e-6 * f, 2e-6, 0.0)),
                )
            })
            .collect();
        let mut one_by_one = team.clone();
        let singles: Vec<usize> =
            points.iter().map(|(p, c)| one_by_one.add_fixed_point(*p, *c).expect("add")).collect();
        let before = team.clone();
        let mut bad = points.clone();
        bad[4].0.y = f64::NAN;
        assert!(team.add_fixed_points(&bad).is_err());
        assert_eq!(team, before, "nothing added");
        assert_eq!(team.add_fixed_points(&points).expect("add"), singles);
        assert_eq!(team, one_by_one);
    }
}
