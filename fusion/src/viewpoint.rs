//! Where a scan's scanner stood, estimated from the scan itself, for the
//! scans that do not say (a PLY, a LAS): a scanner with fixed angular
//! steps leaves its returns apart in proportion to how far they are, so
//! each point's distance to its nearest neighbour, d, tells the range.
//! Two models, each a robust fit (soft-L1 in log spacing):
//!
//! - **the range**: log d = log |p − v| + c, from the scan's centroid and
//!   its frame's origin;
//! - **a turning scanner** (a 2D scanner on a rotating or nodding table, a
//!   terrestrial scanner's head): along a scan line its returns lie
//!   apart in proportion to the range, from one line to the next in
//!   proportion to their distance from the axis it turns about — the
//!   nearer of the two is d, the farther is the distance to the nearest
//!   point the other way (more than 60° from the first) — each stretched
//!   by 1 / cos of the angle at which the ray meets the surface (its
//!   normal from the 12 nearest points), and each kept above a floor (a
//!   scan thinned on a voxel grid keeps its points about a cell apart
//!   wherever its scanner's lay nearer). Fitted for the viewpoint, the
//!   axis, the two steps and the floor, from the range's viewpoint and
//!   the origin about each of the frame's axes; from those starts again
//!   without the floor where the best start's holds up fewer than a
//!   twentieth of its points, the kind kept refitted on more.
//!
//! The turning model is taken where it explains the farther spacing (≥
//! [`MIN_ACROSS_EXPLAINED`]) and the nearer at least as well as the range
//! does; else the range. Issue 38, session 68: the range alone put the
//! 3DTK hall's nodding scanner 0.7–0.8 m from where it stood (its returns
//! crowd near the nodding axis, not near the scanner) and the PCL room's
//! 0.12 m; the turning model finds both within 3 cm and the axes within a
//! degree — and the free-space test then names the 3DTK hall scan among
//! small_gicp's street frames at 21–22 %, as from the true scanners,
//! where from the range's estimates it was 13–14 % against a 12 % line.
//! A spinning LiDAR's frames (small_gicp's) fit the range (0.1–0.2 m).
//!
//! Issue 38: a scan of another place given among PLY scans was placed with
//! exit 0 — the free-space test that names such a scan needs the scanner's
//! position, and a PLY does not carry it. With the estimate the test runs.
//!
//! The estimate is only taken where the spacing follows the model: a scan
//! thinned on a grid coarser than most of its scanner's spacing, or
//! merged from stations far apart, spaces its points otherwise, and the
//! fit's share of the log spacing's spread it explains
//! ([`Estimate::explained`]) falls below [`MIN_EXPLAINED`]. Measured
//! (BENCHMARKS.md, "Estimated viewpoints"): real single scans within
//! 0.01–0.24 m of their scanner, explaining 0.80–1.00; the 3DTK scans
//! thinned to 2 cm cells 0.22–0.32 m (explaining 0.92–0.95; without the
//! floor, session 68, 0.5–1.2 m), to 5 cm not taken.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Point3, SMatrix, SVector, Vector3, Vector4};
use rand::SeedableRng;
use rayon::prelude::*;
use std::ops::Add;

use crate::scale::{finite, quantile};

/// The least share of the log spacing's spread (its MAD², about the
/// median) the viewpoint must explain for the estimate to be taken.
pub const MIN_EXPLAINED: f64 = 0.7;

/// At most this many points' spacings are fitted (drawn at random).
const SAMPLE: usize = 20_000;

/// The soft-L1 loss's width in log spacing (a factor of e^0.5 ≈ 1.6:
/// the spacing across a scan line and along it differ by that much).
const LOSS_WIDTH: f64 = 0.5;

/// Levenberg–Marquardt iterations per start.
const ITERATIONS: usize = 200;

/// At most this many of the sampled spacings are fitted by the turning
/// scanner's model from its six starts, and the best of them again on
/// [`TURNING_SAMPLE`] (the fits are most of the estimate's time).
const TURNING_STARTS_SAMPLE: usize = 1000;

/// At most this many of the sampled spacings fit the turning scanner.
const TURNING_SAMPLE: usize = 5000;

/// The nearest point "the other way" is more than 60° from the nearest
/// point's direction (|cos| below this).
const ACROSS_COS: f64 = 0.5;

/// The least share of the farther spacing's spread a turning scanner must
/// explain to be taken over the range alone: a spinning LiDAR's rings
/// (small_gicp's frames) fit the turning model's nearer spacing better
/// than the range does, from a viewpoint 1.9 m off, but not its farther.
pub const MIN_ACROSS_EXPLAINED: f64 = 0.9;

/// The most an oblique view stretches a spacing, in log (e³ ≈ 20: a
/// surface seen 87° from its normal).
const MAX_STRETCH: f64 = 3.0;

/// A scanner's position estimated from its scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// The scanner, in the scan's frame.
    pub viewpoint: Point3<f64>,
    /// The share of the log spacing's spread the range from `viewpoint`
    /// explains: 1 − (MAD of the residuals / MAD of log d)².
    pub explained: f64,
    /// Spacings fitted.
    pub points: usize,
    /// The axis the scanner turned about (unit, in the scan's frame), where
    /// the spacing showed one: its returns one scan line from the next lie
    /// apart in proportion to their distance from it.
    pub axis: Option<Vector3<f64>>,
}

impl Estimate {
    /// Whether the spacing follows the range well enough to take the
    /// estimate ([`MIN_EXPLAINED`]).
    pub fn taken(&self) -> bool {
        self.explained >= MIN_EXPLAINED
    }
}

/// Estimates where `points`' scanner stood. `None` when fewer than 16
/// points have neighbours both ways (nothing to fit).
pub fn estimate(points: &[Point3<f32>]) -> Option<Estimate> {
    let mut unique = finite(points);
    // Duplicates say nothing of the spacing (a PCL room scan holds each
    // return twice).
    unique.sort_unstable_by(|a, b| a.map(f32::to_bits).cmp(&b.map(f32::to_bits)));
    unique.dedup();
    if unique.len() < 16 {
        return None;
    }
    let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&unique).ok()?;
    // A random sample, not every n-th point: a spinning LiDAR's returns
    // come ring by ring within each firing, and every 4th of small_gicp's
    // frames is one ring, whose spacing alone put its scanner 1.2 m low.
    // Shuffled, as the turning scanner's starts take its first points.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let sample = rand::seq::index::sample(&mut rng, unique.len(), unique.len().min(SAMPLE)).into_vec();
    let spacings: Vec<Spacing> = sample.par_iter().filter_map(|&i| spacing(&tree, &unique, i)).collect();
    if spacings.len() < 16 {
        return None;
    }
    // About the centroid: a national grid's coordinates leave no digits
    // for the fit.
    let centroid = spacings.iter().map(|s| s.p).sum::<Vector3<f64>>() / spacings.len() as f64;
    let local: Vec<Spacing> = spacings.into_iter().map(|s| Spacing { p: s.p - centroid, ..s }).collect();
    let radius = quantile(local.iter().map(|s| s.p.norm()).collect(), 0.5).max(f64::MIN_POSITIVE);
    let nearest_logs: Vec<f64> = local.iter().map(|s| s.near).collect();
    let explains = |residuals: Vec<f64>, logs: Vec<f64>| {
        let spread = mad(logs);
        let e = if spread > 0.0 { 1.0 - (mad(residuals) / spread).powi(2) } else { 0.0 };
        if e.is_finite() { e } else { 0.0 }
    };

    // The range alone.
    let (x, _) = [Vector3::zeros(), -centroid]
        .into_iter()
        .map(|start| fit_range(&local, start, radius))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let ranged = Estimate {
        viewpoint: Point3::from(x.xyz() + centroid),
        explained: explains(local.iter().map(|s| range_residual(s, &x, radius)).collect(), nearest_logs.clone()),
        points: local.len(),
        axis: None,
    };

    // A scanner turning about an axis, from the range fit's viewpoint and
    // the frame's origin, about each of the frame's axes: each start on a
    // few of the spacings, the best on more.
    let starts: Vec<(Vector3<f64>, Vector3<f64>)> = [x.xyz(), -centroid]
        .into_iter()
        .flat_map(|v| [Vector3::x(), Vector3::y(), Vector3::z()].map(|u| (v, u)))
        .collect();
    let few = &local[..local.len().min(TURNING_STARTS_SAMPLE)];
    let more = &local[..local.len().min(TURNING_SAMPLE)];
    let rough = |with_floor: bool| {
        starts
            .par_iter()
            .map(|&(v, u)| fit_turning(few, Turning::start(few, v, u, radius, with_floor), radius))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|best| best.0)
    };
    // With the floor where the spacing shows one — where the starts' best
    // fit has it hold up at least a twentieth of their points —; else as
    // the scanner left it (a floor that holds nothing up only adds a way
    // to fit a spinning LiDAR's rings: a street wedge's, from 2.8 m off).
    // Decided on the starts' few points, so the refit on more runs once.
    let floored = rough(true)?;
    let start = if floored.engaged(few, radius) >= MIN_FLOOR_ENGAGED { floored } else { rough(false)? };
    let turning = fit_turning(more, start, radius).0;
    let (near, across): (Vec<f64>, Vec<f64>) = local
        .iter()
        .map(|s| {
            let (lo, hi) = turning.predicted(s, radius);
            (s.near - lo, s.across - hi)
        })
        .unzip();
    let explained = explains(near, nearest_logs);
    if explains(across, local.iter().map(|s| s.across).collect()) >= MIN_ACROSS_EXPLAINED
        && explained >= ranged.explained
    {
        Some(Estimate {
            viewpoint: Point3::from(turning.v + centroid),
            explained,
            points: local.len(),
            axis: Some(turning.u),
        })
    } else {
        Some(ranged)
    }
}

/// One sampled point (about the centroid, once centred), the log of its
/// distance to its nearest point, the log of its distance to the nearest
/// point the other way (more than 60° from the first), and its surface's
/// normal.
#[derive(Debug, Clone, Copy)]
struct Spacing {
    p: Vector3<f64>,
    near: f64,
    across: f64,
    normal: Vector3<f64>,
}

/// How many neighbours a point's spacing and normal are taken from.
const NEIGHBOURS: usize = 12;

/// `unique[i]`'s [`Spacing`]; `None` when all its neighbours lie one way
/// (a scan line or a ring far from any other).
fn spacing(tree: &ImmutableKdTree<f32, 3>, unique: &[[f32; 3]], i: usize) -> Option<Spacing> {
    let k = std::num::NonZero::new((NEIGHBOURS + 1).min(tree.size()))?;
    let q = unique[i];
    let p = Vector3::new(f64::from(q[0]), f64::from(q[1]), f64::from(q[2]));
    let neighbours: Vec<Vector3<f64>> = tree
        .query(&q)
        .nearest_n::<SquaredEuclidean<f32>>(k)
        .execute()
        .into_iter()
        .filter(|nn| nn.distance > 0.0)
        .map(|nn| {
            let n = unique[nn.item as usize];
            Vector3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2])) - p
        })
        .collect();
    let first = neighbours.first()?;
    let d1 = first.norm();
    let d2 = neighbours.iter().find(|n| (n.dot(first) / (n.norm() * d1)).abs() < ACROSS_COS)?.norm();
    let mean = neighbours.iter().sum::<Vector3<f64>>() / (neighbours.len() + 1) as f64;
    let scatter = neighbours.iter().chain(std::iter::once(&Vector3::zeros())).fold(Matrix3::zeros(), |m, n| {
        let c = n - mean;
        m + c * c.transpose()
    });
    let eigen = scatter.symmetric_eigen();
    let smallest = eigen.eigenvalues.imin();
    Some(Spacing { p, near: d1.ln(), across: d2.ln(), normal: eigen.eigenvectors.column(smallest).into_owned() })
}

/// log d − log |p − v| − c for x = (v, c), d the distance to the nearest
/// point; the range kept above a millionth of the scan's radius.
fn range_residual(s: &Spacing, x: &Vector4<f64>, radius: f64) -> f64 {
    s.near - (s.p - x.xyz()).norm().max(1e-6 * radius).ln() - x.w
}

/// Soft-L1 cost of a residual.
fn loss(r: f64) -> f64 {
    let z = (r / LOSS_WIDTH).powi(2);
    2.0 * ((1.0 + z).sqrt() - 1.0)
}

/// Levenberg–Marquardt on x = (v, c) of [`range_residual`] from viewpoint
/// `start` (about the centroid); (x, cost).
fn fit_range(local: &[Spacing], start: Vector3<f64>, radius: f64) -> (Vector4<f64>, f64) {
    // c at the start: the median of log d − log r.
    let c0 = quantile(
        local.iter().map(|s| range_residual(s, &Vector4::new(start.x, start.y, start.z, 0.0), radius)).collect(),
        0.5,
    );
    minimise(
        Vector4::new(start.x, start.y, start.z, c0),
        |x| in_order(local, |s| loss(range_residual(s, x, radius))),
        |x| {
            in_order(local, |s| {
                let r = range_residual(s, x, radius);
                let d = s.p - x.xyz();
                let r2 = d.norm_squared().max((1e-6 * radius).powi(2));
                // ∂r/∂v = (p − v)/|p − v|², ∂r/∂c = −1.
                let j = Vector4::new(d.x / r2, d.y / r2, d.z / r2, -1.0);
                let w = weight(r);
                Normal(w * j * j.transpose(), w * r * j)
            })
        },
        |x, step| x + step,
    )
}

/// A scanner that turns about an axis through it (a 2D scanner on a
/// rotating or nodding table; a terrestrial scanner's head): along its
/// scan line its returns lie `e^along` × the range apart, from one line to
/// the next `e^round` × their distance from the axis; each stretched where
/// the surface is seen obliquely, by 1 / cos of the angle between the
/// surface's normal and the ray, within the surface's plane.
#[derive(Debug, Clone, Copy)]
struct Turning {
    /// The scanner (about the centroid).
    v: Vector3<f64>,
    along: f64,
    round: f64,
    /// The axis (unit).
    u: Vector3<f64>,
    /// The least log spacing (a scan thinned on a grid keeps its points
    /// about a cell apart wherever the scanner's were nearer).
    floor: f64,
}

impl Turning {
    /// The log spacings `s`'s point would have, the nearer and the
    /// farther; ranges kept above a millionth of the scan's radius.
    fn predicted(&self, s: &Spacing, radius: f64) -> (f64, f64) {
        let (a, b) = self.unfloored(s, radius);
        (floored(a, self.floor), floored(b, self.floor))
    }

    /// [`Turning::predicted`] before the floor.
    fn unfloored(&self, s: &Spacing, radius: f64) -> (f64, f64) {
        let (a, b) = self.terms(s, radius);
        (a.min(b), a.max(b))
    }

    /// The log spacing along the scan line and from one line to the next.
    fn terms(&self, s: &Spacing, radius: f64) -> (f64, f64) {
        let least = 1e-6 * radius;
        let q = s.p - self.v;
        let r = q.norm().max(least);
        let e = q / r;
        let across = self.u.cross(&e);
        let sin = across.norm();
        let rho = (sin * r).max(least);
        // Round the axis; on the axis any direction across the ray.
        let round =
            if sin > 1e-12 { across / sin } else { e.cross(&Vector3::x()).try_normalize(0.0).unwrap_or(Vector3::y()) };
        let along = e.cross(&round);
        let facing = s.normal.dot(&e).abs().max(1e-3);
        let stretch = |t: &Vector3<f64>| (0.5 * (s.normal.dot(t) / facing).powi(2).ln_1p()).min(MAX_STRETCH);
        let a = self.along + r.ln() + stretch(&along);
        let b = self.round + rho.ln() + stretch(&round);
        (a, b)
    }

    /// The scanner at `v` turning about `u`, the terms' constants the
    /// median of the nearer spacing against each.
    fn start(spacings: &[Spacing], v: Vector3<f64>, u: Vector3<f64>, radius: f64, with_floor: bool) -> Turning {
        let least = 1e-6 * radius;
        let offset = |distance: &dyn Fn(&Vector3<f64>) -> f64| {
            quantile(spacings.iter().map(|s| s.near - distance(&(s.p - v)).max(least).ln()).collect(), 0.5)
        };
        // The floor at the nearer spacing's low quantile (or none).
        let floor = if with_floor {
            quantile(spacings.iter().map(|s| s.near).collect(), FLOOR_START_QUANTILE)
        } else {
            f64::NEG_INFINITY
        };
        Turning { v, along: offset(&|q| q.norm()), round: offset(&|q| q.cross(&u).norm()), u, floor }
    }

    /// Moved by `dx` = (v, along, round, the axis's turn along two
    /// directions across it, and the floor).
    fn moved(&self, dx: &Vector8) -> Turning {
        let (t1, t2) = across(&self.u);
        Turning {
            v: self.v + dx.fixed_rows::<3>(0),
            along: self.along + dx[3],
            round: self.round + dx[4],
            u: (self.u + t1 * dx[5] + t2 * dx[6]).normalize(),
            floor: self.floor + dx[7],
        }
    }

    /// The share of `spacings` whose nearer spacing the floor holds up.
    fn engaged(&self, spacings: &[Spacing], radius: f64) -> f64 {
        let held = spacings.iter().filter(|s| self.unfloored(s, radius).0 < self.floor).count();
        held as f64 / spacings.len() as f64
    }

    /// The soft-L1 cost of its residuals at `spacings`.
    fn cost(&self, spacings: &[Spacing], radius: f64) -> f64 {
        in_order(spacings, |s| {
            let (lo, hi) = self.predicted(s, radius);
            loss(s.near - lo) + loss(s.across - hi)
        })
    }
}

type Vector8 = SVector<f64, 8>;

/// How sharply the floor bends the spacing: log (d^p + floor^p)^(1/p),
/// e^(0.17) where the two meet.
const FLOOR_SHARPNESS: f64 = 4.0;

/// The quantile of the nearer spacing the floor starts at.
const FLOOR_START_QUANTILE: f64 = 0.05;

/// The least share of the points the floor must hold up to be kept.
const MIN_FLOOR_ENGAGED: f64 = 0.05;

/// The log spacing `x` kept above the log `floor`, smoothly.
fn floored(x: f64, floor: f64) -> f64 {
    let m = x.max(floor);
    m + ((FLOOR_SHARPNESS * (x - m)).exp() + (FLOOR_SHARPNESS * (floor - m)).exp()).ln() / FLOOR_SHARPNESS
}

/// ∂[`floored`]/∂x (and 1 − it, ∂/∂floor).
fn floored_slope(x: f64, floor: f64) -> f64 {
    1.0 / (1.0 + (FLOOR_SHARPNESS * (floor - x)).exp())
}

/// Two unit directions across `u` and across each other.
fn across(u: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let other = if u.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let t1 = u.cross(&other).normalize();
    (t1, u.cross(&t1))
}

/// Levenberg–Marquardt on a [`Turning`] scanner from `start` (without a
/// floor where it starts with none): the viewpoint's and the axis's
/// columns by forward differences (the nearer and farther spacings swap
/// where the two terms meet); (the scanner, cost).
fn fit_turning(spacings: &[Spacing], start: Turning, radius: f64) -> (Turning, f64) {
    let steps = [1e-6 * radius, 1e-6 * radius, 1e-6 * radius, 1e-6, 1e-6, 1e-6, 1e-6];
    minimise(
        start,
        |t| t.cost(spacings, radius),
        |t| {
            // The viewpoint's and the axis's columns by differences,
            // through the floor's slope; the two steps' and the floor's
            // by their slopes (a step moves its own term alone).
            const BY_DIFFERENCES: [usize; 5] = [0, 1, 2, 5, 6];
            let nudged = BY_DIFFERENCES.map(|k| t.moved(&(Vector8::ith(k, 1.0) * steps[k])));
            let mut normal = in_order(spacings, |s| {
                let (along, round) = t.terms(s, radius);
                let (a, b) = (along.min(round), along.max(round));
                let (lo, hi) = (floored(a, t.floor), floored(b, t.floor));
                let (slope_a, slope_b) = (floored_slope(a, t.floor), floored_slope(b, t.floor));
                let (r1, r2) = (s.near - lo, s.across - hi);
                let (mut j1, mut j2) = (Vector8::zeros(), Vector8::zeros());
                for (&k, n) in BY_DIFFERENCES.iter().zip(&nudged) {
                    let (a_k, b_k) = n.unfloored(s, radius);
                    j1[k] = -slope_a * (a_k - a) / steps[k];
                    j2[k] = -slope_b * (b_k - b) / steps[k];
                }
                let (k_near, k_far) = if along <= round { (3, 4) } else { (4, 3) };
                j1[k_near] = -slope_a;
                j2[k_far] = -slope_b;
                j1[7] = -(1.0 - slope_a);
                j2[7] = -(1.0 - slope_b);
                let (w1, w2) = (weight(r1), weight(r2));
                Normal(j1 * j1.transpose() * w1 + j2 * j2.transpose() * w2, j1 * (w1 * r1) + j2 * (w2 * r2))
            });
            // No floor: its column is empty, and it stays where it is.
            if start.floor == f64::NEG_INFINITY {
                normal.0[(7, 7)] = 1.0;
            }
            normal
        },
        |t, step| t.moved(step),
    )
}

/// Levenberg–Marquardt from `start`: `normal` gives the reweighted normal
/// equations (H, g) of the soft-L1 loss at a point, `cost` the loss,
/// `moved` the point a step away; until a step gains less than a
/// millionth of the cost, or [`ITERATIONS`]. (The point, its cost.)
fn minimise<T, const N: usize>(
    start: T,
    cost: impl Fn(&T) -> f64,
    normal: impl Fn(&T) -> Normal<N>,
    moved: impl Fn(&T, &SVector<f64, N>) -> T,
) -> (T, f64) {
    let mut x = start;
    let mut current = cost(&x);
    let mut lambda = 1e-3;
    for _ in 0..ITERATIONS {
        let Normal(h, g) = normal(&x);
        let mut improved = false;
        while lambda < 1e12 {
            let damped = h + SMatrix::<f64, N, N>::from_diagonal(&h.diagonal()) * lambda;
            let Some(step) = damped.cholesky().map(|c| c.solve(&-g)) else {
                lambda *= 10.0;
                continue;
            };
            let next = moved(&x, &step);
            let c = cost(&next);
            if c.is_finite() && c < current {
                improved = current - c >= 1e-6 * current;
                x = next;
                current = c;
                lambda = (lambda / 10.0).max(1e-9);
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    (x, current)
}

/// The sum of `f` over `spacings`, in parallel but in a fixed order (the
/// same estimate on every run, whatever the threads).
fn in_order<S: Add<Output = S> + Send>(spacings: &[Spacing], f: impl Fn(&Spacing) -> S + Sync) -> S {
    let add = |a: S, b: S| a + b;
    let parts: Vec<S> =
        spacings.par_chunks(256).map(|chunk| chunk.iter().map(&f).reduce(add).expect("a chunk")).collect();
    parts.into_iter().reduce(add).expect("spacings to sum")
}

/// Normal equations H x = g, summed over residuals.
#[derive(Debug, Clone, Copy)]
struct Normal<const N: usize>(SMatrix<f64, N, N>, SVector<f64, N>);

impl<const N: usize> Add for Normal<N> {
    type Output = Self;
    fn add(self, other: Self) -> Self {
        Normal(self.0 + other.0, self.1 + other.1)
    }
}

/// The soft-L1 loss's weight of a residual (reweighted least squares).
fn weight(r: f64) -> f64 {
    1.0 / (1.0 + (r / LOSS_WIDTH).powi(2)).sqrt()
}

/// The median absolute deviation about the median (not scaled).
fn mad(values: Vec<f64>) -> f64 {
    let median = quantile(values.clone(), 0.5);
    quantile(values.into_iter().map(|v| (v - median).abs()).collect(), 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Where the ray from `at` along `u` leaves a room's walls, floor and
    /// ceiling.
    fn hit(at: Vector3<f64>, u: Vector3<f64>) -> Point3<f32> {
        let half = Vector3::new(6.0, 4.0, 1.5);
        let t = (0..3)
            .filter(|&k| u[k].abs() > 1e-12)
            .map(|k| (half[k] * u[k].signum() - at[k]) / u[k])
            .fold(f64::INFINITY, f64::min);
        let p = at + u * t;
        Point3::new(p.x as f32, p.y as f32, p.z as f32)
    }

    /// The room as a scanner at `at` with a fixed angular step returns
    /// it.
    fn scanned_box(at: Vector3<f64>, step_deg: f64) -> Vec<Point3<f32>> {
        let mut points = Vec::new();
        let step = step_deg.to_radians();
        let mut elevation = -std::f64::consts::FRAC_PI_2 + step;
        while elevation < std::f64::consts::FRAC_PI_2 {
            let mut azimuth = 0.0;
            while azimuth < std::f64::consts::TAU {
                let u = Vector3::new(elevation.cos() * azimuth.cos(), elevation.cos() * azimuth.sin(), elevation.sin());
                points.push(hit(at, u));
                azimuth += step / elevation.cos().max(0.05);
            }
            elevation += step;
        }
        points
    }

    /// The room as a 2D scanner at `at` turning all round `axis` returns
    /// it: scan lines 1° a step, from one line to the next 0.5° about the
    /// axis (as the 3DTK hall's nodding scanner: its lines meet on the
    /// axis).
    fn nodded_box(at: Vector3<f64>, axis: Vector3<f64>) -> Vec<Point3<f32>> {
        let (u, forward) = (axis.normalize(), axis.cross(&Vector3::z()).normalize());
        let up = u.cross(&forward);
        let mut points = Vec::new();
        for tilt in (-360..360).map(|k| f64::from(k) * 0.5_f64.to_radians()) {
            let f = forward * tilt.cos() + up * tilt.sin();
            for angle in (-89..=89).map(|k| f64::from(k).to_radians()) {
                points.push(hit(at, f * angle.cos() + u * angle.sin()));
            }
        }
        points
    }

    #[test]
    fn a_scanner_is_found_where_it_stood_at_any_scale_and_place() {
        let at = Vector3::new(1.5, -1.0, 0.2);
        let points = scanned_box(at, 0.5);
        let e = estimate(&points).expect("an estimate");
        assert!((e.viewpoint.coords - at).norm() < 0.05, "{e:?}");
        assert!(e.taken(), "{e:?}");
        // At 1:100, at 100:1 and a kilometre from the frame's origin: the
        // same place.
        for (scale, offset) in
            [(0.01, Vector3::zeros()), (100.0, Vector3::zeros()), (1.0, Vector3::new(800.0, -600.0, 50.0))]
        {
            let moved: Vec<Point3<f32>> =
                points.iter().map(|p| Point3::from(p.coords.cast::<f64>() * scale + offset).cast::<f32>()).collect();
            let m = estimate(&moved).expect("an estimate");
            let expected = at * scale + offset;
            assert!((m.viewpoint.coords - expected).norm() < 0.05 * scale, "{m:?} vs {expected:?}");
            assert!(m.taken(), "{m:?}");
        }
    }

    #[test]
    fn a_nodding_scanner_is_found_on_its_axis_at_any_scale_and_place() {
        let (at, axis) = (Vector3::new(1.5, -1.0, 0.2), Vector3::new(0.3, 1.0, 0.0).normalize());
        let points = nodded_box(at, axis);
        for (scale, offset) in [
            (1.0, Vector3::zeros()),
            (0.01, Vector3::zeros()),
            (100.0, Vector3::zeros()),
            (1.0, Vector3::new(800.0, -600.0, 50.0)),
        ] {
            let moved: Vec<Point3<f32>> =
                points.iter().map(|p| Point3::from(p.coords.cast::<f64>() * scale + offset).cast::<f32>()).collect();
            let e = estimate(&moved).expect("an estimate");
            let expected = at * scale + offset;
            assert!((e.viewpoint.coords - expected).norm() < 0.05 * scale, "{e:?} vs {expected:?}");
            let found = e.axis.expect("the axis");
            assert!(found.dot(&axis).abs() > 1.0_f64.to_radians().cos(), "{found:?} vs {axis:?}");
            assert!(e.taken() && e.explained > 0.9, "{e:?}");
        }
    }

    #[test]
    fn the_floors_slope_is_its_derivative() {
        let h = 1e-6;
        for (x, floor) in [(-3.0, -3.0), (-2.0, -3.5), (-4.0, -3.0), (1.0, -9.0), (-9.0, 1.0)] {
            let by_x = (floored(x + h, floor) - floored(x - h, floor)) / (2.0 * h);
            let by_floor = (floored(x, floor + h) - floored(x, floor - h)) / (2.0 * h);
            assert!((floored_slope(x, floor) - by_x).abs() < 1e-8, "{x} {floor}");
            assert!((1.0 - floored_slope(x, floor) - by_floor).abs() < 1e-8, "{x} {floor}");
        }
        // Far above the floor, the spacing itself.
        assert!((floored(-1.0, -9.0) + 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_nodding_scan_thinned_where_its_returns_crowd_is_still_found() {
        // 3 cm cells: nearer than about 2.5 m from the axis the scanner's
        // lines lie closer than a cell, and one point a cell is kept.
        let (at, axis) = (Vector3::new(1.5, -1.0, 0.2), Vector3::new(0.3, 1.0, 0.0).normalize());
        let cell = 0.03f32;
        let mut seen = std::collections::HashSet::new();
        let thinned: Vec<Point3<f32>> = nodded_box(at, axis)
            .into_iter()
            .filter(|p| seen.insert([p.x, p.y, p.z].map(|v| (v / cell).floor() as i64)))
            .collect();
        let e = estimate(&thinned).expect("an estimate");
        assert!((e.viewpoint.coords - at).norm() < 0.1, "{e:?}");
        assert!(e.taken() && e.axis.is_some(), "{e:?}");
    }

    #[test]
    fn a_scan_thinned_on_a_grid_says_nothing_of_its_scanner() {
        let points = scanned_box(Vector3::new(1.5, -1.0, 0.2), 0.25);
        let cell = 0.2f32;
        let mut seen = std::collections::HashSet::new();
        let thinned: Vec<Point3<f32>> =
            points.into_iter().filter(|p| seen.insert([p.x, p.y, p.z].map(|v| (v / cell).floor() as i64))).collect();
        let e = estimate(&thinned).expect("an estimate");
        assert!(!e.taken(), "{e:?}");
    }
}
