//! A target cloud prepared for ICP: the k-d tree, PCA normals (optionally
//! oriented towards the scanner) and each point's neighbourhood
//! certificate, which answers most nearest-neighbour queries without the
//! tree. Normals and certificates are estimated point by point the first
//! time ICP needs them, from one k-nearest query.

use std::sync::OnceLock;

use kiddo::SquaredEuclidean;
use nalgebra::{Isometry3, Matrix3, Point3, SymmetricEigen, Vector3};
use rayon::prelude::*;

use crate::error::{FusionError, Result};

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

/// A target point's surroundings, estimated the first time ICP needs
/// them: its PCA normal (turned towards the viewpoint, when one is set) and
/// its `Neighbourhood`, from one k-nearest query.
#[derive(Debug, Clone, Copy)]
struct Local {
    /// Zero when the target's normals are given, not estimated.
    normal: Vector3<f64>,
    /// The middle PCA eigenvalue over the largest ([`Target::middle_shares`]).
    middle: f32,
    /// The smallest PCA eigenvalue over the middle one
    /// ([`Target::corner_share`]).
    corner: f32,
    hood: Neighbourhood,
}

/// A target cloud prepared for ICP: its k-d tree and, for point-to-plane,
/// unit normals — given with the points, or PCA normals estimated point by
/// point as ICP first needs them (a point no source point comes near is
/// never estimated: with partial overlap, and for the scans of a set that
/// are only ever matched as sources, most of them) — and each point's
/// `Neighbourhood`, from the same query.
#[derive(Debug)]
pub struct Target {
    pub(crate) points: Vec<[f32; 3]>,
    /// Normals given with the points; empty when estimated or absent.
    given: Vec<Vector3<f64>>,
    /// With given normals: their neighbourhoods' middle shares (see
    /// [`Target::middle_shares`]); empty when not known.
    given_middle: Vec<f32>,
    /// With given normals: their neighbourhoods' corner shares (see
    /// [`Target::corner_shares`]); empty when not known.
    given_corner: Vec<f32>,
    /// Points of an estimated normal's neighbourhood; 0: none estimated.
    normal_neighbours: usize,
    /// Estimated normals are turned towards this point.
    viewpoint: Option<Point3<f64>>,
    tree: KdTree,
    local: Vec<OnceLock<Local>>,
    /// Each estimated point's [middle share](Target::middle_shares), its
    /// wider neighbourhood consulted the first time it is asked for.
    line_share: Vec<OnceLock<f32>>,
    /// The normals point to the side the target's scanner saw.
    pub(crate) oriented: bool,
}

impl Target {
    /// Builds the tree; when `normal_neighbours > 0`, the points get PCA
    /// normals from that many nearest points (at least 3), estimated as
    /// they are first needed.
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
        let local = std::iter::repeat_with(OnceLock::new).take(points.len()).collect();
        let normal_neighbours = if normal_neighbours > 0 { normal_neighbours.max(3) } else { 0 };
        let shares = if normal_neighbours > 0 { points.len() } else { 0 };
        let line_share = std::iter::repeat_with(OnceLock::new).take(shares).collect();
        Ok(Self {
            points,
            given: Vec::new(),
            given_middle: Vec::new(),
            given_corner: Vec::new(),
            normal_neighbours,
            viewpoint: None,
            tree,
            local,
            line_share,
            oriented: false,
        })
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
        t.given = normals;
        Ok(t)
    }

    /// [`with_normals`](Self::with_normals) for normals already oriented
    /// towards the scanners that saw their points (e.g. scans' oriented
    /// normals moved into one frame with their scans).
    pub fn with_oriented_normals(points: &[Point3<f32>], normals: Vec<Vector3<f64>>) -> Result<Self> {
        let mut t = Self::with_normals(points, normals)?;
        t.oriented = !t.given.is_empty();
        Ok(t)
    }

    /// The [`middle_shares`](Self::middle_shares) of the given normals'
    /// neighbourhoods, from the targets they were estimated in. Empty: not
    /// known (taken as planar).
    pub fn with_middle_shares(mut self, shares: Vec<f32>) -> Result<Self> {
        self.given_middle = self.one_per_point("middle share count", shares)?;
        Ok(self)
    }

    /// `shares` when empty or one per point, else an error naming `what`.
    fn one_per_point(&self, what: &str, shares: Vec<f32>) -> Result<Vec<f32>> {
        if !shares.is_empty() && shares.len() != self.points.len() {
            return Err(FusionError::OutOfRange {
                what: what.into(),
                value: shares.len() as f64,
                expected: format!("one per point ({})", self.points.len()),
            });
        }
        Ok(shares)
    }

    /// The [`corner_shares`](Self::corner_shares) of the given normals'
    /// neighbourhoods, from the targets they were estimated in. Empty: not
    /// known (taken as planar).
    pub fn with_corner_shares(mut self, shares: Vec<f32>) -> Result<Self> {
        self.given_corner = self.one_per_point("corner share count", shares)?;
        Ok(self)
    }

    /// Turns every normal towards `viewpoint` (the scanner that took the
    /// points, in their frame): nᵀ(viewpoint − q) ≥ 0. Does nothing
    /// without normals.
    pub fn orient_normals_towards(&mut self, viewpoint: &Point3<f64>) {
        for (n, q) in self.given.iter_mut().zip(&self.points) {
            orient(n, q, viewpoint);
        }
        if self.normal_neighbours > 0 {
            self.viewpoint = Some(*viewpoint);
            for (l, q) in self.local.iter_mut().zip(&self.points) {
                if let Some(l) = l.get_mut() {
                    orient(&mut l.normal, q, viewpoint);
                }
            }
        }
        self.oriented = self.has_normals();
    }

    /// True when the normals are oriented towards the scanner.
    pub fn has_oriented_normals(&self) -> bool {
        self.oriented
    }

    /// True when the points have normals (given or estimated).
    pub fn has_normals(&self) -> bool {
        self.normal_neighbours > 0 || !self.given.is_empty()
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

    /// Every point's normal (estimating those not yet estimated); empty
    /// without normals.
    pub fn normals(&self) -> Vec<Vector3<f64>> {
        if !self.has_normals() {
            return Vec::new();
        }
        (0..self.points.len()).into_par_iter().map(|i| self.normal(i)).collect()
    }

    /// Each point's corner share: the smallest PCA eigenvalue of the
    /// neighbourhood its normal came from over the middle one — near 0 on
    /// one plane, up to 1 where the neighbourhood is no plane (two
    /// surfaces meeting among its points, a blob)
    /// ([`super::IcpConfig::corner_ratio`]; estimating those not yet
    /// estimated). Empty without normals.
    pub fn corner_shares(&self) -> Vec<f32> {
        self.corner_shares_beyond(0.0)
    }

    /// `share` of every point, in parallel; empty without normals.
    fn each_point(&self, share: impl Fn(&Self, usize) -> f32 + Sync + Send) -> Vec<f32> {
        if !self.has_normals() {
            return Vec::new();
        }
        (0..self.points.len()).into_par_iter().map(|i| share(self, i)).collect()
    }

    /// Point `i`'s [corner share](Self::corner_shares) where its ten
    /// nearest other points reach farther than `reach_sq` (squared metres),
    /// 0 where they do not (0 when not known). Given normals' shares are
    /// taken as given.
    pub(crate) fn corner_share_beyond(&self, i: usize, reach_sq: f64) -> f32 {
        if self.normal_neighbours == 0 {
            return self.given_corner.get(i).copied().unwrap_or(0.0);
        }
        let local = self.local(i);
        if f64::from(4.0 * local.hood.reach_sq) > reach_sq { local.corner } else { 0.0 }
    }

    /// Each point's [corner share](Self::corner_shares) where its ten
    /// nearest other points reach farther than `reach_m`, 0 where they do
    /// not: a sparse neighbourhood's (as
    /// [`super::IcpConfig::corner_everywhere`] off judges them, the
    /// stage's correspondence distance the reach). Empty without normals.
    pub fn corner_shares_beyond(&self, reach_m: f64) -> Vec<f32> {
        self.each_point(|t, i| t.corner_share_beyond(i, reach_m * reach_m))
    }

    /// Point `i`'s unit normal (the target has normals).
    pub(crate) fn normal(&self, i: usize) -> Vector3<f64> {
        if self.normal_neighbours > 0 { self.local(i).normal } else { self.given[i] }
    }

    /// Each point's middle share — the middle PCA eigenvalue of the
    /// neighbourhood its normal came from, over the largest (estimating
    /// those not yet estimated): near 0 where the neighbours lie along one
    /// line, which a scan line's arc does, and its PCA normal is then the
    /// line's own plane, not the surface's ([`super::IcpConfig::line_ratio`]);
    /// 0 where the normal is not clear at all (the smallest eigenvalue
    /// above [`AMBIGUOUS_NORMAL`] of the middle one). But 1 where the
    /// normal stands: where the wider neighbourhood ([`WIDER`] times the
    /// points) is a line too — a thin real structure (a pole, a kerb, a
    /// wire), whose points' normals, each some direction across it,
    /// together see it — or a surface whose normal is within 30° of the
    /// point's (a multi-beam lidar's ring on flat ground: the ring's plane
    /// is the ground's). Empty without normals.
    pub fn middle_shares(&self) -> Vec<f32> {
        self.each_point(Self::middle_share)
    }

    /// Point `i`'s [middle share](Self::middle_shares) (1 when not known).
    pub(crate) fn middle_share(&self, i: usize) -> f32 {
        if self.normal_neighbours == 0 {
            return self.given_middle.get(i).copied().unwrap_or(1.0);
        }
        *self.line_share[i].get_or_init(|| {
            let local = self.local(i);
            if local.middle >= 1.0 || self.wider_agrees(i, &local.normal) { 1.0 } else { local.middle }
        })
    }

    /// Whether point `i`'s `normal` stands against its wider neighbourhood
    /// ([`middle_shares`](Self::middle_shares)): a line there too (its
    /// middle PCA eigenvalue below [`WIDE_SURFACE`] of the largest), or a
    /// clear surface whose normal is within 30° of `normal` — not a
    /// surface with another normal, nor a blob with no clear normal at any
    /// scale (a sparse far stretch of a pipe, its neighbourhoods wider
    /// than the pipe).
    fn wider_agrees(&self, i: usize, normal: &Vector3<f64>) -> bool {
        let k = (WIDER * self.normal_neighbours).min(self.points.len());
        let k = std::num::NonZero::new(k).unwrap_or(std::num::NonZero::<usize>::MIN);
        let nn = self.tree.query(&self.points[i]).nearest_n::<SquaredEuclidean<f32>>(k).execute();
        let eig = SymmetricEigen::new(self.scatter(nn.iter().map(|r| r.item)));
        let mut order = [0, 1, 2];
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let e = order.map(|k| eig.eigenvalues[k].max(0.0));
        if e[1] <= WIDE_SURFACE * e[2] {
            return true;
        }
        e[0] <= AMBIGUOUS_NORMAL * e[1] && eig.eigenvectors.column(order[0]).dot(normal).abs() >= AGREE_COS
    }

    /// Whether `offset` (a source point's offset from target point `i`
    /// along the surface, metres) takes it beyond what the target sampled
    /// there: farther than half the way to `i`'s nearest neighbour, and
    /// farther in its direction than any of `i`'s neighbours lie — where a
    /// partial overlap ends or an occlusion begins, `i` is the last sample
    /// at the edge and the source point has no partner in the target.
    ///
    /// A scanner that samples in lines (a rotating line scanner's profiles,
    /// a multi-beam lidar's rings) leaves gaps between them far wider than
    /// the spacing along them, and `i`'s nearest neighbours all lie on its
    /// own line: a point in the gap is covered by the next line. So before
    /// calling it beyond, the target is searched within three times the
    /// offset of `i` for a sample at least as far along the offset, near
    /// the surface (within 30° of its tangent plane).
    pub(crate) fn beyond(&self, i: usize, offset: &Vector3<f64>) -> bool {
        let hood = &self.local(i).hood;
        let q = point(&self.points[i]);
        let length_sq = offset.norm_squared();
        let mut nearest_sq = f64::INFINITY;
        for &k in &hood.points[..usize::from(hood.len)] {
            let d = point(&self.points[k as usize]) - q;
            // A neighbour at least as far along the offset: covered.
            if d.dot(offset) >= length_sq {
                return false;
            }
            nearest_sq = nearest_sq.min(d.norm_squared());
        }
        if length_sq <= nearest_sq / 4.0 {
            return false;
        }
        let normal = self.normal(i);
        let reach = 9.0 * length_sq;
        !self.tree.query(&self.points[i]).within::<SquaredEuclidean<f32>>(reach as f32).unsorted().execute().iter().any(
            |r| {
                let d = point(&self.points[r.item as usize]) - q;
                d.dot(offset) >= length_sq && d.dot(&normal).abs() <= 0.5 * d.norm()
            },
        )
    }

    /// The distance from point `i` to its nearest other point, metres
    /// (zero when it has none).
    pub(crate) fn spacing(&self, i: usize) -> f64 {
        let hood = &self.local(i).hood;
        hood.points[..usize::from(hood.len)]
            .first()
            .map_or(0.0, |&k| (point(&self.points[k as usize]) - point(&self.points[i])).norm())
    }

    /// Point `j`'s surroundings, queried the first time they are needed.
    fn local(&self, j: usize) -> &Local {
        self.local[j].get_or_init(|| {
            let n = self.points.len();
            let k = self.normal_neighbours.max(CERTIFICATE_NEIGHBOURS + 1).min(n);
            let k = std::num::NonZero::new(k).unwrap_or(std::num::NonZero::<usize>::MIN);
            // Sorted by distance: the normal takes the nearest ones.
            let nn = self.tree.query(&self.points[j]).nearest_n::<SquaredEuclidean<f32>>(k).execute();
            let hood = Neighbourhood::new(j, nn.iter().map(|r| (r.item, r.distance)), nn.len() == n);
            if self.normal_neighbours == 0 {
                return Local { normal: Vector3::zeros(), middle: 1.0, corner: 0.0, hood };
            }
            let used = &nn[..self.normal_neighbours.min(nn.len())];
            let (mut normal, middle, corner) = pca_normal(&self.scatter(used.iter().map(|r| r.item)));
            if let Some(v) = &self.viewpoint {
                orient(&mut normal, &self.points[j], v);
            }
            Local { normal, middle: middle as f32, corner: corner as f32, hood }
        })
    }

    /// The scatter matrix of the points `items` (at least one) about
    /// their mean: Σ (q − q̄)(q − q̄)ᵀ.
    fn scatter(&self, items: impl Iterator<Item = u32> + Clone) -> Matrix3<f64> {
        let (sum, count) =
            items.clone().fold((Vector3::zeros(), 0usize), |(s, n), k| (s + point(&self.points[k as usize]), n + 1));
        let mean = sum / count as f64;
        items.fold(Matrix3::zeros(), |s, k| {
            let d = point(&self.points[k as usize]) - mean;
            s + d * d.transpose()
        })
    }

    fn nearest(&self, q: &[f32; 3]) -> (usize, f64) {
        let r = self.tree.query(q).nearest_one::<SquaredEuclidean<f32>>().execute();
        (r.item as usize, f64::from(r.distance))
    }

    /// The nearest point to `q` (index, squared distance), as
    /// [`nearest`](Self::nearest) finds it, trying the neighbourhood of
    /// `hint` (a point near `q`, or `u32::MAX` for none) first.
    pub(crate) fn nearest_from(&self, q: &[f32; 3], hint: u32) -> (usize, f64) {
        self.certified_nearest(q, hint).map_or_else(|| self.nearest(q), |(i, d2)| (i, f64::from(d2)))
    }

    /// The nearest point to `q` when `q` lies within the reach of `hint`'s
    /// `Neighbourhood`, else `None`.
    fn certified_nearest(&self, q: &[f32; 3], hint: u32) -> Option<(usize, f32)> {
        let h = self.points.get(hint as usize)?;
        let hood = &self.local(hint as usize).hood;
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

/// Turns `n` (the normal at `q`) towards `viewpoint`.
fn orient(n: &mut Vector3<f64>, q: &[f32; 3], viewpoint: &Point3<f64>) {
    if n.dot(&(viewpoint.coords - point(q))) < 0.0 {
        *n = -*n;
    }
}

fn squared_distance(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// The wider neighbourhood that tells whether a point's normal stands
/// ([`Target::middle_shares`]): this many times the normal's points.
pub const WIDER: usize = 4;

/// … a line there: its middle PCA eigenvalue at most this share of the
/// largest (a surface: above it, and its smallest not above
/// [`AMBIGUOUS_NORMAL`] of the middle one).
pub const WIDE_SURFACE: f64 = 0.1;

/// cos 30°: a normal within 30° of its wider neighbourhood's stands.
const AGREE_COS: f64 = 0.866_025_403_784_438_6;

/// A neighbourhood whose smallest PCA eigenvalue is above this share of
/// its middle one has no clear normal: its [middle share](Target::middle_shares)
/// is 0. Noise across a thin line, or a neighbourhood wider than the
/// surface is flat (a pipe's sparse far reaches), leaves the two smaller
/// eigenvalues alike and their eigenvectors any pair in their plane — on
/// the sewer's 60 slices, fused at 0.1 m cells, such points (λ_min/λ_mid
/// ≥ 0.2: 3–4 % of them) gave 42–51 % of what the pipe's axis seemed to
/// be seen by (BENCHMARKS.md, "Sparse scan lines in the mission's ICP
/// fusion").
pub const AMBIGUOUS_NORMAL: f64 = 0.2;

/// A neighbourhood's covariance `a` (symmetric 3×3): the unit
/// eigenvector of its smallest eigenvalue — the eigenvalues in closed
/// form (trigonometric solution of the characteristic cubic), the vector
/// as the longest cross product of two rows of A − λI, falling back to the
/// iterative solver when that vector is ill-defined (a repeated smallest
/// eigenvalue) — its middle eigenvalue over its largest (1 for a zero
/// matrix, 0 when the smallest eigenvalue is above [`AMBIGUOUS_NORMAL`]
/// of the middle one) and its smallest over its middle (0 when the
/// middle is 0).
fn pca_normal(a: &Matrix3<f64>) -> (Vector3<f64>, f64, f64) {
    let shares = |mut e: [f64; 3]| {
        e.sort_by(f64::total_cmp);
        let corner = if e[1] > 0.0 { (e[0].max(0.0) / e[1]).min(1.0) } else { 0.0 };
        let middle = if e[2] <= 0.0 {
            1.0
        } else if e[0] > AMBIGUOUS_NORMAL * e[1] {
            0.0
        } else {
            (e[1] / e[2]).max(0.0)
        };
        (middle, corner)
    };
    let iterative = || {
        let eig = SymmetricEigen::new(*a);
        let e = eig.eigenvalues;
        let (middle, corner) = shares([e[0], e[1], e[2]]);
        (eig.eigenvectors.column(e.imin()).into_owned(), middle, corner)
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
    let largest = q + 2.0 * p * phi.cos();
    let (middle, corner) = shares([lambda, largest, 3.0 * q - lambda - largest]);
    let m = a - Matrix3::identity() * lambda;
    let (r0, r1, r2) = (m.row(0).transpose(), m.row(1).transpose(), m.row(2).transpose());
    let best = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)]
        .into_iter()
        .max_by(|x, y| x.norm_squared().total_cmp(&y.norm_squared()))
        .unwrap_or_default();
    // |rᵢ × rⱼ| ~ p² when the other two eigenvalues are apart from λ.
    if best.norm_squared() > 1e-12 * p2 * p2 { (best.normalize(), middle, corner) } else { iterative() }
}

/// A stored point in f64.
pub(crate) fn point(p: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
}

#[cfg(test)]
mod tests {
    use nalgebra::UnitQuaternion;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::icp::IcpConfig;

    /// A source point's offset from a sample of a grid (0.1 m) is covered
    /// inside the grid and along or into it from its edge, and within half
    /// a spacing beyond the edge sample; beyond that it is beyond.
    #[test]
    fn a_point_beyond_the_sampled_surface_is_beyond() {
        let grid: Vec<Point3<f32>> =
            (0..20).flat_map(|i| (0..20).map(move |j| Point3::new(i as f32 * 0.1, j as f32 * 0.1, 0.0))).collect();
        let target = Target::new(&grid, 10).expect("target");
        let at = |i: usize, j: usize| i * 20 + j;
        assert!(!target.beyond(at(10, 10), &Vector3::new(0.04, 0.03, 0.0)));
        assert!(!target.beyond(at(10, 10), &Vector3::new(-0.05, 0.0, 0.0)));
        // The edge x = 1.9: outward within half a spacing, along, inward.
        assert!(!target.beyond(at(19, 10), &Vector3::new(0.04, 0.0, 0.0)));
        assert!(!target.beyond(at(19, 10), &Vector3::new(0.0, 0.08, 0.0)));
        assert!(!target.beyond(at(19, 10), &Vector3::new(-0.08, 0.0, 0.0)));
        // Outward past half a spacing, and out of a corner.
        assert!(target.beyond(at(19, 10), &Vector3::new(0.08, 0.0, 0.0)));
        assert!(target.beyond(at(19, 10), &Vector3::new(0.3, 0.1, 0.0)));
        assert!(target.beyond(at(19, 19), &Vector3::new(0.05, 0.05, 0.0)));
    }

    /// Lines of samples 1 cm apart along them and 0.2 m apart across (a
    /// lidar's rings on the ground): a point in the gap between two lines
    /// is covered by the next line, though every one of its sample's
    /// nearest neighbours lies on the sample's own line; past the last
    /// line, or out of the lines' end, it is beyond.
    #[test]
    fn a_point_between_a_scanners_lines_is_covered() {
        let lines: Vec<Point3<f32>> =
            (0..5).flat_map(|i| (0..200).map(move |j| Point3::new(j as f32 * 0.01, i as f32 * 0.2, 0.0))).collect();
        let up = vec![Vector3::z(); lines.len()];
        let target = Target::with_normals(&lines, up).expect("target");
        let at = |i: usize, j: usize| i * 200 + j;
        // The nearest neighbours alone do not see the next line.
        let hood = &target.local(at(2, 100)).hood;
        assert!(hood.points[..usize::from(hood.len)].iter().all(|&k| k as usize / 200 == 2));
        assert!(!target.beyond(at(2, 100), &Vector3::new(0.0, 0.09, 0.0)));
        assert!(!target.beyond(at(2, 100), &Vector3::new(0.01, -0.09, 0.0)));
        // Past the last line, and out of the lines' end.
        assert!(target.beyond(at(4, 100), &Vector3::new(0.0, 0.09, 0.0)));
        assert!(target.beyond(at(2, 199), &Vector3::new(0.09, 0.0, 0.0)));
    }

    /// The line test's share tells a scan line's artefact from a normal
    /// that stands: a pipe scanned in rings 8 cm apart (1 cm along each)
    /// has every point's ten nearest neighbours on its own ring, their
    /// normal along the axis, while the wider 40 span three rings and
    /// show the wall — flagged; a thin pole (a real line) and a ring on
    /// flat ground (its plane the ground's) keep their normals — 1.
    #[test]
    fn a_scan_lines_artefact_is_told_from_a_real_line() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut noise = |sigma: f32| rng.random_range(-sigma..sigma);
        let mut pipe = Vec::new();
        for ring in 0..12 {
            let x = ring as f32 * 0.08;
            for k in 0..314 {
                let a = k as f32 * 0.01 / 0.5;
                pipe.push(Point3::new(x + noise(2e-4), 0.5 * a.cos() + noise(2e-4), 0.5 * a.sin()));
            }
        }
        let t = Target::new(&pipe, 10).expect("pipe");
        let shares = t.middle_shares();
        // Away from the first and last rings.
        let inner: Vec<usize> = (0..pipe.len()).filter(|&i| (0.15..0.75).contains(&pipe[i].x)).collect();
        let along = |i: usize| t.normal(i).x.abs();
        let artefacts = inner.iter().filter(|&&i| along(i) > 0.9).count();
        assert!(artefacts > inner.len() * 9 / 10, "ring normals along the axis: {artefacts} of {}", inner.len());
        let flagged = inner.iter().filter(|&&i| shares[i] < 0.1).count();
        assert!(flagged > inner.len() * 9 / 10, "flagged {flagged} of {}", inner.len());
        // A pole: 2 m of points 1 cm apart, 1 mm of noise across.
        let pole: Vec<Point3<f32>> = (0..200).map(|k| Point3::new(noise(1e-3), noise(1e-3), k as f32 * 0.01)).collect();
        let t = Target::new(&pole, 10).expect("pole");
        assert!(t.middle_shares().iter().all(|&s| s == 1.0), "a pole's normals stand");
        // Flat ground in a lidar's rings 0.5 m apart, 1 cm along each.
        let mut ground = Vec::new();
        for ring in 0..3 {
            let r = 5.0 + ring as f32 * 0.5;
            for k in 0..(std::f32::consts::TAU * r / 0.01) as usize {
                let a = k as f32 * 0.01 / r;
                ground.push(Point3::new(r * a.cos(), r * a.sin(), noise(1e-4)));
            }
        }
        let t = Target::new(&ground, 10).expect("ground");
        let shares = t.middle_shares();
        assert!(
            shares.iter().all(|&s| s == 1.0),
            "{} of the ground's ring points flagged",
            shares.iter().filter(|&&s| s < 1.0).count()
        );
        // A blob (a pipe's sparse far stretch, seen in neighbourhoods wider
        // than the pipe): no surface at any scale.
        let blob: Vec<Point3<f32>> = (0..200).map(|_| Point3::new(noise(1.0), noise(1.0), noise(1.0))).collect();
        let t = Target::new(&blob, 10).expect("blob");
        let kept = t.middle_shares().iter().filter(|&&s| s == 1.0).count();
        assert!(kept < 20, "{kept} of a blob's 200 normals stand");
    }

    /// `pca_normal` agrees with nalgebra's `SymmetricEigen` on random
    /// covariances, from isotropic to nearly planar and linear: the
    /// smallest eigenvector, and the middle eigenvalue over the largest.
    #[test]
    fn pca_normal_matches_symmetric_eigen() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let turn = |rng: &mut ChaCha8Rng| {
            UnitQuaternion::from_euler_angles(
                rng.random_range(-3.0..3.0),
                rng.random_range(-1.5..1.5),
                rng.random_range(-3.0..3.0),
            )
            .to_rotation_matrix()
            .into_inner()
        };
        for k in 0..2000 {
            let r = turn(&mut rng);
            let thin = [1.0, 1e-2, 1e-4, 1e-6][k % 4];
            let d = Matrix3::from_diagonal(&Vector3::new(
                rng.random_range(0.5..1.0),
                rng.random_range(0.1..0.4),
                thin * rng.random_range(0.0..0.05),
            ));
            let a = r * d * r.transpose() * 1e-2;
            let eig = SymmetricEigen::new(a);
            let reference = eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned();
            let (v, _, _) = pca_normal(&a);
            assert!((v.norm() - 1.0).abs() < 1e-12);
            assert!(v.dot(&reference).abs() > 1.0 - 1e-9, "case {k}: {v} vs {reference}");
        }
        // Lines and planes: the middle eigenvalue from 0.1 % to 80 % of the largest.
        for k in 0..2000 {
            let r = turn(&mut rng);
            let largest = rng.random_range(0.5..1.0);
            let middle = largest * 10f64.powf(rng.random_range(-3.0..-0.1));
            // The smallest from 0 to 40 % of the middle: ambiguous from 20 %.
            let d = Matrix3::from_diagonal(&Vector3::new(largest, middle, middle * rng.random_range(0.0..0.4)));
            let a = r * d * r.transpose() * 1e-2;
            let mut e: Vec<f64> = SymmetricEigen::new(a).eigenvalues.iter().copied().collect();
            e.sort_by(f64::total_cmp);
            let (_, share, corner) = pca_normal(&a);
            let expected = if e[0] > AMBIGUOUS_NORMAL * e[1] { 0.0 } else { e[1] / e[2] };
            assert!((share - expected).abs() < 1e-9, "case {k}: {share} against eigenvalues {e:?}");
            assert!((corner - e[0] / e[1]).abs() < 1e-7, "case {k}: corner {corner} against eigenvalues {e:?}");
        }
        // Repeated eigenvalues go through the fallback and still give a unit
        // eigenvector; the two smaller alike: no clear normal.
        let (v, share, corner) = pca_normal(&Matrix3::from_diagonal(&Vector3::new(2.0, 1.0, 1.0)));
        assert!((v.x.abs() < 1e-12) && (v.norm() - 1.0).abs() < 1e-12);
        assert_eq!(share, 0.0, "a disc's normal is either of two directions");
        assert!((corner - 1.0).abs() < 1e-12, "a disc's corner share: {corner}");
        let (_, share, _) = pca_normal(&Matrix3::from_diagonal(&Vector3::new(1.0, 0.01, 0.01)));
        assert_eq!(share, 0.0, "a needle");
        let (_, share, corner) = pca_normal(&Matrix3::from_diagonal(&Vector3::new(1.0, 0.01, 0.002)));
        assert!((share - 0.01).abs() < 1e-12, "a flat strip: {share}");
        assert!((corner - 0.2).abs() < 1e-12, "a flat strip's corner share: {corner}");
        let (_, share, corner) = pca_normal(&Matrix3::from_diagonal(&Vector3::new(1.0, 0.5, 0.0)));
        assert!((share - 0.5).abs() < 1e-12, "a plane: {share}");
        assert_eq!(corner, 0.0, "a plane is no corner");
        assert_eq!(pca_normal(&Matrix3::zeros()).1, 1.0);
        assert_eq!(pca_normal(&Matrix3::zeros()).2, 0.0);
    }

    /// Normals estimated as they are needed are the PCA normals of each
    /// point's 10 nearest points (found here by brute force), turned to the
    /// viewpoint — also those estimated before the viewpoint was set — and
    /// a match whose source covers a quarter of the target estimates few
    /// of the target's normals.
    #[test]
    fn normals_estimated_as_needed_are_the_nearest_points_pca() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        // A wavy floor and a wall, 8 × 4 m.
        let mut cloud = Vec::new();
        for _ in 0..6000 {
            let (a, b) = (rng.random_range(0.0f32..8.0), rng.random_range(0.0f32..4.0));
            cloud.push(Point3::new(a, b, 0.05 * (a * 2.0).sin()));
            cloud.push(Point3::new(a, 4.0, b));
        }
        let mut target = Target::new(&cloud, 10).expect("target");
        assert!(target.local.iter().all(|l| l.get().is_none()), "nothing estimated at construction");
        let early = target.normal(7);
        let viewpoint = Point3::new(4.0, 2.0, 1.5);
        target.orient_normals_towards(&viewpoint);
        let source: Vec<Point3<f32>> = cloud.iter().filter(|p| p.x < 2.0).copied().collect();
        let config = IcpConfig { max_correspondence_m: 0.2, reject_back_faces: true, ..IcpConfig::default() };
        let r = crate::icp::align(&source, &target, &Isometry3::translation(0.03, 0.0, 0.01), &config).expect("icp");
        assert!(r.target_from_source.translation.vector.norm() < 1e-3, "{}", r.target_from_source);
        let estimated = target.local.iter().filter(|l| l.get().is_some()).count();
        assert!(estimated < cloud.len() * 2 / 5, "{estimated} of {} normals estimated", cloud.len());
        let normals = target.normals();
        assert!((normals[7].dot(&early).abs() - 1.0).abs() < 1e-12);
        assert!(normals[7].dot(&(viewpoint.coords - point(&target.points[7]))) >= 0.0, "turned when oriented");
        for (i, n) in normals.iter().enumerate().step_by(37) {
            let mut by_distance: Vec<(f32, usize)> =
                (0..cloud.len()).map(|k| (squared_distance(&target.points[i], &target.points[k]), k)).collect();
            by_distance.sort_by(|a, b| a.0.total_cmp(&b.0));
            let near: Vec<Vector3<f64>> = by_distance[..10].iter().map(|&(_, k)| point(&target.points[k])).collect();
            let mean = near.iter().sum::<Vector3<f64>>() / 10.0;
            let cov = near.iter().fold(Matrix3::zeros(), |s, q| s + (q - mean) * (q - mean).transpose());
            let eig = SymmetricEigen::new(cov);
            let pca = eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned();
            assert!(n.dot(&pca).abs() > 1.0 - 1e-9, "point {i}: {n} vs {pca}");
            assert!(n.dot(&(viewpoint.coords - point(&target.points[i]))) >= 0.0, "point {i} faces the viewpoint");
        }
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
}
