//! The parent fix (seed 003 eqs 7–16) for any N ≥ 2 children.
//!
//! Gauss–Newton on min vᵀ Σ_L⁻¹ v (eq. 13) with Σ_L = H_c Σ_C H_cᵀ + Σ_m
//! (eq. 9): the children's joint covariance Σ_C enters the weights. Each step
//! whitens the design matrix with the Cholesky factor of Σ_L and solves by QR
//! (square-root form; the normal matrix AᵀΣ_L⁻¹A is never inverted directly).
//! Σ_0 = (AᵀΣ_L⁻¹A)⁻¹ (eq. 15); the new pose's cross-covariance with any
//! other state s is F·cov(C, s) with F = −B·H_c, B = Σ_0 AᵀΣ_L⁻¹ (eq. 16
//! generalised).

use nalgebra::{DMatrix, DVector, Matrix3, Matrix4, Point3, Vector2, Vector4};

use crate::error::{CpsError, Result, ensure_finite};
use crate::instrument::Instrument;
use crate::observation::{ParentPose, Reading, observe_with_jacobians};

/// One child as the parent sees it during a fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SightedChild {
    /// Child index in team order (used in errors and results).
    pub child: usize,
    /// Current estimate of the child's prism position, world frame, metres.
    pub position: Point3<f64>,
    /// The reading taken from the new parent station to this child.
    pub reading: Reading,
}

/// Gauss–Newton settings of the parent fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixOptions {
    /// Iteration cap.
    pub max_iterations: usize,
    /// Converged when every position increment is below this, metres.
    pub position_tolerance_m: f64,
    /// … and the heading increment is below this, radians.
    pub heading_tolerance_rad: f64,
    /// Starting pose; `None` uses the closed-form start ([`closed_form_start`]).
    pub initial: Option<ParentPose>,
}

impl Default for FixOptions {
    fn default() -> Self {
        Self { max_iterations: 20, position_tolerance_m: 1e-10, heading_tolerance_rad: 1e-12, initial: None }
    }
}

/// Geometries whose column-equilibrated square-root factor has a condition
/// estimate beyond this are rejected as degenerate.
pub const MAX_CONDITION: f64 = 1e10;

/// Everything a parent fix determines. Observations are ordered child by
/// child as given, (r, φ, ψ) within each child.
#[derive(Debug, Clone)]
pub struct ParentFix {
    /// The estimated pose.
    pub pose: ParentPose,
    /// Σ_0: covariance of (x, y, z, θ), m² and rad².
    pub covariance: Matrix4<f64>,
    /// F (4 × 3N): cov(parent, s) = F · cov(C, s) for every other state s,
    /// C the sighted children's stacked positions in the order given.
    pub f_map: DMatrix<f64>,
    /// Gauss–Newton iterations done.
    pub iterations: usize,
    /// Whether the increments fell below the tolerances.
    pub converged: bool,
    /// Redundancy n − u = 3N − 4.
    pub redundancy: usize,
    /// A-posteriori variance factor σ0² = vᵀΣ_L⁻¹v / (n − u).
    pub sigma0_squared: f64,
    /// Residuals v = observed − computed (m, rad, rad per child).
    pub residuals: Vec<f64>,
    /// Condition estimate of the equilibrated square-root factor.
    pub condition: f64,
    /// The last linearisation, kept for [`ParentFix::reliability`].
    design: DMatrix<f64>,
    sigma_l_chol: nalgebra::Cholesky<f64, nalgebra::Dyn>,
}

/// Per-observation reliability of a fix (blunder detection).
#[derive(Debug, Clone, PartialEq)]
pub struct Reliability {
    /// Redundancy number of each observation, (Q_vv Σ_L⁻¹)_ii ∈ [0, 1]; they
    /// sum to the redundancy.
    pub redundancy_numbers: Vec<f64>,
    /// Baarda's w-statistic per observation (standard normal without a
    /// blunder); `None` for an observation that nothing checks (redundancy
    /// number ≈ 0).
    pub w_statistics: Vec<Option<f64>>,
}

impl Reliability {
    /// Index of the observation with the largest |w|, if any is checked.
    pub fn largest_w(&self) -> Option<(usize, f64)> {
        self.w_statistics
            .iter()
            .enumerate()
            .filter_map(|(i, w)| w.map(|w| (i, w)))
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
    }

    /// The w of sighted point `k` (its three observations: distance,
    /// azimuth, elevation) with the largest |w|, if any of them is checked.
    pub fn largest_w_of_point(&self, k: usize) -> Option<f64> {
        self.w_statistics.get(3 * k..3 * k + 3)?.iter().flatten().copied().max_by(|a, b| a.abs().total_cmp(&b.abs()))
    }
}

impl ParentFix {
    /// Redundancy numbers and Baarda w-statistics of every observation, for
    /// correlated observations: with M = Σ_L⁻¹ Q_vv Σ_L⁻¹ and
    /// Q_vv = Σ_L − A Σ_0 Aᵀ, w_i = (Σ_L⁻¹v)_i / √M_ii and r_i = (Σ_L M)_ii.
    /// Computed on request: prediction never needs it.
    pub fn reliability(&self) -> Reliability {
        let n_obs = self.design.nrows();
        let sigma_l_inv = self.sigma_l_chol.inverse();
        let p_a = &sigma_l_inv * &self.design; // Σ_L⁻¹ A
        let cov = DMatrix::from_fn(4, 4, |i, j| self.covariance[(i, j)]);
        let m = &sigma_l_inv - &p_a * cov * p_a.transpose();
        let sigma_l = self.sigma_l_chol.l() * self.sigma_l_chol.l().transpose();
        let p_v = &sigma_l_inv * DVector::from_column_slice(&self.residuals);
        let mut redundancy_numbers = Vec::with_capacity(n_obs);
        let mut w_statistics = Vec::with_capacity(n_obs);
        for i in 0..n_obs {
            let ri = sigma_l.row(i).dot(&m.column(i).transpose());
            redundancy_numbers.push(ri);
            let denom = m[(i, i)];
            w_statistics.push(if ri > 1e-9 && denom > 0.0 { Some(p_v[i] / denom.sqrt()) } else { None });
        }
        Reliability { redundancy_numbers, w_statistics }
    }
}

/// Closed-form start: the 2-D rigid fit (rotation θ, translation) of the
/// measured horizontal vectors r·cos ψ·(cos φ, sin φ) onto the children's
/// horizontal positions; z from the mean of c_z − r·sin ψ. Works for any
/// N ≥ 2 horizontally distinct children, including a parent standing on the
/// line between two of them.
pub fn closed_form_start(children: &[SightedChild]) -> Result<ParentPose> {
    if children.len() < 2 {
        return Err(CpsError::TooFewChildren { got: children.len() });
    }
    let n = children.len() as f64;
    let local: Vec<Vector2<f64>> = children
        .iter()
        .map(|c| {
            let h = c.reading.slope_m * c.reading.elevation_rad.cos();
            h * Vector2::new(c.reading.azimuth_rad.cos(), c.reading.azimuth_rad.sin())
        })
        .collect();
    let world: Vec<Vector2<f64>> = children.iter().map(|c| c.position.xy().coords).collect();
    let local_mean = local.iter().sum::<Vector2<f64>>() / n;
    let world_mean = world.iter().sum::<Vector2<f64>>() / n;
    let (mut s_cos, mut s_sin, mut spread) = (0.0, 0.0, 0.0);
    for (u, c) in local.iter().zip(&world) {
        let (u, c) = (u - local_mean, c - world_mean);
        s_cos += u.dot(&c);
        s_sin += u.x * c.y - u.y * c.x;
        spread += c.norm_squared();
    }
    if spread.sqrt() < 1e-6 {
        return Err(CpsError::CoincidentPoints {
            what: "children used in the parent fix (horizontally)".into(),
            separation_m: spread.sqrt(),
        });
    }
    let heading = s_sin.atan2(s_cos);
    let (s, c) = heading.sin_cos();
    let rotated = Vector2::new(c * local_mean.x - s * local_mean.y, s * local_mean.x + c * local_mean.y);
    let xy = world_mean - rotated;
    let z = children.iter().map(|c| c.position.z - c.reading.slope_m * c.reading.elevation_rad.sin()).sum::<f64>() / n;
    Ok(ParentPose::new(xy.x, xy.y, z, heading))
}

/// One linearisation of the fix at a pose.
struct Linearisation {
    /// Misclosure l − f(p) (azimuth wrapped).
    misclosure: DVector<f64>,
    /// A = ∂f/∂p (3N × 4).
    a: DMatrix<f64>,
    /// H_c = ∂f/∂C (3N × 3N, block diagonal).
    h_c: DMatrix<f64>,
    /// Lower Cholesky factor of Σ_L.
    sigma_l_chol: nalgebra::Cholesky<f64, nalgebra::Dyn>,
}

fn linearise(
    pose: &ParentPose,
    children: &[SightedChild],
    children_cov: &DMatrix<f64>,
    instruments: &[&Instrument],
) -> Result<Linearisation> {
    let n = children.len();
    let m = 3 * n;
    let mut misclosure = DVector::zeros(m);
    let mut a = DMatrix::zeros(m, 4);
    let mut h_c = DMatrix::zeros(m, m);
    let mut blocks = Vec::with_capacity(n);
    for (k, c) in children.iter().enumerate() {
        let (computed, j) = observe_with_jacobians(pose, &c.position)?;
        misclosure.fixed_rows_mut::<3>(3 * k).copy_from_slice(&c.reading.minus(&computed));
        a.fixed_view_mut::<3, 4>(3 * k, 0).copy_from(&j.wrt_parent);
        h_c.fixed_view_mut::<3, 3>(3 * k, 3 * k).copy_from(&j.wrt_child);
        blocks.push(j.wrt_child);
    }
    // Σ_L = H_c Σ_C H_cᵀ + Σ_m, block by block (H_c is block diagonal):
    // (Σ_L)_kl = H_k Σ_kl H_lᵀ (+ Σ_m,k on the diagonal). Exactly symmetric.
    let mut sigma_l = DMatrix::zeros(m, m);
    for k in 0..n {
        for l in 0..=k {
            let s_kl: Matrix3<f64> = children_cov.fixed_view::<3, 3>(3 * k, 3 * l).into_owned();
            let mut block = blocks[k] * s_kl * blocks[l].transpose();
            if k == l {
                block = 0.5 * (block + block.transpose()) + instruments[k].reading_covariance(&children[k].reading);
            }
            sigma_l.fixed_view_mut::<3, 3>(3 * k, 3 * l).copy_from(&block);
            if k != l {
                sigma_l.fixed_view_mut::<3, 3>(3 * l, 3 * k).copy_from(&block.transpose());
            }
        }
    }
    let sigma_l_chol = nalgebra::Cholesky::new(sigma_l).ok_or_else(|| CpsError::NotPositiveDefinite {
        what: "Σ_L = H_c Σ_C H_cᵀ + Σ_meas of the parent fix".into(),
    })?;
    Ok(Linearisation { misclosure, a, h_c, sigma_l_chol })
}

/// One whitened least-squares step: Ã = L⁻¹A, ṽ = L⁻¹(l − f) with Σ_L = LLᵀ.
struct Step {
    dx: Vector4<f64>,
    r: Matrix4<f64>,
    condition: f64,
    a_w: DMatrix<f64>,
    v_w: DVector<f64>,
}

/// Solves the whitened system Ã dx ≈ ṽ by QR.
fn whitened_step(lin: &Linearisation) -> Result<Step> {
    let l = lin.sigma_l_chol.l();
    let a_w = l
        .solve_lower_triangular(&lin.a)
        .ok_or_else(|| CpsError::NotPositiveDefinite { what: "Σ_L of the parent fix".into() })?;
    let v_w = l
        .solve_lower_triangular(&lin.misclosure)
        .ok_or_else(|| CpsError::NotPositiveDefinite { what: "Σ_L of the parent fix".into() })?;
    let col_norms: Vec<f64> = (0..4).map(|k| a_w.column(k).norm()).collect();
    let qr = a_w.clone().qr();
    let r_dyn = qr.r();
    let r = Matrix4::from_fn(|i, j| r_dyn[(i, j)]);
    let diag: Vec<f64> = (0..4).map(|k| (r[(k, k)] / col_norms[k].max(f64::MIN_POSITIVE)).abs()).collect();
    let (dmin, dmax) = diag.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &d| (lo.min(d), hi.max(d)));
    let condition = if dmin > 0.0 { dmax / dmin } else { f64::INFINITY };
    if condition.is_nan() || condition > MAX_CONDITION {
        return Err(CpsError::DegenerateGeometry {
            what: "the children do not determine the parent's x, y, z and heading".into(),
            condition,
        });
    }
    let mut qtv = v_w.clone();
    qr.q_tr_mul(&mut qtv);
    let rhs = Vector4::new(qtv[0], qtv[1], qtv[2], qtv[3]);
    let dx = r.solve_upper_triangular(&rhs).ok_or_else(|| CpsError::DegenerateGeometry {
        what: "singular square-root factor in the parent fix".into(),
        condition,
    })?;
    Ok(Step { dx, r, condition, a_w, v_w })
}

/// Fixes the parent from N ≥ 2 sighted children whose stacked positions have
/// the joint covariance `children_cov` (3N × 3N, order as in `children`).
pub fn fix_parent(
    children: &[SightedChild],
    children_cov: &DMatrix<f64>,
    instrument: &Instrument,
    options: &FixOptions,
) -> Result<ParentFix> {
    fix_parent_mixed(children, children_cov, &vec![instrument; children.len()], options)
}

/// [`fix_parent`] with each sighting's own noise model (`instruments[k]`
/// for `children[k]`): a control prism's sightings leave its centring out
/// of the reading, which its position's covariance holds.
pub fn fix_parent_mixed(
    children: &[SightedChild],
    children_cov: &DMatrix<f64>,
    instruments: &[&Instrument],
    options: &FixOptions,
) -> Result<ParentFix> {
    if instruments.len() != children.len() {
        return Err(CpsError::OutOfRange {
            what: "noise models of the sightings".into(),
            value: instruments.len() as f64,
            expected: format!("one per sighted point ({})", children.len()),
        });
    }
    if children.len() < 2 {
        return Err(CpsError::TooFewChildren { got: children.len() });
    }
    let m = 3 * children.len();
    if children_cov.shape() != (m, m) {
        return Err(CpsError::OutOfRange {
            what: "shape of the children's joint covariance".into(),
            value: children_cov.nrows() as f64,
            expected: format!("{m} × {m}"),
        });
    }
    if let Some(bad) = children_cov.iter().find(|v| !v.is_finite()) {
        return Err(CpsError::NonFinite { what: "children's joint covariance".into(), value: *bad });
    }
    for (k, c) in children.iter().enumerate() {
        c.reading.validate(c.child)?;
        instruments[k].check_range(c.child, c.reading.slope_m)?;
        for (axis, v) in ["x", "y", "z"].iter().zip(c.position.iter()) {
            ensure_finite(|| format!("{axis} of child {}", c.child), *v)?;
        }
        if children[..k].iter().any(|o| o.child == c.child) {
            return Err(CpsError::DuplicateChild { child: c.child });
        }
    }

    let mut pose = match options.initial {
        Some(p) => p,
        None => closed_form_start(children)?,
    };
    let mut iterations = 0;
    let (lin, step, converged) = loop {
        let lin = linearise(&pose, children, children_cov, instruments)?;
        let step = whitened_step(&lin)?;
        let dx = step.dx;
        iterations += 1;
        pose = ParentPose::from_vector(&(pose.to_vector() + dx));
        if !pose.to_vector().iter().all(|v| v.is_finite()) {
            return Err(CpsError::Diverged { what: "parent fix".into(), iterations });
        }
        // At national-grid coordinates (10⁶–10⁷ m) a step below 1e-10 m is
        // below the coordinates' own resolution (one ulp of 5·10⁶ is
        // 9·10⁻¹⁰ m): the tolerance is at least a few ulps of them.
        // Nor need a step be below a billionth of the fix's own σ: far
        // along an open traverse the children's covariance dominates the
        // weights, which move with the pose, and the steps shrink by a
        // constant factor — at 53 km they were still 1e-10 after 20
        // iterations, and the run stopped with a fix "not converged".
        let sigma = step.r.try_inverse().map_or(Vector4::zeros(), |r_inv| Vector4::from_fn(|i, _| r_inv.row(i).norm()));
        let resolution = 8.0 * f64::EPSILON * pose.position.coords.amax();
        let converged = (0..3).all(|i| dx[i].abs() < options.position_tolerance_m.max(resolution).max(1e-9 * sigma[i]))
            && dx[3].abs() < options.heading_tolerance_rad.max(1e-9 * sigma[3]);
        if converged || iterations >= options.max_iterations {
            break (lin, step, converged);
        }
    };
    statistics(pose, lin, step, iterations, converged)
}

/// Covariance, F map and σ0² from the last linearisation.
fn statistics(
    pose: ParentPose,
    lin: Linearisation,
    step: Step,
    iterations: usize,
    converged: bool,
) -> Result<ParentFix> {
    let Step { dx, r, condition, a_w, v_w } = step;
    let n_obs = lin.a.nrows();
    // Σ_0 = (RᵀR)⁻¹ = R⁻¹R⁻ᵀ (eq. 15).
    let r_inv = r
        .solve_upper_triangular(&Matrix4::identity())
        .ok_or_else(|| CpsError::DegenerateGeometry { what: "singular R".into(), condition })?;
    let mut covariance = r_inv * r_inv.transpose();
    covariance = 0.5 * (covariance + covariance.transpose());
    // B = Σ_0 Aᵀ Σ_L⁻¹ (eq. 14), F = −B H_c (eq. 16); Σ_L⁻¹A = L⁻ᵀ Ã.
    let sigma_l_inv_a = lin
        .sigma_l_chol
        .l_dirty()
        .tr_solve_lower_triangular(&a_w)
        .ok_or_else(|| CpsError::NotPositiveDefinite { what: "Σ_L of the parent fix".into() })?;
    let b = DMatrix::from_fn(4, n_obs, |i, j| (0..4).map(|k| covariance[(i, k)] * sigma_l_inv_a[(j, k)]).sum());
    let f_map = -(&b * &lin.h_c);
    // Residuals after the last step, v = l − f(p) − A dx; vᵀΣ_L⁻¹v = |ṽ − Ã dx|².
    let dx_dyn = DVector::from_column_slice(dx.as_slice());
    let v = &lin.misclosure - &lin.a * &dx_dyn;
    let redundancy = n_obs - 4;
    let sigma0_squared = if redundancy > 0 { (v_w - a_w * dx_dyn).norm_squared() / redundancy as f64 } else { 0.0 };
    let fix = ParentFix {
        pose,
        covariance,
        f_map,
        iterations,
        converged,
        redundancy,
        sigma0_squared,
        residuals: v.iter().copied().collect(),
        condition,
        design: lin.a,
        sigma_l_chol: lin.sigma_l_chol,
    };
    if !fix.covariance.iter().chain(fix.f_map.iter()).all(|x| x.is_finite()) {
        return Err(CpsError::Diverged { what: "parent fix covariance".into(), iterations });
    }
    Ok(fix)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observation::{observe, wrap_angle};

    fn sighted(parent: &ParentPose, children: &[Point3<f64>]) -> Vec<SightedChild> {
        children
            .iter()
            .enumerate()
            .map(|(k, c)| SightedChild { child: k, position: *c, reading: observe(parent, c).expect("regular") })
            .collect()
    }

    fn instrument() -> Instrument {
        Instrument { sigma_distance_ppm: 0.0, min_range_m: 0.5, max_range_m: 1000.0, ..Instrument::default() }
    }

    fn small_cov(m: usize) -> DMatrix<f64> {
        DMatrix::from_diagonal_element(m, m, 1e-6)
    }

    #[test]
    fn recovers_a_known_pose_from_exact_readings() {
        let truth = ParentPose::new(12.3, -4.5, 0.7, 2.9);
        let children = [Point3::new(20.0, 5.0, 0.2), Point3::new(5.0, -10.0, 1.1), Point3::new(30.0, -20.0, -0.4)];
        for n in 2..=3 {
            let s = sighted(&truth, &children[..n]);
            // From the closed form and from a poor start.
            for initial in [None, Some(ParentPose::new(10.0, -2.0, 0.0, 2.5))] {
                let opts = FixOptions { initial, ..FixOptions::default() };
                let fix = fix_parent(&s, &small_cov(3 * n), &instrument(), &opts).expect("fix");
                assert!(fix.converged);
                assert!((fix.pose.position - truth.position).norm() < 1e-9, "{:?}", fix.pose);
                assert!(wrap_angle(fix.pose.heading_rad - truth.heading_rad).abs() < 1e-9);
                assert_eq!(fix.redundancy, 3 * n - 4);
                assert!(fix.residuals.iter().all(|v| v.abs() < 1e-9));
            }
        }
    }

    #[test]
    fn converges_at_national_grid_coordinates() {
        // UTM 32N eastings and northings: one ulp of 5.7·10⁶ m is 9·10⁻¹⁰ m,
        // above the 1e-10 m tolerance; the fix still reports convergence.
        let shift = nalgebra::Vector3::new(500_000.0, 5_700_000.0, 300.0);
        let truth = ParentPose::new(12.3 + shift.x, -4.5 + shift.y, 0.7 + shift.z, 2.9);
        let children = [Point3::new(20.0, 5.0, 0.2), Point3::new(5.0, -10.0, 1.1), Point3::new(30.0, -20.0, -0.4)];
        let children: Vec<Point3<f64>> = children.iter().map(|c| c + shift).collect();
        for n in 2..=3 {
            // Readings with noise (a few mm and arc seconds), as measured.
            let mut s = sighted(&truth, &children[..n]);
            for (k, c) in s.iter_mut().enumerate() {
                let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                c.reading.slope_m += sign * 0.002;
                c.reading.azimuth_rad -= sign * 1e-5;
                c.reading.elevation_rad += 7e-6;
            }
            let fix = fix_parent(&s, &small_cov(3 * n), &instrument(), &FixOptions::default()).expect("fix");
            assert!(fix.converged, "{} iterations", fix.iterations);
            assert!(fix.iterations < 10, "{} iterations", fix.iterations);
            assert!((fix.pose.position - truth.position).norm() < 0.01, "{:?}", fix.pose);
        }
    }

    #[test]
    fn closed_form_start_works_on_the_line_between_two_children() {
        let truth = ParentPose::new(3.0, 4.0, 0.0, 0.4);
        let dir = nalgebra::Vector3::new(0.4f64.cos(), 0.4f64.sin(), 0.0);
        let children = [truth.position + 10.0 * dir, truth.position - 7.0 * dir];
        let s = sighted(&truth, &children);
        let start = closed_form_start(&s).expect("start");
        assert!((start.position - truth.position).norm() < 1e-9);
        assert!(wrap_angle(start.heading_rad - truth.heading_rad).abs() < 1e-12);
        let fix = fix_parent(&s, &small_cov(6), &instrument(), &FixOptions::default()).expect("fix");
        assert!((fix.pose.position - truth.position).norm() < 1e-9);
    }

    #[test]
    fn a_20_mm_blunder_on_one_distance_gets_the_largest_w() {
        let truth = ParentPose::new(0.0, 0.0, 0.0, 0.3);
        let children = [
            Point3::new(15.0, 8.0, 0.3),
            Point3::new(14.0, -9.0, -0.2),
            Point3::new(-12.0, 10.0, 0.1),
            Point3::new(-10.0, -13.0, 0.0),
        ];
        let cov = DMatrix::from_diagonal_element(12, 12, 1e-8);
        for blundered in 0..children.len() {
            let mut s = sighted(&truth, &children);
            s[blundered].reading.slope_m += 0.020;
            let fix = fix_parent(&s, &cov, &instrument(), &FixOptions::default()).expect("fix");
            let rel = fix.reliability();
            let (idx, w) = rel.largest_w().expect("checked observations");
            assert_eq!(idx, 3 * blundered, "w = {:?}", rel.w_statistics);
            // Per sighted point: the blundered one carries it.
            assert_eq!(rel.largest_w_of_point(blundered), Some(w));
            assert_eq!(rel.largest_w_of_point(children.len()), None);
            assert!(w.abs() > 3.29, "a 20 mm blunder against 3 mm noise is significant: w = {w}");
            let total: f64 = rel.redundancy_numbers.iter().sum();
            assert!((total - fix.redundancy as f64).abs() < 1e-9, "Σ r_i = {total}");
        }
    }

    #[test]
    fn w_statistics_are_standard_normal_under_noise() {
        // Monte Carlo of the w-test's null distribution (σ0² ≈ 1, w ~ N(0,1)).
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let truth = ParentPose::new(0.0, 0.0, 0.0, 0.0);
        let children = [Point3::new(15.0, 8.0, 0.3), Point3::new(14.0, -9.0, -0.2), Point3::new(-12.0, 10.0, 0.1)];
        let inst = instrument();
        let cov = DMatrix::from_diagonal_element(9, 9, 1e-12);
        let (mut sum_w2, mut sum_s0, mut count) = (0.0, 0.0, 0usize);
        let trials = 2000;
        for _ in 0..trials {
            let mut s = sighted(&truth, &children);
            for c in &mut s {
                let [vr, vp, vv] = inst.reading_variances(&c.reading);
                c.reading.slope_m += Normal::new(0.0, vr.sqrt()).expect("σ").sample(&mut rng);
                c.reading.azimuth_rad += Normal::new(0.0, vp.sqrt()).expect("σ").sample(&mut rng);
                c.reading.elevation_rad += Normal::new(0.0, vv.sqrt()).expect("σ").sample(&mut rng);
            }
            let fix = fix_parent(&s, &cov, &inst, &FixOptions::default()).expect("fix");
            sum_s0 += fix.sigma0_squared;
            for w in fix.reliability().w_statistics.iter().flatten() {
                sum_w2 += w * w;
                count += 1;
            }
        }
        // E[w²] = 1, E[σ0²] = 1 (σ0² ~ χ²₅/5, variance 2/5).
        let mean_w2 = sum_w2 / count as f64;
        let mean_s0 = sum_s0 / trials as f64;
        // Var(w²) = 2; w's of one fix are correlated, so bound the mean of w² as
        // if they were fully correlated: 3·√(2/trials).
        assert!((mean_w2 - 1.0).abs() < 3.0 * (2.0 / trials as f64).sqrt(), "E[w²] = {mean_w2}");
        assert!((mean_s0 - 1.0).abs() < 3.0 * (2.0 / (5.0 * trials as f64)).sqrt(), "E[σ0²] = {mean_s0}");
    }

    #[test]
    fn degenerate_inputs_are_typed_errors() {
        let truth = ParentPose::new(0.0, 0.0, 0.0, 0.0);
        let one = sighted(&truth, &[Point3::new(10.0, 0.0, 0.0)]);
        assert!(matches!(
            fix_parent(&one, &small_cov(3), &instrument(), &FixOptions::default()),
            Err(CpsError::TooFewChildren { got: 1 })
        ));
        let same = sighted(&truth, &[Point3::new(10.0, 0.0, 0.0), Point3::new(10.0, 0.0, 0.0)]);
        assert!(matches!(
            fix_parent(&same, &small_cov(6), &instrument(), &FixOptions::default()),
            Err(CpsError::CoincidentPoints { .. })
        ));
        let mut nan = sighted(&truth, &[Point3::new(10.0, 0.0, 0.0), Point3::new(0.0, 10.0, 0.0)]);
        nan[1].reading.azimuth_rad = f64::NAN;
        let err = fix_parent(&nan, &small_cov(6), &instrument(), &FixOptions::default()).expect_err("NaN");
        assert!(err.to_string().contains("azimuth to child 1"), "{err}");
        let mut zero = sighted(&truth, &[Point3::new(10.0, 0.0, 0.0), Point3::new(0.0, 10.0, 0.0)]);
        zero[0].reading.slope_m = 0.0;
        assert!(fix_parent(&zero, &small_cov(6), &instrument(), &FixOptions::default()).is_err());
        let far = sighted(&truth, &[Point3::new(2000.0, 0.0, 0.0), Point3::new(0.0, 10.0, 0.0)]);
        assert!(matches!(
            fix_parent(&far, &small_cov(6), &instrument(), &FixOptions::default()),
            Err(CpsError::BeyondInstrumentRange { child: 0, .. })
        ));
    }
}
