//! Scan poses from absolute priors (the CPS pose of each scan) and relative
//! ICP matches between scans, adjusted together: a pose graph solved by
//! Gauss–Newton on the manifold, the small_gicp "general factor" idea done
//! for the whole set at once.
//!
//! Every pose is `world_from_scan`; errors are ξ = (ω, v) with **left**
//! perturbation in the world frame, as in [`crate::icp`]:
//! - a prior on scan i (mean P, information Λ) contributes
//!   ‖ξ(Tᵢ · P⁻¹)‖²_Λ;
//! - an edge (target t, source s, measured Z = `target_from_source`,
//!   information Λ in the target frame as [`IcpResult`](crate::icp::IcpResult)
//!   gives it) contributes ‖ξ(Tₜ⁻¹ · Tₛ · Z⁻¹)‖²_Λ. With Tₛ ← exp(δₛ)Tₛ the
//!   error moves by Ad(Tₜ⁻¹)·δₛ, with Tₜ ← exp(δₜ)Tₜ by −Ad(Tₜ⁻¹)·δₜ, where
//!   `Ad(R, t) = [[R, 0], [[t]×R, R]]` in the (ω, v) order.
//!
//! - or a **joint** prior on all scans ([`JointPrior`]): the stacked
//!   errors e = (ξ(T₁·P₁⁻¹), …, ξ(T_N·P_N⁻¹)) with a full 6N×6N covariance
//!   contribute eᵀΛe. The CPS poses of a mission's stations are correlated
//!   (each fix rests on children placed from the station before), and
//!   independent priors would count their common error once per station.
//!
//! The normal equations are dense (6N unknowns; N is a mission's scan
//! count) and solved with faer's Cholesky factorisation; each pose's 6×6
//! covariance is the matching diagonal block of their inverse.

use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side, prelude::*};
use nalgebra::{Isometry3, Matrix3, Matrix6, UnitQuaternion, Vector3, Vector6};

use crate::error::{FusionError, Result};
use crate::se3::{Prior, adjoint, exp, left_difference};

/// A relative pose between two scans, e.g. an ICP match.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// The scan whose frame the measurement is in.
    pub target: usize,
    /// The scan it places.
    pub source: usize,
    /// The measured `target_from_source`.
    pub target_from_source: Isometry3<f64>,
    /// Its information, ξ = (ω, v), left perturbation in the target frame.
    pub information: Matrix6<f64>,
}

/// What [`optimize`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphResult {
    /// The adjusted `world_from_scan` of every scan.
    pub world_from_scan: Vec<Isometry3<f64>>,
    /// Each pose's 6×6 covariance, ξ = (ω, v), left perturbation, world frame.
    pub covariance: Vec<Matrix6<f64>>,
    /// Gauss–Newton iterations done.
    pub iterations: usize,
    /// Σ eᵀΛe over priors and edges at the solution.
    pub chi2: f64,
    /// Redundancy: 6 × (priors + edges) − 6 × scans.
    pub redundancy: usize,
}

/// A joint Gaussian prior on the poses of N scans: means Pᵢ and the 6N×6N
/// covariance of the stacked left perturbations ξᵢ (Tᵢ = exp(ξᵢ)·Pᵢ), with
/// its information (eigenvalues of the covariance below 1e-12 are floored
/// there, so a pose known exactly — a mission's start — stays finite).
#[derive(Debug, Clone)]
pub struct JointPrior {
    means: Vec<Isometry3<f64>>,
    covariance: Mat<f64>,
    information: Mat<f64>,
}

/// The covariance eigenvalue floor of priors (see [`JointPrior`]).
const VARIANCE_FLOOR: f64 = 1e-12;

/// The inverse of a symmetric positive semi-definite 6×6 (covariance ↔
/// information) with its eigenvalues floored at [`VARIANCE_FLOOR`], so a
/// zero one (a quantity known exactly) stays finite; symmetric.
fn floored_inverse(m: &Matrix6<f64>) -> Matrix6<f64> {
    let eig = (0.5 * (m + m.transpose())).symmetric_eigen();
    let values = eig.eigenvalues.map(|v| 1.0 / v.max(VARIANCE_FLOOR));
    let inverse = eig.eigenvectors * Matrix6::from_diagonal(&values) * eig.eigenvectors.transpose();
    0.5 * (inverse + inverse.transpose())
}

impl JointPrior {
    /// The prior with `means` and their joint `covariance` (6N×6N,
    /// symmetric, finite).
    pub fn new(means: Vec<Isometry3<f64>>, covariance: Mat<f64>) -> Result<Self> {
        let n = 6 * means.len();
        if covariance.nrows() != n || covariance.ncols() != n || n == 0 {
            return Err(FusionError::OutOfRange {
                what: "joint prior covariance size".into(),
                value: covariance.nrows() as f64,
                expected: format!("6 × {} poses = {n} rows and columns", means.len()),
            });
        }
        let mut worst: f64 = 0.0;
        for i in 0..n {
            for j in 0..n {
                let v = covariance[(i, j)];
                if !v.is_finite() {
                    return Err(FusionError::OutOfRange {
                        what: format!("joint prior covariance entry ({i}, {j})"),
                        value: v,
                        expected: "finite".into(),
                    });
                }
                worst = worst.max((v - covariance[(j, i)]).abs());
            }
        }
        let scale = (0..n).map(|i| covariance[(i, i)].abs()).fold(0.0, f64::max);
        if worst > 1e-9 * scale.max(VARIANCE_FLOOR) {
            return Err(FusionError::Degenerate {
                what: format!("joint prior covariance is not symmetric ({worst:e})"),
            });
        }
        let eig = covariance
            .self_adjoint_eigen(Side::Lower)
            .map_err(|_| FusionError::Degenerate { what: "joint prior covariance eigendecomposition".into() })?;
        let (u, values) = (eig.U(), eig.S().column_vector());
        let scaled = Mat::<f64>::from_fn(n, n, |i, k| u[(i, k)] / values[k].max(VARIANCE_FLOOR));
        let information = &scaled * u.transpose();
        let information = Mat::from_fn(n, n, |i, j| 0.5 * (information[(i, j)] + information[(j, i)]));
        Ok(Self { means, covariance, information })
    }

    /// Independent priors as one joint prior (block diagonal).
    pub fn independent(priors: &[Prior]) -> Result<Self> {
        let n = priors.len();
        let mut covariance = Mat::<f64>::zeros(6 * n, 6 * n);
        for (i, p) in priors.iter().enumerate() {
            let block = floored_inverse(&p.information);
            for r in 0..6 {
                for c in 0..6 {
                    covariance[(6 * i + r, 6 * i + c)] = block[(r, c)];
                }
            }
        }
        Self::new(priors.iter().map(|p| p.target_from_source).collect(), covariance)
    }

    /// The prior CPS gives the scanners of N stations: each station's
    /// `world_from_scanner` as the mean, the stations' joint 4N×4N CPS
    /// covariance (order x, y, z, θ per station, with every cross-term)
    /// mapped through each station's [`cps_jacobian`], plus the tilt
    /// sensor's roll and pitch σ, independent per station.
    pub fn cps(
        world_from_scanner: &[Isometry3<f64>],
        poses: &[cps::ParentPose],
        tilts: &[scanner::Tilt],
        covariance: &Mat<f64>,
        tilt_sigma_rad: f64,
    ) -> Result<Self> {
        FusionError::require_non_negative("tilt sigma (rad)", tilt_sigma_rad)?;
        let n = world_from_scanner.len();
        if poses.len() != n || tilts.len() != n || covariance.nrows() != 4 * n || covariance.ncols() != 4 * n {
            return Err(FusionError::OutOfRange {
                what: "CPS joint prior sizes".into(),
                value: covariance.nrows() as f64,
                expected: format!("{n} poses and tilts and a {0}×{0} covariance", 4 * n),
            });
        }
        let jacobians: Vec<Matrix6<f64>> = poses.iter().zip(tilts).map(|(p, t)| cps_jacobian(p, t)).collect();
        let mut joint = Mat::<f64>::zeros(6 * n, 6 * n);
        for i in 0..n {
            for k in 0..n {
                // J_i[:, 0..4] · C_ik · J_k[:, 0..4]ᵀ (+ the tilt on the diagonal).
                let mut full = Matrix6::zeros();
                for r in 0..4 {
                    for c in 0..4 {
                        full[(r, c)] = covariance[(4 * i + r, 4 * k + c)];
                    }
                }
                if i == k {
                    full[(4, 4)] = tilt_sigma_rad * tilt_sigma_rad;
                    full[(5, 5)] = tilt_sigma_rad * tilt_sigma_rad;
                }
                let block = jacobians[i] * full * jacobians[k].transpose();
                for r in 0..6 {
                    for c in 0..6 {
                        joint[(6 * i + r, 6 * k + c)] = block[(r, c)];
                    }
                }
            }
        }
        let joint = Mat::from_fn(6 * n, 6 * n, |i, j| 0.5 * (joint[(i, j)] + joint[(j, i)]));
        Self::new(world_from_scanner.to_vec(), joint)
    }

    /// Number of poses.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when it holds no pose.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// The mean of pose i.
    pub fn mean(&self, i: usize) -> Isometry3<f64> {
        self.means[i]
    }

    /// cov(ξᵢ, ξⱼ), 6×6.
    pub fn covariance_block(&self, i: usize, j: usize) -> Matrix6<f64> {
        Matrix6::from_fn(|r, c| self.covariance[(6 * i + r, 6 * j + c)])
    }

    /// Pose i's marginal prior (mean and the inverse of its 6×6 block).
    pub fn marginal(&self, i: usize) -> Prior {
        Prior { target_from_source: self.means[i], information: floored_inverse(&self.covariance_block(i, i)) }
    }
}

/// The priors of a pose graph: one (or none) per scan, or a joint one.
#[derive(Debug, Clone, Copy)]
enum Priors<'a> {
    Each(&'a [Option<Prior>]),
    Joint(&'a JointPrior),
}

/// The prior on a scanner's `world_from_scanner` that a CPS pose gives:
/// the pose (x, y, z, θ) with its 4×4 covariance, and the tilt sensor's roll
/// and pitch with their standard deviation (independent of the pose).
///
/// With `world_from_scanner = T(p)·Rz(θ)·Ry(β)·Rx(α)·body_from_scanner`,
/// a change (dp, dθ, dβ, dα) moves it by ω = ẑ dθ + Rz(θ) ŷ dβ +
/// Rz(θ) Ry(β) x̂ dα and v = dp − ω × p (left perturbation; the lever arm
/// cancels). Variances below (1e-6)² are floored there so the information
/// stays finite when a quantity is known exactly.
pub fn cps_prior(
    world_from_scanner: &Isometry3<f64>,
    pose: &cps::ParentPose,
    covariance: &nalgebra::Matrix4<f64>,
    tilt: &scanner::Tilt,
    tilt_sigma_rad: f64,
) -> Result<Prior> {
    FusionError::require_non_negative("tilt sigma (rad)", tilt_sigma_rad)?;
    if !covariance.iter().all(|v| v.is_finite()) {
        return Err(FusionError::OutOfRange {
            what: "CPS pose covariance".into(),
            value: covariance.amax(),
            expected: "finite".into(),
        });
    }
    let jac = cps_jacobian(pose, tilt);
    let mut full = Matrix6::zeros();
    full.fixed_view_mut::<4, 4>(0, 0).copy_from(covariance);
    full[(4, 4)] = tilt_sigma_rad * tilt_sigma_rad;
    full[(5, 5)] = tilt_sigma_rad * tilt_sigma_rad;
    let information = floored_inverse(&(jac * full * jac.transpose()));
    Ok(Prior { target_from_source: *world_from_scanner, information })
}

/// ∂ξ/∂(x, y, z, θ, pitch, roll) of `world_from_scanner` (see [`cps_prior`]).
pub fn cps_jacobian(pose: &cps::ParentPose, tilt: &scanner::Tilt) -> Matrix6<f64> {
    let rz = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), pose.heading_rad);
    let ry = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), tilt.pitch_rad);
    let columns = [Vector3::z(), rz * Vector3::y(), rz * ry * Vector3::x()];
    let p = pose.position.coords;
    let mut j = Matrix6::zeros();
    for (k, w) in columns.iter().enumerate() {
        let col = 3 + k;
        j.fixed_view_mut::<3, 1>(0, col).copy_from(w);
        j.fixed_view_mut::<3, 1>(3, col).copy_from(&(-w.cross(&p)));
    }
    j.fixed_view_mut::<3, 3>(3, 0).copy_from(&Matrix3::identity());
    j
}

/// Adjusts `init` (every scan's `world_from_scan`) to the priors
/// (`priors[i]` on scan i, at least one) and the edges, by Gauss–Newton
/// until a step moves every pose by less than 1e-9 m and 1e-9 rad (at most
/// `max_iterations` steps).
pub fn optimize(
    init: &[Isometry3<f64>],
    priors: &[Option<Prior>],
    edges: &[Edge],
    max_iterations: usize,
) -> Result<GraphResult> {
    let n = init.len();
    if priors.len() != n {
        return Err(FusionError::OutOfRange {
            what: "pose graph priors".into(),
            value: priors.len() as f64,
            expected: format!("one entry (or None) per scan: {n}"),
        });
    }
    if priors.iter().all(Option::is_none) {
        return Err(FusionError::Degenerate { what: "pose graph without any prior: the world frame is free".into() });
    }
    solve(init, Priors::Each(priors), edges, max_iterations)
}

/// [`optimize`] with a joint prior on every scan.
pub fn optimize_joint(
    init: &[Isometry3<f64>],
    prior: &JointPrior,
    edges: &[Edge],
    max_iterations: usize,
) -> Result<GraphResult> {
    if prior.len() != init.len() {
        return Err(FusionError::OutOfRange {
            what: "joint prior poses".into(),
            value: prior.len() as f64,
            expected: format!("one per scan: {}", init.len()),
        });
    }
    solve(init, Priors::Joint(prior), edges, max_iterations)
}

fn solve(init: &[Isometry3<f64>], priors: Priors<'_>, edges: &[Edge], max_iterations: usize) -> Result<GraphResult> {
    let n = init.len();
    for e in edges {
        if e.target >= n || e.source >= n || e.target == e.source {
            return Err(FusionError::OutOfRange {
                what: format!("pose graph edge {} → {}", e.source, e.target),
                value: e.source.max(e.target) as f64,
                expected: format!("two different scans below {n}"),
            });
        }
        if !e.information.iter().all(|v| v.is_finite()) {
            return Err(FusionError::OutOfRange {
                what: format!("information of edge {} → {}", e.source, e.target),
                value: e.information.amax(),
                expected: "finite".into(),
            });
        }
    }
    let mut poses = init.to_vec();
    let mut iterations = 0;
    loop {
        let (h, b, _) = normal_equations(&poses, priors, edges);
        let llt = h.llt(Side::Lower).map_err(|_| FusionError::Degenerate {
            what: "pose graph normal equations (a scan without a prior or a path of edges to one)".into(),
        })?;
        let dx = llt.solve(&b);
        iterations += 1;
        let mut largest: f64 = 0.0;
        for (i, pose) in poses.iter_mut().enumerate() {
            let d = Vector6::from_fn(|k, _| -dx[(6 * i + k, 0)]);
            largest = largest.max(d.amax());
            *pose = exp(&d) * *pose;
        }
        if !largest.is_finite() {
            return Err(FusionError::Degenerate { what: "pose graph step is not finite".into() });
        }
        if largest < 1e-9 || iterations >= max_iterations {
            let (h, _, chi2_after) = normal_equations(&poses, priors, edges);
            let inverse = h
                .llt(Side::Lower)
                .map_err(|_| FusionError::Degenerate { what: "pose graph information at the solution".into() })?
                .inverse();
            let covariance = (0..n)
                .map(|i| {
                    let m = Matrix6::from_fn(|r, c| inverse[(6 * i + r, 6 * i + c)]);
                    0.5 * (m + m.transpose())
                })
                .collect();
            let prior_count = match priors {
                Priors::Each(each) => each.iter().flatten().count(),
                Priors::Joint(joint) => joint.len(),
            };
            let observations = 6 * (prior_count + edges.len());
            return Ok(GraphResult {
                world_from_scan: poses,
                covariance,
                iterations,
                chi2: chi2_after,
                redundancy: observations.saturating_sub(6 * n),
            });
        }
    }
}

/// The poses' covariances when the edges' errors have `covariances`
/// (`None`: as the edge's information says), while the adjustment weighs
/// them by their information: H⁻¹·M·H⁻¹ with H the normal matrix at
/// `poses` and M = Σ JᵀΛ·C·ΛJ over the edges (JᵀΛJ for `None`) plus the
/// priors' information — the covariance of a least-squares estimate
/// whose weights are not the inverse of its observations' covariance
/// (with C = Λ⁻¹ throughout, H⁻¹, [`optimize`]'s). `poses` must be
/// [`optimize`]'s solution with these priors and edges.
pub fn sandwich_covariance(
    poses: &[Isometry3<f64>],
    priors: &[Option<Prior>],
    edges: &[Edge],
    covariances: &[Option<Matrix6<f64>>],
) -> Result<Vec<Matrix6<f64>>> {
    Ok(sandwich_joint(poses, priors, edges, covariances)?.diagonal())
}

/// [`sandwich_covariance`] with the poses' cross-covariances: the whole
/// H⁻¹·M·H⁻¹.
pub fn sandwich_joint(
    poses: &[Isometry3<f64>],
    priors: &[Option<Prior>],
    edges: &[Edge],
    covariances: &[Option<Matrix6<f64>>],
) -> Result<JointCovariance> {
    let n = poses.len();
    if covariances.len() != edges.len() {
        return Err(FusionError::OutOfRange {
            what: "edge covariances".into(),
            value: covariances.len() as f64,
            expected: format!("one per edge: {}", edges.len()),
        });
    }
    let (h, _, _) = normal_equations(poses, Priors::Each(priors), edges);
    let inverse = h
        .llt(Side::Lower)
        .map_err(|_| FusionError::Degenerate { what: "pose graph information at the solution".into() })?
        .inverse();
    // M: the priors' and the edges' own information, then each edge with
    // a covariance of its own in place of its information.
    let (mut m, _, _) = normal_equations(poses, Priors::Each(priors), &[]);
    for (e, c) in edges.iter().zip(covariances) {
        let l = &e.information;
        let middle = c.map_or(*l, |c| l * c * l);
        let js = adjoint(&poses[e.target].inverse());
        let blocks = [
            (e.source, e.source, 1.0),
            (e.target, e.target, 1.0),
            (e.source, e.target, -1.0),
            (e.target, e.source, -1.0),
        ];
        let jmj = js.transpose() * middle * js;
        for (i, j, sign) in blocks {
            for r in 0..6 {
                for k in 0..6 {
                    m[(6 * i + r, 6 * j + k)] += sign * jmj[(r, k)];
                }
            }
        }
    }
    let p = &inverse * &m * &inverse;
    Ok(JointCovariance { matrix: Mat::from_fn(6 * n, 6 * n, |i, j| 0.5 * (p[(i, j)] + p[(j, i)])) })
}

/// The joint covariance of N poses' stacked left perturbations ξᵢ (6N×6N,
/// symmetric): block (i, j) is cov(ξᵢ, ξⱼ) — each pose's covariance on the
/// diagonal, and off it what a pose's error shares with another's (the
/// relative pose between two scans placed by the same links is known far
/// better than either alone).
#[derive(Debug, Clone, PartialEq)]
pub struct JointCovariance {
    matrix: Mat<f64>,
}

impl JointCovariance {
    /// N poses known exactly.
    pub fn zeros(n: usize) -> Self {
        Self { matrix: Mat::zeros(6 * n, 6 * n) }
    }

    /// The number of poses.
    pub fn len(&self) -> usize {
        self.matrix.nrows() / 6
    }

    /// Whether it has no pose.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// cov(ξᵢ, ξⱼ), 6×6.
    pub fn block(&self, i: usize, j: usize) -> Matrix6<f64> {
        Matrix6::from_fn(|r, c| self.matrix[(6 * i + r, 6 * j + c)])
    }

    /// Adds `m` to block (i, j) — and its transpose to block (j, i), so the
    /// whole stays symmetric (`m` once on the diagonal, which must be
    /// symmetric itself).
    pub fn add(&mut self, i: usize, j: usize, m: &Matrix6<f64>) {
        for r in 0..6 {
            for c in 0..6 {
                self.matrix[(6 * i + r, 6 * j + c)] += m[(r, c)];
                if i != j {
                    self.matrix[(6 * j + c, 6 * i + r)] += m[(r, c)];
                }
            }
        }
    }

    /// The covariance of ξ_b − ξₐ, Cₐₐ + C_bb − Cₐ_b − C_bₐ: what scan `b`'s
    /// pose relative to `a`'s is uncertain by (first order, in the
    /// perturbations' frame).
    pub fn relative(&self, a: usize, b: usize) -> Matrix6<f64> {
        self.block(a, a) + self.block(b, b) - self.block(a, b) - self.block(b, a)
    }

    /// The stacked `xi` of poses `from`.. (one ξ per pose, the first
    /// `from` left out) in these poses' joint σ: ξᵀ·C⁻¹·ξ; `None` where
    /// their covariance is singular.
    pub fn chi2(&self, xi: &[Vector6<f64>], from: usize) -> Option<f64> {
        let n = self.len().min(xi.len()).saturating_sub(from);
        if n == 0 {
            return Some(0.0);
        }
        let sub = Mat::<f64>::from_fn(6 * n, 6 * n, |r, c| self.matrix[(6 * from + r, 6 * from + c)]);
        let rhs = Mat::<f64>::from_fn(6 * n, 1, |r, _| xi[from + r / 6][r % 6]);
        let solved = sub.llt(Side::Lower).ok()?.solve(&rhs);
        let chi2 = (0..6 * n).map(|r| rhs[(r, 0)] * solved[(r, 0)]).sum::<f64>();
        chi2.is_finite().then_some(chi2)
    }

    /// Every pose's own covariance (the diagonal blocks).
    pub fn diagonal(&self) -> Vec<Matrix6<f64>> {
        (0..self.len()).map(|i| self.block(i, i)).collect()
    }

    /// Pose `i` known exactly: its rows and columns zero (the pose that
    /// holds the frame, against which the others' are).
    pub fn hold(&mut self, i: usize) {
        for k in 0..self.matrix.nrows() {
            for r in 6 * i..6 * i + 6 {
                self.matrix[(r, k)] = 0.0;
                self.matrix[(k, r)] = 0.0;
            }
        }
    }

    /// `self` less `other`, block by block (the same number of poses).
    pub fn less(&self, other: &Self) -> Self {
        Self { matrix: &self.matrix - &other.matrix }
    }

    /// The ξ of every pose turned by `ad` (ξ' = ad·ξ): each block
    /// ad·C·adᵀ.
    pub fn turned(&self, ad: &Matrix6<f64>) -> Self {
        let n = self.len();
        let mut out = Self::zeros(n);
        // Block (j, i) is block (i, j) transposed: `add` writes both.
        for i in 0..n {
            for j in 0..=i {
                out.add(i, j, &(ad * self.block(i, j) * ad.transpose()));
            }
        }
        out
    }

    /// The matrix, row by row.
    pub fn rows(&self) -> Vec<Vec<f64>> {
        (0..self.matrix.nrows()).map(|r| (0..self.matrix.ncols()).map(|c| self.matrix[(r, c)]).collect()).collect()
    }
}

/// H = Σ JᵀΛJ, b = Σ JᵀΛe and Σ eᵀΛe at `poses`.
fn normal_equations(poses: &[Isometry3<f64>], priors: Priors<'_>, edges: &[Edge]) -> (Mat<f64>, Mat<f64>, f64) {
    let n = poses.len();
    let mut h = Mat::<f64>::zeros(6 * n, 6 * n);
    let mut b = Mat::<f64>::zeros(6 * n, 1);
    let mut chi2 = 0.0;
    let add = |h: &mut Mat<f64>, i: usize, j: usize, m: &Matrix6<f64>| {
        for r in 0..6 {
            for c in 0..6 {
                h[(6 * i + r, 6 * j + c)] += m[(r, c)];
            }
        }
    };
    match priors {
        Priors::Each(each) => {
            for (i, prior) in each.iter().enumerate() {
                if let Some(p) = prior {
                    let e = left_difference(&poses[i], &p.target_from_source);
                    chi2 += (e.transpose() * p.information * e)[(0, 0)];
                    add(&mut h, i, i, &p.information);
                    let g = p.information * e;
                    for r in 0..6 {
                        b[(6 * i + r, 0)] += g[r];
                    }
                }
            }
        }
        Priors::Joint(joint) => {
            let mut e = Mat::<f64>::zeros(6 * n, 1);
            for (i, pose) in poses.iter().enumerate() {
                let ei = left_difference(pose, &joint.means[i]);
                for r in 0..6 {
                    e[(6 * i + r, 0)] = ei[r];
                }
            }
            let g = &joint.information * &e;
            chi2 += (e.transpose() * &g)[(0, 0)];
            h += &joint.information;
            b += &g;
        }
    }
    for edge in edges {
        let (t, s) = (edge.target, edge.source);
        let inv_t = poses[t].inverse();
        let e = left_difference(&(inv_t * poses[s]), &edge.target_from_source);
        chi2 += (e.transpose() * edge.information * e)[(0, 0)];
        let js = adjoint(&inv_t);
        let jt = -js;
        let l = &edge.information;
        add(&mut h, s, s, &(js.transpose() * l * js));
        add(&mut h, t, t, &(jt.transpose() * l * jt));
        add(&mut h, s, t, &(js.transpose() * l * jt));
        add(&mut h, t, s, &(jt.transpose() * l * js));
        let (gs, gt) = (js.transpose() * l * e, jt.transpose() * l * e);
        for r in 0..6 {
            b[(6 * s + r, 0)] += gs[r];
            b[(6 * t + r, 0)] += gt[r];
        }
    }
    (h, b, chi2)
}

#[cfg(test)]
mod tests {
    use nalgebra::Point3;
    use nalgebra::Translation3;

    use super::*;

    /// The CPS Jacobian against central differences of the composed pose.
    #[test]
    fn cps_jacobian_matches_finite_differences() {
        let pose = cps::ParentPose::new(12.5, -3.25, 0.75, 2.2);
        let tilt = scanner::Tilt { roll_rad: 0.03, pitch_rad: -0.05 };
        let lever =
            Isometry3::from_parts(Translation3::new(0.1, -0.2, 0.4), UnitQuaternion::from_euler_angles(0.1, 0.0, 0.3));
        let world = |q: &[f64; 6]| {
            let p = cps::ParentPose { position: Point3::new(q[0], q[1], q[2]), heading_rad: q[3] };
            scanner::Tilt { roll_rad: q[5], pitch_rad: q[4] }.world_from_body(&p) * lever
        };
        let base = [pose.position.x, pose.position.y, pose.position.z, pose.heading_rad, tilt.pitch_rad, tilt.roll_rad];
        let j = cps_jacobian(&pose, &tilt);
        let h = 1e-5;
        for k in 0..6 {
            let (mut plus, mut minus) = (base, base);
            plus[k] += h;
            minus[k] -= h;
            let w0 = world(&base);
            let fd = (left_difference(&world(&plus), &w0) - left_difference(&world(&minus), &w0)) / (2.0 * h);
            let col = j.column(k);
            assert!((fd - col).amax() < 1e-7, "column {k}: {fd} vs {col}");
        }
    }

    /// The CPS joint prior: each marginal is the per-station prior
    /// [`cps_prior`] gives, and a cross block is J₀·C₀₁·J₁ᵀ (no tilt term:
    /// the tilt readings are independent).
    #[test]
    fn cps_joint_prior_blocks() {
        let poses = [cps::ParentPose::new(1.0, 2.0, 0.5, 0.3), cps::ParentPose::new(5.0, 2.5, 0.4, 0.35)];
        let tilts =
            [scanner::Tilt { roll_rad: 0.01, pitch_rad: -0.02 }, scanner::Tilt { roll_rad: 0.0, pitch_rad: 0.01 }];
        let scanners: Vec<Isometry3<f64>> = poses.iter().zip(&tilts).map(|(p, t)| t.world_from_body(p)).collect();
        let c00 = nalgebra::Matrix4::from_diagonal(&nalgebra::Vector4::new(1e-6, 2e-6, 4e-6, 1e-8));
        let c11 = 3.0 * c00;
        let c01 = 0.8 * c00;
        let mut joint = Mat::<f64>::zeros(8, 8);
        for r in 0..4 {
            for c in 0..4 {
                joint[(r, c)] = c00[(r, c)];
                joint[(4 + r, 4 + c)] = c11[(r, c)];
                joint[(r, 4 + c)] = c01[(r, c)];
                joint[(4 + c, r)] = c01[(r, c)];
            }
        }
        let sigma = 1e-4;
        let prior = JointPrior::cps(&scanners, &poses, &tilts, &joint, sigma).expect("prior");
        for (i, c) in [c00, c11].iter().enumerate() {
            let single = cps_prior(&scanners[i], &poses[i], c, &tilts[i], sigma).expect("single");
            let m = prior.marginal(i);
            assert_eq!(m.target_from_source, scanners[i]);
            assert!((m.information - single.information).amax() < 1e-6 * single.information.amax());
        }
        let j0 = cps_jacobian(&poses[0], &tilts[0]).fixed_columns::<4>(0).into_owned();
        let j1 = cps_jacobian(&poses[1], &tilts[1]).fixed_columns::<4>(0).into_owned();
        let expected = j0 * c01 * j1.transpose();
        assert!((prior.covariance_block(0, 1) - expected).amax() < 1e-15);
        assert!(JointPrior::cps(&scanners, &poses[..1], &tilts, &joint, sigma).is_err());
    }

    /// Edges whose errors are not what their information says: the
    /// sandwich is the scatter of the re-solved poses (Monte Carlo), and
    /// with every edge as its information says it is `optimize`'s own.
    #[test]
    fn the_sandwich_is_what_monte_carlo_scatters() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let pose = |x: f64, y: f64, yaw: f64| {
            Isometry3::from_parts(Translation3::new(x, y, 0.1 * x), UnitQuaternion::from_euler_angles(0.01, -0.02, yaw))
        };
        let truth = [pose(0.0, 0.0, 0.0), pose(4.0, 0.5, 0.3), pose(7.5, 3.0, 0.9), pose(3.0, 5.0, -0.4)];
        let information = |k: f64| {
            let mut m = Matrix6::from_diagonal(&Vector6::new(4e6, 3e6, 5e6, 1e6 * k, 2e6, 8e5));
            m[(0, 4)] = 3e5;
            m[(4, 0)] = 3e5;
            m
        };
        // A ring and a diagonal; the errors of two edges are 4× their
        // information's variance, one has a pull of 3 mm besides.
        let pairs = [(0, 1), (1, 2), (2, 3), (3, 0), (0, 2)];
        let exact: Vec<Edge> = pairs
            .iter()
            .enumerate()
            .map(|(k, &(t, s))| Edge {
                target: t,
                source: s,
                target_from_source: truth[t].inverse() * truth[s],
                information: information(1.0 + k as f64),
            })
            .collect();
        let pull = Vector6::new(1e-4, -2e-4, 0.0, 2e-3, 1e-3, -2e-3);
        let covariances: Vec<Option<Matrix6<f64>>> = exact
            .iter()
            .enumerate()
            .map(|(k, e)| {
                let c = e.information.try_inverse().expect("invertible");
                match k {
                    1 | 3 => Some(4.0 * c),
                    4 => Some(c + pull * pull.transpose()),
                    _ => None,
                }
            })
            .collect();
        let priors =
            [Some(Prior { target_from_source: truth[0], information: Matrix6::identity() * 1e12 }), None, None, None];
        let plain = optimize(&truth, &priors, &exact, 50).expect("solves").covariance;
        let same = sandwich_covariance(&truth, &priors, &exact, &[None; 5]).expect("sandwich");
        for i in 1..4 {
            assert!((same[i] - plain[i]).amax() < 1e-9 * plain[i].amax(), "pose {i}");
        }
        let joint = sandwich_joint(&truth, &priors, &exact, &covariances).expect("sandwich");
        let predicted = joint.diagonal();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let draws = 2000;
        let mut scatter = vec![Matrix6::zeros(); 4];
        let mut stacked = nalgebra::DMatrix::<f64>::zeros(18, 18);
        for _ in 0..draws {
            let edges: Vec<Edge> = exact
                .iter()
                .zip(&covariances)
                .map(|(e, c)| {
                    let c = c.unwrap_or_else(|| e.information.try_inverse().expect("invertible"));
                    let l = c.cholesky().expect("SPD").l();
                    let z = Vector6::from_fn(|_, _| StandardNormal.sample(&mut rng));
                    Edge { target_from_source: exp(&(l * z)) * e.target_from_source, ..*e }
                })
                .collect();
            let solved = optimize(&truth, &priors, &edges, 20).expect("solves").world_from_scan;
            for i in 0..4 {
                let u = left_difference(&solved[i], &truth[i]);
                scatter[i] += u * u.transpose() / f64::from(draws);
            }
            let u = nalgebra::DVector::from_iterator(
                18,
                (1..4).flat_map(|i| left_difference(&solved[i], &truth[i]).iter().copied().collect::<Vec<_>>()),
            );
            stacked += &u * u.transpose() / f64::from(draws);
        }
        // The three free poses together: the joint covariance whitens
        // their stacked scatter within e^±0.35 (18 dimensions at 2000
        // draws spread it about e^±0.2); taken as sharing nothing (its
        // diagonal blocks alone), far off.
        let whiten_all = |c: &nalgebra::DMatrix<f64>| {
            let li = c.clone().cholesky().expect("SPD").l().try_inverse().expect("invertible");
            (&li * &stacked * li.transpose())
                .symmetric_eigen()
                .eigenvalues
                .iter()
                .map(|v| v.ln().abs())
                .fold(0.0, f64::max)
        };
        let whole = nalgebra::DMatrix::from_fn(18, 18, |r, c| joint.block(1 + r / 6, 1 + c / 6)[(r % 6, c % 6)]);
        let apart = nalgebra::DMatrix::from_fn(18, 18, |r, c| {
            if r / 6 == c / 6 { joint.block(1 + r / 6, 1 + c / 6)[(r % 6, c % 6)] } else { 0.0 }
        });
        assert!(whiten_all(&whole) < 0.35, "joint off by e^{}", whiten_all(&whole));
        assert!(whiten_all(&apart) > 1.0, "without the cross-covariances off by only e^{}", whiten_all(&apart));
        for i in 1..4 {
            // Whitened by the prediction, the scatter's variances within
            // e^±0.2 (sampling spreads them about e^±0.1 at 2000 draws) —
            // and the plain covariance is measurably off.
            let white = |c: &Matrix6<f64>| {
                let li = c.cholesky().expect("SPD").l().try_inverse().expect("invertible");
                (li * scatter[i] * li.transpose())
                    .symmetric_eigen()
                    .eigenvalues
                    .iter()
                    .map(|v| v.ln().abs())
                    .fold(0.0, f64::max)
            };
            assert!(white(&predicted[i]) < 0.2, "pose {i}: sandwich off by e^{}", white(&predicted[i]));
            assert!(white(&plain[i]) > 0.5, "pose {i}: plain off by only e^{}", white(&plain[i]));
        }
    }

    /// A joint covariance's blocks: added symmetric, held, turned.
    #[test]
    fn a_joint_covariance_keeps_its_blocks_symmetric() {
        let mut j = JointCovariance::zeros(3);
        let a = Matrix6::from_fn(|r, c| (r * 6 + c) as f64);
        let d = Matrix6::from_diagonal(&Vector6::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0));
        j.add(2, 1, &a);
        j.add(1, 1, &d);
        j.add(0, 2, &d);
        assert_eq!((j.block(2, 1), j.block(1, 2), j.block(1, 1)), (a, a.transpose(), d));
        let t = adjoint(&Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_euler_angles(0.3, -0.2, 1.4),
        ));
        let turned = j.turned(&t);
        assert!((turned.block(2, 1) - t * a * t.transpose()).amax() < 1e-12 * a.amax());
        assert_eq!(turned.diagonal().len(), 3);
        j.hold(2);
        assert_eq!(
            (j.block(2, 1), j.block(0, 2), j.block(2, 2)),
            (Matrix6::zeros(), Matrix6::zeros(), Matrix6::zeros())
        );
        assert_eq!(j.block(1, 1), d);
    }

    /// The adjoint moves a left perturbation through a transform.
    #[test]
    fn adjoint_conjugates() {
        let t =
            Isometry3::from_parts(Translation3::new(3.0, -1.0, 2.0), UnitQuaternion::from_euler_angles(0.2, -0.4, 1.1));
        // First order: the second-order remainder is ~|ξ|²·|t| ≈ 4e-10.
        let xi = Vector6::new(1e-5, -2e-5, 5e-6, 2e-5, 1e-5, -3e-5);
        let lhs = t * exp(&xi) * t.inverse();
        let rhs = exp(&(adjoint(&t) * xi));
        assert!(left_difference(&lhs, &rhs).amax() < 2e-9);
        // and it is not the identity map.
        assert!(left_difference(&lhs, &exp(&xi)).amax() > 1e-5);
    }
}
