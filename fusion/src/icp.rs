//! ICP (seed 000 §4): point-to-point with Horn's closed-form rotation and
//! point-to-plane with normals from the k nearest neighbours, nearest
//! neighbours through a `kiddo` k-d tree built once per target (and, from
//! the second iteration, mostly through each target point's
//! `Neighbourhood` instead), a maximum correspondence distance and a
//! coarse-to-fine schedule.
//!
//! **Covariance convention.** [`IcpResult::information`] is the 6×6 inverse
//! covariance of the error ξ = (ω, v) — rotation first, then translation — in
//! the **target** frame with **left** perturbation:
//! `target_from_source_true = exp(ξ) · target_from_source`, so a source
//! point p maps to `T̂p + ω × T̂p + v`. It is `Jᵀ J / σ̂²` at the last
//! linearisation point (within the tolerances of the solution when
//! converged), with σ̂² the residual variance per scalar residual.

use kiddo::SquaredEuclidean;
use nalgebra::{
    Isometry3, Matrix3, Matrix4, Matrix6, Point3, SymmetricEigen, Translation3, UnitQuaternion, Vector3, Vector6,
};
use rayon::prelude::*;
use std::sync::OnceLock;

use crate::error::{FusionError, Result};

/// The error metric.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Point-to-point, closed form (Horn's unit quaternion).
    PointToPoint,
    /// Point-to-plane, Gauss–Newton on the target's normals.
    PointToPlane,
}

/// ICP settings (one flat struct, documented defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcpConfig {
    /// Error metric. Default point-to-plane.
    pub method: Method,
    /// Pairs farther apart than this are ignored, metres. Default 1.0.
    pub max_correspondence_m: f64,
    /// Iteration cap. Default 50.
    pub max_iterations: usize,
    /// Converged when an update moves less than this, metres. Default 1e-5.
    pub translation_tolerance_m: f64,
    /// Converged when an update turns less than this, radians. Default 1e-5.
    pub rotation_tolerance_rad: f64,
    /// Neighbours for normal estimation. Default 10.
    pub normal_neighbours: usize,
    /// Robust kernel on the residuals. Default none (least squares).
    pub kernel: Kernel,
    /// Keep the estimate after every iteration in [`IcpResult::trace`]
    /// (for viewing the registration). Default false.
    pub trace: bool,
    /// Leave out a pair whose target normal faces away from the source
    /// scanner ([`source_viewpoint`](Self::source_viewpoint)): the source
    /// cannot have seen that side of the surface, so the pair joins two
    /// faces of a thin object (a door reveal, a pilaster), which pulls a
    /// moving scanner back towards where it came from. Needs a target with
    /// oriented normals ([`Target::orient_normals_towards`]). Default false.
    pub reject_back_faces: bool,
    /// Where the source's scanner stands in the source frame, for
    /// `reject_back_faces` (a scan kept in a robot's body frame has its
    /// scanner at the head's lever arm). Default the origin.
    pub source_viewpoint: Point3<f64>,
}

/// A robust kernel, applied by iteratively reweighted least squares: each
/// pair's weight is recomputed from its residual every iteration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kernel {
    /// Plain least squares (weight 1).
    None,
    /// Huber: weight 1 up to `width_m`, `width_m / |r|` beyond.
    Huber {
        /// The kernel width, metres.
        width_m: f64,
    },
}

impl Kernel {
    fn weight(self, residual: f64) -> f64 {
        match self {
            Kernel::None => 1.0,
            Kernel::Huber { width_m } => {
                let a = residual.abs();
                if a <= width_m { 1.0 } else { width_m / a }
            }
        }
    }
}

impl Default for IcpConfig {
    fn default() -> Self {
        Self {
            method: Method::PointToPlane,
            max_correspondence_m: 1.0,
            max_iterations: 50,
            translation_tolerance_m: 1e-5,
            rotation_tolerance_rad: 1e-5,
            normal_neighbours: 10,
            kernel: Kernel::None,
            trace: false,
            reject_back_faces: false,
            source_viewpoint: Point3::origin(),
        }
    }
}

/// The k-d tree of a target: kiddo's Eytzinger-ordered stems with flat
/// per-axis leaf arrays of at most 16 points. Against kiddo's default
/// `ImmutableKdTree` (arena leaves of 32) it answers ICP's nearest-neighbour
/// queries about a third faster (BENCHMARKS.md, "the k-d tree choice";
/// public so the benchmark measures this very layout).
pub type KdTree = kiddo::KdTree<f32, u32, kiddo::Eytzinger, kiddo::FlatVec<f32, u32, 3, 16>, 3, 16>;

/// How many nearest other target points a `Neighbourhood` keeps.
const CERTIFICATE_NEIGHBOURS: usize = 10;

/// The nearest other points of a target point q and r², r being the
/// distance to the farthest of them: every other target point is at least
/// r from q. So a query p with |p − q| ≤ r/2 has its nearest neighbour
/// among q and these points (any other point k has
/// |p − q_k| ≥ |q_k − q| − |p − q| ≥ r − r/2 ≥ |p − q|).
///
/// ICP's correspondences move little from one iteration to the next: a
/// source point is checked against its last partner's neighbourhood first
/// and goes to the k-d tree only when that certificate fails — on the 3DTK
/// pair for about 30 % of the points — with exactly the tree's answer
/// either way.
#[derive(Debug, Clone, Copy)]
struct Neighbourhood {
    points: [u32; CERTIFICATE_NEIGHBOURS],
    len: u8,
    /// (r/2)²: the certificate holds for |p − q|² ≤ this.
    reach_sq: f32,
}

impl Neighbourhood {
    /// From a k-nearest query around point `j` (sorted by distance,
    /// normally with `j` itself first), `all` when it returned every point.
    fn new(j: usize, found: impl Iterator<Item = (u32, f32)>, all: bool) -> Self {
        let mut n = Self { points: [0; CERTIFICATE_NEIGHBOURS], len: 0, reach_sq: 0.0 };
        let mut farthest = 0.0f32;
        for (k, d2) in found.filter(|&(k, _)| k as usize != j).take(CERTIFICATE_NEIGHBOURS) {
            n.points[usize::from(n.len)] = k;
            n.len += 1;
            farthest = farthest.max(d2);
        }
        // Every point left out is at least as far as the farthest kept one
        // (the query is sorted), unless nothing was left out at all.
        let kept_all = all && usize::from(n.len) < CERTIFICATE_NEIGHBOURS;
        n.reach_sq = if kept_all { f32::INFINITY } else { farthest / 4.0 };
        n
    }
}

/// A target cloud prepared for ICP: its k-d tree, (for point-to-plane)
/// unit normals, and each point's `Neighbourhood`, filled in as ICP
/// first needs it (or with the normals, from the same query).
#[derive(Debug)]
pub struct Target {
    points: Vec<[f32; 3]>,
    normals: Vec<Vector3<f64>>,
    tree: KdTree,
    neighbourhoods: Vec<OnceLock<Neighbourhood>>,
    /// The normals point to the side the target's scanner saw.
    oriented: bool,
}

impl Target {
    /// Builds the tree and, when `normal_neighbours > 0`, PCA normals.
    pub fn new(points: &[Point3<f32>], normal_neighbours: usize) -> Result<Self> {
        let points: Vec<[f32; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        if points.len() < 6 {
            return Err(FusionError::OutOfRange {
                what: "target point count".into(),
                value: points.len() as f64,
                expected: "≥ 6".into(),
            });
        }
        let tree = KdTree::new_from_slice(&points)
            .map_err(|e| FusionError::Degenerate { what: format!("k-d tree: {e:?}") })?;
        let mut t = Self { points, normals: Vec::new(), tree, neighbourhoods: Vec::new(), oriented: false };
        if normal_neighbours > 0 {
            (t.normals, t.neighbourhoods) = t.estimate_normals(normal_neighbours.max(3));
        } else {
            t.neighbourhoods = std::iter::repeat_with(OnceLock::new).take(t.points.len()).collect();
        }
        Ok(t)
    }

    /// A target from points and their unit normals (estimated elsewhere, e.g.
    /// once per scan in its own frame and then moved with the scan); no
    /// normals (an empty vector) make a point-to-point target.
    pub fn with_normals(points: &[Point3<f32>], normals: Vec<Vector3<f64>>) -> Result<Self> {
        if !normals.is_empty() && normals.len() != points.len() {
            return Err(FusionError::OutOfRange {
                what: "normal count".into(),
                value: normals.len() as f64,
                expected: format!("one per point ({})", points.len()),
            });
        }
        let mut t = Self::new(points, 0)?;
        t.normals = normals;
        Ok(t)
    }

    /// [`with_normals`](Self::with_normals) for normals already oriented
    /// towards the scanners that saw their points (e.g. scans' oriented
    /// normals moved into one frame with their scans).
    pub fn with_oriented_normals(points: &[Point3<f32>], normals: Vec<Vector3<f64>>) -> Result<Self> {
        let mut t = Self::with_normals(points, normals)?;
        t.oriented = !t.normals.is_empty();
        Ok(t)
    }

    /// Turns every normal towards `viewpoint` (the scanner that took the
    /// points, in their frame): nᵀ(viewpoint − q) ≥ 0. Does nothing
    /// without normals.
    pub fn orient_normals_towards(&mut self, viewpoint: &Point3<f64>) {
        for (n, q) in self.normals.iter_mut().zip(&self.points) {
            if n.dot(&(viewpoint.coords - point(q))) < 0.0 {
                *n = -*n;
            }
        }
        self.oriented = !self.normals.is_empty();
    }

    /// True when the normals are oriented towards the scanner.
    pub fn has_oriented_normals(&self) -> bool {
        self.oriented
    }

    /// The points, in the order of [`normals`](Self::normals).
    pub fn points(&self) -> impl ExactSizeIterator<Item = Point3<f32>> + '_ {
        self.points.iter().map(|p| Point3::new(p[0], p[1], p[2]))
    }

    /// How many `source` points, mapped by `target_from_source`, have a
    /// target point within `max_distance_m` (the correspondences ICP would
    /// use there).
    pub fn correspondences(
        &self,
        source: &[Point3<f32>],
        target_from_source: &Isometry3<f64>,
        max_distance_m: f64,
    ) -> usize {
        let max_sq = max_distance_m * max_distance_m;
        let m: Isometry3<f32> = target_from_source.cast();
        source
            .par_iter()
            .filter(|p| {
                let q = m * *p;
                self.nearest(&[q.x, q.y, q.z]).1 <= max_sq
            })
            .count()
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when empty (never, by construction).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Normals (empty when not estimated).
    pub fn normals(&self) -> &[Vector3<f64>] {
        &self.normals
    }

    /// PCA normals from the `k` nearest points, and each point's
    /// neighbourhood from the same query.
    fn estimate_normals(&self, k: usize) -> (Vec<Vector3<f64>>, Vec<OnceLock<Neighbourhood>>) {
        let n = self.points.len();
        let k = std::num::NonZero::new(k.min(n)).unwrap_or(std::num::NonZero::<usize>::MIN);
        self.points
            .par_iter()
            .enumerate()
            .map(|(j, p)| {
                let nn = self.tree.query(p).nearest_n::<SquaredEuclidean<f32>>(k).execute();
                let mean =
                    nn.iter().fold(Vector3::zeros(), |s, r| s + point(&self.points[r.item as usize])) / nn.len() as f64;
                let cov = nn.iter().fold(Matrix3::zeros(), |s, r| {
                    let d = point(&self.points[r.item as usize]) - mean;
                    s + d * d.transpose()
                });
                let hood = Neighbourhood::new(j, nn.iter().map(|r| (r.item, r.distance)), nn.len() == n);
                (smallest_eigenvector(&cov), OnceLock::from(hood))
            })
            .unzip()
    }

    /// Point `j`'s neighbourhood, queried the first time it is needed.
    fn neighbourhood(&self, j: usize) -> &Neighbourhood {
        self.neighbourhoods[j].get_or_init(|| {
            let k = (CERTIFICATE_NEIGHBOURS + 1).min(self.points.len());
            let k = std::num::NonZero::new(k).unwrap_or(std::num::NonZero::<usize>::MIN);
            let nn = self.tree.query(&self.points[j]).nearest_n::<SquaredEuclidean<f32>>(k).execute();
            Neighbourhood::new(j, nn.iter().map(|r| (r.item, r.distance)), nn.len() == self.points.len())
        })
    }

    fn nearest(&self, q: &[f32; 3]) -> (usize, f64) {
        let r = self.tree.query(q).nearest_one::<SquaredEuclidean<f32>>().execute();
        (r.item as usize, f64::from(r.distance))
    }

    /// The nearest point to `q` (index, squared distance), as
    /// [`nearest`](Self::nearest) finds it, trying the neighbourhood of
    /// `hint` (a point near `q`, or `u32::MAX` for none) first.
    fn nearest_from(&self, q: &[f32; 3], hint: u32) -> (usize, f64) {
        self.certified_nearest(q, hint).map_or_else(|| self.nearest(q), |(i, d2)| (i, f64::from(d2)))
    }

    /// The nearest point to `q` when `q` lies within the reach of `hint`'s
    /// `Neighbourhood`, else `None`.
    fn certified_nearest(&self, q: &[f32; 3], hint: u32) -> Option<(usize, f32)> {
        let h = self.points.get(hint as usize)?;
        let hood = self.neighbourhood(hint as usize);
        let d2 = squared_distance(q, h);
        if d2 > hood.reach_sq {
            return None;
        }
        let mut best = (hint as usize, d2);
        for &k in &hood.points[..usize::from(hood.len)] {
            let dk = squared_distance(q, &self.points[k as usize]);
            if dk < best.1 {
                best = (k as usize, dk);
            }
        }
        Some(best)
    }
}

fn squared_distance(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// The unit eigenvector of the smallest eigenvalue of a symmetric 3×3
/// matrix: the eigenvalue in closed form (trigonometric solution of the
/// characteristic cubic), the vector as the longest cross product of two
/// rows of A − λI. Falls back to the iterative solver when that vector is
/// ill-defined (a repeated smallest eigenvalue).
fn smallest_eigenvector(a: &Matrix3<f64>) -> Vector3<f64> {
    let iterative = || {
        let eig = SymmetricEigen::new(*a);
        eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned()
    };
    let p1 = a[(0, 1)].powi(2) + a[(0, 2)].powi(2) + a[(1, 2)].powi(2);
    let q = a.trace() / 3.0;
    let p2 = (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p.is_nan() || p <= 0.0 {
        return iterative();
    }
    let b = (a - Matrix3::identity() * q) / p;
    let phi = (b.determinant() / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    let lambda = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let m = a - Matrix3::identity() * lambda;
    let (r0, r1, r2) = (m.row(0).transpose(), m.row(1).transpose(), m.row(2).transpose());
    let best = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)]
        .into_iter()
        .max_by(|x, y| x.norm_squared().total_cmp(&y.norm_squared()))
        .unwrap_or_default();
    // |rᵢ × rⱼ| ~ p² when the other two eigenvalues are apart from λ.
    if best.norm_squared() > 1e-12 * p2 * p2 { best.normalize() } else { iterative() }
}

fn point(p: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
}

/// What an ICP run returns.
#[derive(Debug, Clone, PartialEq)]
pub struct IcpResult {
    /// The estimate: maps source points into the target frame.
    pub target_from_source: Isometry3<f64>,
    /// Whether an update fell below the tolerances before the cap.
    pub converged: bool,
    /// Iterations done.
    pub iterations: usize,
    /// Correspondences within the distance at the last linearisation
    /// point (the estimate before the last update, which moved it by less
    /// than the tolerances when `converged`).
    pub inliers: usize,
    /// RMS of the residuals at the last linearisation point (point-to-plane
    /// distances or point-to-point distances), metres.
    pub rmse_m: f64,
    /// 6×6 information of ξ = (ω, v) at the last linearisation point, see
    /// the module docs.
    pub information: Matrix6<f64>,
    /// With [`IcpConfig::trace`]: `target_from_source` after each
    /// iteration (the last is the estimate); empty otherwise.
    pub trace: Vec<Isometry3<f64>>,
}

impl IcpResult {
    /// The 6×6 covariance of ξ = (ω, v) (the inverse of
    /// [`information`](Self::information)), or `None` when the information
    /// is singular (a degenerate geometry).
    pub fn covariance(&self) -> Option<Matrix6<f64>> {
        self.information.cholesky().map(|c| c.inverse())
    }
}

/// Sums over the correspondences of one iteration.
#[derive(Clone, Copy, Default)]
struct Sums {
    n: usize,
    /// Σ w (point-to-point; equals n without a kernel).
    sw: f64,
    sq: f64,
    h: Matrix6<f64>,
    b: Vector6<f64>,
    sp: Vector3<f64>,
    sq_t: Vector3<f64>,
    spq: Matrix3<f64>,
    spp: Matrix3<f64>,
}

impl Sums {
    fn merge(mut self, o: Sums) -> Sums {
        self.n += o.n;
        self.sw += o.sw;
        self.sq += o.sq;
        self.h += o.h;
        self.b += o.b;
        self.sp += o.sp;
        self.sq_t += o.sq_t;
        self.spq += o.spq;
        self.spp += o.spp;
        self
    }

    /// Σ w JᵀJ of the pairs, with J = [−[p]×, I] for point-to-point (derived
    /// from Σw, Σwp and Σwppᵀ: [p]×ᵀ[p]× = |p|²I − ppᵀ) and the accumulated
    /// `h` for point-to-plane.
    fn normal_matrix(&self, method: Method) -> Matrix6<f64> {
        match method {
            Method::PointToPlane => self.h,
            Method::PointToPoint => {
                let k = skew(&self.sp);
                let mut h = Matrix6::zeros();
                h.fixed_view_mut::<3, 3>(0, 0).copy_from(&(Matrix3::identity() * self.spp.trace() - self.spp));
                h.fixed_view_mut::<3, 3>(0, 3).copy_from(&k);
                h.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-k));
                h.fixed_view_mut::<3, 3>(3, 3).copy_from(&(Matrix3::identity() * self.sw));
                h
            }
        }
    }
}

/// The cross-product matrix: `skew(v) · x = v × x`.
pub(crate) fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Horn's closed-form rotation: the unit quaternion is the eigenvector of
/// the largest eigenvalue of N built from S = Σ (p − p̄)(q − q̄)ᵀ.
pub(crate) fn horn_rotation(s: &Matrix3<f64>) -> UnitQuaternion<f64> {
    let (sxx, sxy, sxz) = (s[(0, 0)], s[(0, 1)], s[(0, 2)]);
    let (syx, syy, syz) = (s[(1, 0)], s[(1, 1)], s[(1, 2)]);
    let (szx, szy, szz) = (s[(2, 0)], s[(2, 1)], s[(2, 2)]);
    #[rustfmt::skip]
    let n = Matrix4::new(
        sxx + syy + szz, syz - szy,        szx - sxz,        sxy - syx,
        syz - szy,       sxx - syy - szz,  sxy + syx,        szx + sxz,
        szx - sxz,       sxy + syx,        -sxx + syy - szz, syz + szy,
        sxy - syx,       szx + sxz,        syz + szy,        -sxx - syy + szz,
    );
    let eig = SymmetricEigen::new(n);
    let q = eig.eigenvectors.column(eig.eigenvalues.imax());
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// Aligns `source` to `target` from `init` (`target_from_source`).
pub fn align(source: &[Point3<f32>], target: &Target, init: &Isometry3<f64>, config: &IcpConfig) -> Result<IcpResult> {
    align_impl(source, target, init, config, None)
}

/// A prior on `target_from_source` — typically the CPS pose of the scan
/// and its covariance — with its 6×6 information in the same convention as
/// [`IcpResult::information`] (ξ = (ω, v), left perturbation, target frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// The prior's mean.
    pub target_from_source: Isometry3<f64>,
    /// Its information (inverse covariance), symmetric positive semi-definite.
    pub information: Matrix6<f64>,
}

/// Point-to-plane ICP whose normal equations include a prior: each
/// Gauss–Newton step minimises Σ r²/σ̂² + eᵀ Λ e, with σ̂² the current
/// residual variance and e ≈ ξ(T · T_prior⁻¹) the prior's error (first
/// order). The result is the fused estimate; its `information` is the
/// fused one, H/σ̂² + Λ, so directions the scans do not constrain (along a
/// corridor, about a pipe's axis) keep the prior's uncertainty instead of
/// failing as singular.
pub fn align_with_prior(
    source: &[Point3<f32>],
    target: &Target,
    init: &Isometry3<f64>,
    prior: &Prior,
    config: &IcpConfig,
) -> Result<IcpResult> {
    if config.method != Method::PointToPlane {
        return Err(FusionError::OutOfRange {
            what: "ICP method with a prior".into(),
            value: 0.0,
            expected: "point-to-plane".into(),
        });
    }
    let l = &prior.information;
    let symmetric = (l - l.transpose()).amax() <= 1e-9 * l.amax().max(1.0);
    let psd = l.symmetric_eigenvalues().iter().all(|v| *v >= -1e-9 * l.amax().max(1.0));
    if !(l.iter().all(|v| v.is_finite()) && symmetric && psd) {
        return Err(FusionError::OutOfRange {
            what: "prior information".into(),
            value: l.amax(),
            expected: "a finite, symmetric, positive semi-definite 6×6".into(),
        });
    }
    align_impl(source, target, init, config, Some(prior))
}

fn align_impl(
    source: &[Point3<f32>],
    target: &Target,
    init: &Isometry3<f64>,
    config: &IcpConfig,
    prior: Option<&Prior>,
) -> Result<IcpResult> {
    check(config)?;
    if config.reject_back_faces && !target.oriented {
        return Err(FusionError::OutOfRange {
            what: "target normals".into(),
            value: 0.0,
            expected:
                "normals oriented towards the target's scanner (Target::orient_normals_towards) to reject back faces"
                    .into(),
        });
    }
    if config.method == Method::PointToPlane && target.normals.is_empty() {
        return Err(FusionError::OutOfRange {
            what: "target normals".into(),
            value: 0.0,
            expected: "a target built with normal_neighbours > 0 for point-to-plane".into(),
        });
    }
    let max_sq = config.max_correspondence_m * config.max_correspondence_m;
    let mut estimate = *init;
    let mut converged = false;
    let mut iterations = 0;
    let mut trace = Vec::new();
    // The statistics come from the last iteration's pass (as small_gicp's
    // do): one more nearest-neighbour pass at the final estimate would cost
    // a sixth of a typical run and change them by the last, sub-tolerance
    // update.
    let mut last = Sums::default();
    let mut partners = vec![u32::MAX; source.len()];
    while iterations < config.max_iterations {
        let sums = accumulate(source, target, &estimate, max_sq, config, &mut partners);
        last = sums;
        if sums.n < 6 {
            return Err(FusionError::TooFewCorrespondences {
                found: sums.n,
                needed: 6,
                max_distance_m: config.max_correspondence_m,
                iteration: iterations,
            });
        }
        let update = match config.method {
            Method::PointToPoint => {
                let n = sums.sw;
                let (cp, cq) = (sums.sp / n, sums.sq_t / n);
                let s = sums.spq - n * cp * cq.transpose();
                let r = horn_rotation(&s);
                Isometry3::from_parts(Translation3::from(cq - r * cp), r)
            }
            Method::PointToPlane => {
                let (h, b) = match prior {
                    None => (sums.h, sums.b),
                    Some(p) => {
                        let sigma2 = residual_variance(&sums, config.method);
                        let e = crate::graph::left_difference(&estimate, &p.target_from_source);
                        (sums.h / sigma2 + p.information, sums.b / sigma2 + p.information * e)
                    }
                };
                let delta = h
                    .cholesky()
                    .ok_or_else(|| FusionError::Degenerate {
                        what: format!("point-to-plane normal equations at iteration {iterations}"),
                    })?
                    .solve(&(-b));
                crate::graph::exp(&delta)
            }
        };
        estimate = update * estimate;
        iterations += 1;
        if config.trace {
            trace.push(estimate);
        }
        if update.translation.vector.norm() < config.translation_tolerance_m
            && update.rotation.angle() < config.rotation_tolerance_rad
        {
            converged = true;
            break;
        }
    }
    let sums = last;
    let rmse_m = (sums.sq / sums.n.max(1) as f64).sqrt();
    let information = sums.normal_matrix(config.method) / residual_variance(&sums, config.method)
        + prior.map_or_else(Matrix6::zeros, |p| p.information);
    Ok(IcpResult { target_from_source: estimate, converged, iterations, inliers: sums.n, rmse_m, information, trace })
}

/// σ̂² per scalar residual: point-to-plane has one per pair, point-to-point three.
fn residual_variance(sums: &Sums, method: Method) -> f64 {
    let scalars = if method == Method::PointToPlane { sums.n } else { 3 * sums.n };
    (sums.sq / scalars.saturating_sub(6).max(1) as f64).max(1e-18)
}

fn check(c: &IcpConfig) -> Result<()> {
    FusionError::require_positive("max correspondence distance (m)", c.max_correspondence_m)?;
    if let Kernel::Huber { width_m } = c.kernel {
        FusionError::require_positive("Huber width (m)", width_m)?;
    }
    FusionError::require_non_negative("translation tolerance (m)", c.translation_tolerance_m)?;
    FusionError::require_non_negative("rotation tolerance (rad)", c.rotation_tolerance_rad)?;
    if c.max_iterations == 0 {
        return Err(FusionError::OutOfRange { what: "iteration cap".into(), value: 0.0, expected: "≥ 1".into() });
    }
    Ok(())
}

/// One pass over the source: nearest neighbours within the distance and
/// the sums both metrics need. `partners` holds each source point's
/// nearest target point of the last pass (`u32::MAX` before the first),
/// where its search starts, and is updated.
fn accumulate(
    source: &[Point3<f32>],
    target: &Target,
    estimate: &Isometry3<f64>,
    max_sq: f64,
    config: &IcpConfig,
    partners: &mut [u32],
) -> Sums {
    let r: Matrix3<f64> = estimate.rotation.to_rotation_matrix().into_inner();
    let t = estimate.translation.vector;
    // The source scanner in the target frame.
    let back_faces = config.reject_back_faces.then(|| r * config.source_viewpoint.coords + t);
    source
        .par_chunks(4096)
        .zip(partners.par_chunks_mut(4096))
        .map(|(chunk, partners)| {
            let mut s = Sums::default();
            for (p, partner) in chunk.iter().zip(partners) {
                let pt = r * p.coords.cast::<f64>() + t;
                let (i, d2) = target.nearest_from(&[pt.x as f32, pt.y as f32, pt.z as f32], *partner);
                *partner = i as u32;
                if d2 > max_sq {
                    continue;
                }
                let q = point(&target.points[i]);
                if let Some(eye) = back_faces
                    && target.normals[i].dot(&(eye - q)) < 0.0
                {
                    continue;
                }
                s.n += 1;
                match config.method {
                    Method::PointToPlane => {
                        let n = target.normals[i];
                        let res = n.dot(&(pt - q));
                        let w = config.kernel.weight(res);
                        // r = nᵀ(T̂p + ω × T̂p + v − q): ∂r/∂ω = T̂p × n, ∂r/∂v = n.
                        let c = pt.cross(&n);
                        let j = Vector6::new(c.x, c.y, c.z, n.x, n.y, n.z);
                        s.h += w * j * j.transpose();
                        s.b += w * res * j;
                        s.sq += res * res;
                    }
                    Method::PointToPoint => {
                        let e2 = (pt - q).norm_squared();
                        let w = config.kernel.weight(e2.sqrt());
                        s.sq += e2;
                        s.sw += w;
                        s.sp += w * pt;
                        s.sq_t += w * q;
                        s.spq += w * pt * q.transpose();
                        s.spp += w * pt * pt.transpose();
                    }
                }
            }
            s
        })
        .reduce(Sums::default, Sums::merge)
}

/// One stage of a coarse-to-fine schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stage {
    /// Reduced-points cell of both clouds, metres.
    pub voxel_m: f64,
    /// Correspondence distance, metres.
    pub max_correspondence_m: f64,
}

/// Runs [`align`] stage by stage (voxel-reducing both clouds each time),
/// each stage starting from the previous result. Returns the last stage's
/// result with the total iteration count.
pub fn align_coarse_to_fine(
    source: &[Point3<f32>],
    target: &[Point3<f32>],
    init: &Isometry3<f64>,
    stages: &[Stage],
    config: &IcpConfig,
) -> Result<IcpResult> {
    let mut estimate = *init;
    let mut last = None;
    let mut total = 0;
    for st in stages {
        let neighbours = if config.method == Method::PointToPlane { config.normal_neighbours } else { 0 };
        let (src, tgt) = rayon::join(
            || scanner::reduced_points(source, st.voxel_m),
            || Target::new(&scanner::reduced_points(target, st.voxel_m)?, neighbours),
        );
        let (src, tgt) = (src?, tgt?);
        let cfg = IcpConfig { max_correspondence_m: st.max_correspondence_m, ..*config };
        let r = align(&src, &tgt, &estimate, &cfg)?;
        estimate = r.target_from_source;
        total += r.iterations;
        last = Some(r);
    }
    let mut r = last.ok_or_else(|| FusionError::OutOfRange {
        what: "number of stages".into(),
        value: 0.0,
        expected: "≥ 1".into(),
    })?;
    r.iterations = total;
    Ok(r)
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// The point-to-point normal matrix derived from the sums equals Σ JᵀJ
    /// with J = [−[p]×, I] built point by point.
    #[test]
    fn point_to_point_normal_matrix() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut sums = Sums::default();
        let mut explicit = Matrix6::zeros();
        for _ in 0..20 {
            let p = Vector3::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0));
            let mut j = nalgebra::Matrix3x6::zeros();
            j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-skew(&p)));
            j.fixed_view_mut::<3, 3>(0, 3).copy_from(&Matrix3::identity());
            explicit += j.transpose() * j;
            sums.n += 1;
            sums.sw += 1.0;
            sums.sp += p;
            sums.spp += p * p.transpose();
        }
        assert!((sums.normal_matrix(Method::PointToPoint) - explicit).amax() < 1e-9);
    }

    /// The closed-form smallest eigenvector agrees with the iterative solver
    /// on random covariances, from isotropic to nearly planar and linear.
    #[test]
    fn smallest_eigenvector_matches_symmetric_eigen() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for k in 0..2000 {
            let r = UnitQuaternion::from_euler_angles(
                rng.random_range(-3.0..3.0),
                rng.random_range(-1.5..1.5),
                rng.random_range(-3.0..3.0),
            )
            .to_rotation_matrix()
            .into_inner();
            let thin = [1.0, 1e-2, 1e-4, 1e-6][k % 4];
            let d = Matrix3::from_diagonal(&Vector3::new(
                rng.random_range(0.5..1.0),
                rng.random_range(0.1..0.4),
                thin * rng.random_range(0.0..0.05),
            ));
            let a = r * d * r.transpose() * 1e-2;
            let eig = SymmetricEigen::new(a);
            let reference = eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned();
            let v = smallest_eigenvector(&a);
            assert!((v.norm() - 1.0).abs() < 1e-12);
            assert!(v.dot(&reference).abs() > 1.0 - 1e-9, "case {k}: {v} vs {reference}");
        }
        // Repeated eigenvalues go through the fallback and still give a unit eigenvector.
        let v = smallest_eigenvector(&Matrix3::from_diagonal(&Vector3::new(2.0, 1.0, 1.0)));
        assert!((v.x.abs() < 1e-12) && (v.norm() - 1.0).abs() < 1e-12);
    }

    /// The neighbourhood certificate gives exactly the k-d tree's nearest
    /// distance whenever it applies, and applies to most queries near a
    /// surface when the hint is a nearby point; hints far off, out of range
    /// or missing fall back to the tree. Both with neighbourhoods from the
    /// normals' query and queried lazily, and for a cloud smaller than a
    /// neighbourhood.
    #[test]
    fn certified_nearest_matches_the_tree() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        // Two walls and a floor, 5 cm apart, with 1 cm noise.
        let mut cloud = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let (a, b) = (i as f32 * 0.05, j as f32 * 0.05);
                let mut e = || rng.random_range(-0.01f32..0.01);
                cloud.push(Point3::new(a, b, e()));
                cloud.push(Point3::new(a, e(), b));
                cloud.push(Point3::new(e(), a, b));
            }
        }
        // (points, normal neighbours, near hints that must certify of 3000):
        // 7 points with lazy neighbourhoods hold the whole cloud in each.
        for (points, normals, expected) in
            [(&cloud[..], 10, 1500), (&cloud[..], 0, 1500), (&cloud[..7], 0, 3000), (&cloud[..7], 5, 1000)]
        {
            let target = Target::new(points, normals).expect("target");
            let mut near_certified = 0;
            for _ in 0..3000 {
                let p = points[rng.random_range(0..points.len())];
                let q = [
                    p.x + rng.random_range(-0.03..0.03),
                    p.y + rng.random_range(-0.03..0.03),
                    p.z + rng.random_range(-0.03..0.03),
                ];
                let (_, truth) = target.nearest(&q);
                // A hint near q: the tree's answer for a point 1.4 cm off.
                let near = target.nearest(&[q[0] + 0.01, q[1] - 0.01, q[2]]).0 as u32;
                let hints = [near, rng.random_range(0..points.len() as u32), u32::MAX, points.len() as u32];
                for (h, hint) in hints.into_iter().enumerate() {
                    if let Some((i, d2)) = target.certified_nearest(&q, hint) {
                        near_certified += usize::from(h == 0);
                        assert!((f64::from(d2) - truth).abs() <= 1e-6 * truth.max(1e-6), "{d2} vs {truth}");
                        assert_eq!(f64::from(squared_distance(&q, &target.points[i])), f64::from(d2));
                    }
                    assert!((target.nearest_from(&q, hint).1 - truth).abs() <= 1e-6 * truth.max(1e-6));
                }
            }
            assert!(near_certified >= expected, "{near_certified} of 3000 near hints certified");
        }
    }

    /// Points every `step` metres on the rectangle `corner + a·u + b·v`,
    /// a, b ∈ [0, 1].
    fn grid(corner: [f64; 3], u: [f64; 3], v: [f64; 3], step: f64) -> Vec<Vector3<f64>> {
        let (c, u, v) = (Vector3::from(corner), Vector3::from(u), Vector3::from(v));
        let (nu, nv) = ((u.norm() / step) as usize, (v.norm() / step) as usize);
        (0..=nu)
            .flat_map(|i| (0..=nv).map(move |j| c + u * (i as f64 / nu as f64) + v * (j as f64 / nv as f64)))
            .collect()
    }

    /// A plate 0.1 m thick between two scanners: the target (scanner at
    /// x = −3) sees its face x = 0, the source (scanner at x = +3, its
    /// frame's origin) its back x = 0.1; both see a floor, a side wall and
    /// an end wall at x = 5. Pairing the back with the face pulls the
    /// source 0.1 m towards the target's scanner, weighted by how many
    /// pairs that is; rejecting back faces leaves only surfaces both saw,
    /// and the known pose comes out exactly.
    #[test]
    fn back_faces_are_rejected() {
        let common: Vec<Vector3<f64>> = [
            grid([-3.0, -2.0, -1.0], [8.0, 0.0, 0.0], [0.0, 4.0, 0.0], 0.1), // floor
            grid([-3.0, -2.0, -1.0], [8.0, 0.0, 0.0], [0.0, 0.0, 3.0], 0.1), // side wall
            grid([5.0, -2.0, -1.0], [0.0, 4.0, 0.0], [0.0, 0.0, 3.0], 0.1),  // end wall
        ]
        .concat();
        let face = grid([0.0, -0.5, -0.5], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], 0.05);
        let back: Vec<Vector3<f64>> = face.iter().map(|p| p + Vector3::new(0.1, 0.0, 0.0)).collect();
        let cast = |v: &[Vector3<f64>]| -> Vec<Point3<f32>> { v.iter().map(|p| Point3::from(p.cast())).collect() };
        let mut target = Target::new(&cast(&[common.clone(), face].concat()), 10).expect("target");
        let eye = Vector3::new(3.0, 0.0, 0.0);
        let truth = Isometry3::translation(eye.x, eye.y, eye.z);
        let source: Vec<Vector3<f64>> = [common, back].concat().iter().map(|p| p - eye).collect();
        let source = cast(&source);
        let config = IcpConfig { max_correspondence_m: 0.5, ..IcpConfig::default() };
        let rejecting = IcpConfig { reject_back_faces: true, ..config };

        assert!(!target.has_oriented_normals());
        let e = align(&source, &target, &truth, &rejecting).expect_err("normals not oriented yet");
        assert!(e.to_string().contains("oriented towards"), "{e}");
        target.orient_normals_towards(&Point3::new(-3.0, 0.0, 0.0));
        assert!(target.has_oriented_normals());
        for (n, q) in target.normals().iter().zip(target.points()) {
            assert!(n.dot(&(Vector3::new(-3.0, 0.0, 0.0) - q.coords.cast())) >= 0.0);
        }
        let start = Isometry3::translation(0.05, -0.03, 0.02) * truth;
        let plain = align(&source, &target, &start, &config).expect("plain");
        let clean = align(&source, &target, &start, &rejecting).expect("rejecting");
        let along = |r: &IcpResult| (r.target_from_source.translation.vector - eye).x;
        assert!(along(&plain) < -0.01, "the back pulls the source back: {} m", along(&plain));
        assert!((clean.target_from_source.translation.vector - eye).norm() < 1e-4, "{}", clean.target_from_source);
        assert!(clean.target_from_source.rotation.angle_to(&truth.rotation) < 1e-5);
        assert_eq!(clean.inliers, source.len() - 21 * 21, "every back point left out, nothing else");

        // The same source in a frame whose origin is in front of the plate
        // (x = −1), its scanner still at x = 3: only with the scanner's
        // place given are the back points left out.
        let origin = Vector3::new(-1.0, 0.0, 0.0);
        let moved: Vec<Point3<f32>> =
            source.iter().map(|p| Point3::from((p.coords.cast() + eye - origin).cast())).collect();
        let truth = Isometry3::translation(origin.x, origin.y, origin.z);
        let start = Isometry3::translation(0.05, -0.03, 0.02) * truth;
        let unplaced = align(&moved, &target, &start, &rejecting).expect("scanner taken at the origin");
        let placed = IcpConfig { source_viewpoint: Point3::from(eye - origin), ..rejecting };
        let placed = align(&moved, &target, &start, &placed).expect("scanner placed");
        let along = |r: &IcpResult| (r.target_from_source.translation.vector - origin).x;
        assert!(along(&unplaced) < -0.01, "a wrong viewpoint keeps the back: {} m", along(&unplaced));
        assert!((placed.target_from_source.translation.vector - origin).norm() < 1e-4, "{}", placed.target_from_source);
        assert_eq!(placed.inliers, clean.inliers);
    }

    /// Horn recovers an exact rotation from noiseless pairs.
    #[test]
    fn horn_exact() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let truth = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
        let ps: Vec<Vector3<f64>> = (0..50)
            .map(|_| {
                Vector3::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0))
            })
            .collect();
        let cp = ps.iter().sum::<Vector3<f64>>() / 50.0;
        let s = ps.iter().fold(Matrix3::zeros(), |s, p| s + (p - cp) * (truth * (p - cp)).transpose());
        assert!(horn_rotation(&s).angle_to(&truth) < 1e-12);
    }
}
