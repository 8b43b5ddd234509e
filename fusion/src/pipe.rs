//! Pipe fitting (seed 000 §5): a tube (a, b, r) matched into a scanned pipe,
//! then a deviation map of every point against the fitted surface with the
//! deviations grouped into obstacles and deformations.
//!
//! **Closest point.** With n = (b − a)/‖b − a‖ (a unit vector, so the seed's
//! ⟨n, n⟩ is 1) and s = ⟨x − a, n⟩ the projection of x on the axis, the
//! closest point on the surface of the tube is
//!
//! c = a + s·n + r·u/‖u‖,  u = (x − a) − s·n,
//!
//! i.e. the seed's eq (3) with the axis point a added (eq (3) as printed,
//! `s·n + r·(x − s·n)/‖x − s·n‖`, holds only for a = 0). For the finite
//! tube s is clamped to [0, ‖b − a‖], which leaves the radial direction u
//! unchanged. u = 0 (x on the axis) has no unique answer; we pick a fixed
//! direction perpendicular to n.
//!
//! **Fit.** 1. start from a default tube; 2. ICP: pair every point within
//! the gate with its closest surface point and move the tube by Horn's
//! closed-form rigid motion; 3. adapt the radius: for a fixed axis the
//! radius minimising Σ(‖uᵢ‖ − r)² is the mean of ‖uᵢ‖ — the end point of
//! the seed's "gradually enlarged or reduced" in closed form. 2–3 repeat on
//! reduced points, then on all points. The gate shrinks to
//! `gate_sigmas` robust standard deviations (1.4826·MAD), so obstacles and
//! deformations do not pull the fit.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::error::{FusionError, Result};
use crate::icp::solve::horn_rotation;

/// A finite tube: axis from `a` to `b`, radius `radius_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pipe {
    /// One end of the axis.
    pub a: Point3<f64>,
    /// The other end of the axis.
    pub b: Point3<f64>,
    /// Radius, metres.
    pub radius_m: f64,
}

impl Pipe {
    /// Unit axis direction a → b.
    pub fn direction(&self) -> Vector3<f64> {
        (self.b - self.a).normalize()
    }

    /// Axis length, metres.
    pub fn length_m(&self) -> f64 {
        (self.b - self.a).norm()
    }

    /// (s, u, n): the clamped axial coordinate of `x`, its radial vector and
    /// the unit axis.
    fn project(&self, x: &Point3<f64>) -> (f64, Vector3<f64>, Vector3<f64>) {
        let axis = self.b - self.a;
        let length = axis.norm();
        let n = axis / length;
        let s = (x - self.a).dot(&n);
        let u = (x - self.a) - s * n;
        (s.clamp(0.0, length), u, n)
    }

    /// The closest point on the tube's surface (see the module docs).
    pub fn closest_point(&self, x: &Point3<f64>) -> Point3<f64> {
        let (s, u, n) = self.project(x);
        let radial = u.try_normalize(1e-12).unwrap_or_else(|| perpendicular(&n));
        self.a + s * n + self.radius_m * radial
    }

    /// Signed radial deviation of `x` from the surface: positive outside the
    /// tube (the wall is farther out than the model), negative inside
    /// (something intrudes into the pipe).
    pub fn deviation_m(&self, x: &Point3<f64>) -> f64 {
        self.project(x).1.norm() - self.radius_m
    }

    /// The tube moved by `motion`.
    fn moved(&self, motion: &nalgebra::Isometry3<f64>) -> Pipe {
        Pipe { a: motion * self.a, b: motion * self.b, radius_m: self.radius_m }
    }

    fn check(&self, what: &str) -> Result<()> {
        let finite = self.a.iter().chain(self.b.iter()).all(|v| v.is_finite());
        if !finite || self.length_m().is_nan() || self.length_m() <= 1e-6 {
            return Err(FusionError::OutOfRange {
                what: format!("{what} axis length (m)"),
                value: self.length_m(),
                expected: "finite points a ≠ b".into(),
            });
        }
        FusionError::require_positive(&format!("{what} radius (m)"), self.radius_m)
    }
}

fn perpendicular(n: &Vector3<f64>) -> Vector3<f64> {
    let helper = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    n.cross(&helper).normalize()
}

/// Pipe-fit settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipeConfig {
    /// Reduced-points cell for the coarse stage, metres. Default 0.05.
    pub coarse_voxel_m: f64,
    /// Points farther than this from the default tube are ignored at first,
    /// metres. Default 0.15.
    pub initial_gate_m: f64,
    /// The gate afterwards, in robust standard deviations. Default 3.
    pub gate_sigmas: f64,
    /// The gate never shrinks below this, metres. Default 0.01.
    pub min_gate_m: f64,
    /// Iteration cap per stage. Default 100.
    pub max_iterations: usize,
    /// Converged when the axis ends and radius move less than this, metres.
    /// Default 1e-6.
    pub tolerance_m: f64,
}

impl Default for PipeConfig {
    fn default() -> Self {
        Self {
            coarse_voxel_m: 0.05,
            initial_gate_m: 0.15,
            gate_sigmas: 3.0,
            min_gate_m: 0.01,
            max_iterations: 100,
            tolerance_m: 1e-6,
        }
    }
}

/// A fitted pipe.
#[derive(Debug, Clone, PartialEq)]
pub struct PipeFit {
    /// The tube in the points' frame.
    pub pipe: Pipe,
    /// Iterations over both stages.
    pub iterations: usize,
    /// Whether the fine stage converged before its cap.
    pub converged: bool,
    /// Points inside the final gate.
    pub inliers: usize,
    /// RMS deviation of the inliers, metres.
    pub rmse_m: f64,
    /// The final gate, metres.
    pub gate_m: f64,
}

/// Fits a tube into `points` from the default tube `initial`.
pub fn fit_pipe(points: &[Point3<f32>], initial: &Pipe, config: &PipeConfig) -> Result<PipeFit> {
    initial.check("default tube")?;
    for (what, v) in [
        ("pipe initial gate (m)", config.initial_gate_m),
        ("pipe gate (robust σ)", config.gate_sigmas),
        ("pipe minimum gate (m)", config.min_gate_m),
        ("pipe tolerance (m)", config.tolerance_m),
        ("pipe iteration cap", config.max_iterations as f64),
    ] {
        FusionError::require_positive(what, v)?;
    }
    let coarse = scanner::reduced_points(points, config.coarse_voxel_m)?;
    let to64 = |v: &[Point3<f32>]| v.iter().map(|p| p.cast::<f64>()).collect::<Vec<_>>();
    let (mut pipe, mut gate) = (*initial, config.initial_gate_m);
    let mut iterations = 0;
    let mut last = (false, 0, 0.0);
    for stage in [to64(&coarse), to64(points)] {
        let mut converged = false;
        for _ in 0..config.max_iterations {
            iterations += 1;
            let inliers: Vec<&Point3<f64>> = stage.iter().filter(|x| pipe.deviation_m(x).abs() <= gate).collect();
            if inliers.len() < 6 {
                return Err(FusionError::TooFewCorrespondences {
                    found: inliers.len(),
                    needed: 6,
                    max_distance_m: gate,
                    iteration: iterations - 1,
                });
            }
            // 2. ICP step: the tube moves onto the points (c → x).
            let n = inliers.len() as f64;
            let pairs: Vec<(Point3<f64>, Point3<f64>)> = inliers.iter().map(|x| (pipe.closest_point(x), **x)).collect();
            let cc = pairs.iter().fold(Vector3::zeros(), |s, (c, _)| s + c.coords) / n;
            let cx = pairs.iter().fold(Vector3::zeros(), |s, (_, x)| s + x.coords) / n;
            let s = pairs.iter().fold(Matrix3::zeros(), |s, (c, x)| s + (c.coords - cc) * (x.coords - cx).transpose());
            let r: UnitQuaternion<f64> = horn_rotation(&s);
            let motion = nalgebra::Isometry3::from_parts(Translation3::from(cx - r * cc), r);
            let mut next = pipe.moved(&motion);
            // 3. Radius: the mean radial distance of the inliers.
            let radial: Vec<f64> = inliers.iter().map(|x| next.project(x).1.norm()).collect();
            next.radius_m = radial.iter().sum::<f64>() / n;
            let step =
                (next.a - pipe.a).norm().max((next.b - pipe.b).norm()).max((next.radius_m - pipe.radius_m).abs());
            pipe = next;
            // The gate follows the robust spread of the inliers' deviations.
            let mut dev: Vec<f64> = radial.iter().map(|r| (r - pipe.radius_m).abs()).collect();
            let mid = dev.len() / 2;
            let mad = *dev.select_nth_unstable_by(mid, f64::total_cmp).1;
            gate = (config.gate_sigmas * 1.4826 * mad).max(config.min_gate_m);
            let sq: f64 = dev.iter().map(|d| d * d).sum();
            last = (converged, inliers.len(), (sq / n).sqrt());
            if step < config.tolerance_m {
                converged = true;
                break;
            }
        }
        last.0 = converged;
    }
    pipe.check("fitted tube")?;
    Ok(PipeFit { pipe, iterations, converged: last.0, inliers: last.1, rmse_m: last.2, gate_m: gate })
}

/// A scan's points within this share of the radius from a tube's
/// surface are on it ([`tube_of`]).
pub const TUBE_BAND: f64 = 0.05;
/// A scan is a pipe's when at least this share of its points is on the
/// tube ([`Tube::is_pipe`]).
pub const TUBE_SHARE: f64 = 0.8;
/// … and they fill at least this share of the 36 sectors of 10° about
/// its axis (a plane fits a tube of a huge radius, seen from one side).
pub const TUBE_AROUND: f64 = 0.75;
/// [`tube_of`] fits at most this many of a scan's points (evenly taken).
const TUBE_SAMPLE: usize = 20_000;
/// [`tube_of`] fits a tube from an axis only where this share of the
/// points lies within [`SCREEN_BAND`] of the radius from its first tube.
const SCREEN_SHARE: f64 = 0.5;
const SCREEN_BAND: f64 = 0.25;
const SECTORS: usize = 36;

/// The tube a scan's points lie on ([`tube_of`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Tube {
    /// The fitted tube, in the points' frame.
    pub pipe: Pipe,
    /// The share of the points within [`TUBE_BAND`] of the radius from its
    /// surface.
    pub share: f64,
    /// The share of the 36 sectors of 10° about the axis those points
    /// fill (a sector counts with at least a fifth of the mean sector's
    /// points).
    pub around: f64,
}

impl Tube {
    /// Whether the scan is a pipe's: [`TUBE_SHARE`] of its points on the
    /// tube, all around it ([`TUBE_AROUND`]).
    pub fn is_pipe(&self) -> bool {
        self.share >= TUBE_SHARE && self.around >= TUBE_AROUND
    }
}

/// The tube `points` lie on best: fitted ([`fit_pipe`], its gates scaled to
/// the tube's first radius) from each of their three principal axes
/// through their centroid, with the median distance from it as the
/// radius, the fit with the most points on it kept. Scale- and
/// frame-free: every length is the radius's share. A tube wider than
/// the points' reach (their 90th-percentile distance from the centroid:
/// a plane is a tube of a huge radius) is none, and an axis is fitted
/// only where half the points lie within a quarter of the radius from
/// its first tube (a box's or a plane's do not: the fit's cost spared).
/// `None` when no axis passes or no fit holds.
pub fn tube_of(points: &[Point3<f32>]) -> Option<Tube> {
    let step = points.len().div_ceil(TUBE_SAMPLE).max(1);
    let sample: Vec<Point3<f32>> =
        points.iter().step_by(step).copied().filter(|p| p.coords.iter().all(|v| v.is_finite())).collect();
    if sample.len() < 6 {
        return None;
    }
    let n = sample.len() as f64;
    let c = sample.iter().fold(Vector3::zeros(), |s, p| s + p.coords.cast::<f64>()) / n;
    let spread = sample.iter().fold(Matrix3::zeros(), |s, p| {
        let d = p.coords.cast::<f64>() - c;
        s + d * d.transpose()
    }) / n;
    let mut reach: Vec<f64> = sample.iter().map(|p| (p.coords.cast::<f64>() - c).norm()).collect();
    let k = (reach.len() * 9) / 10;
    let reach = *reach.select_nth_unstable_by(k.min(sample.len() - 1), f64::total_cmp).1;
    let axes = spread.symmetric_eigen().eigenvectors;
    (0..3)
        .filter_map(|i| {
            let axis: Vector3<f64> = axes.column(i).into_owned();
            let along: Vec<f64> = sample.iter().map(|p| (p.coords.cast::<f64>() - c).dot(&axis)).collect();
            let mut radial: Vec<f64> =
                sample.iter().zip(&along).map(|(p, &s)| (p.coords.cast::<f64>() - c - s * axis).norm()).collect();
            let mid = radial.len() / 2;
            let r0 = *radial.select_nth_unstable_by(mid, f64::total_cmp).1;
            let (lo, hi) = along.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &s| (l.min(s), h.max(s)));
            let near = radial.iter().filter(|&&r| (r - r0).abs() <= SCREEN_BAND * r0).count();
            if !(r0 > 0.0 && hi > lo) || (near as f64) < SCREEN_SHARE * radial.len() as f64 {
                return None;
            }
            let start = Pipe { a: Point3::from(c + lo * axis), b: Point3::from(c + hi * axis), radius_m: r0 };
            let config = PipeConfig {
                coarse_voxel_m: 0.1 * r0,
                initial_gate_m: 0.3 * r0,
                gate_sigmas: 3.0,
                min_gate_m: 1e-3 * r0,
                max_iterations: 50,
                tolerance_m: 1e-6 * r0,
            };
            let pipe = fit_pipe(&sample, &start, &config).ok()?.pipe;
            (pipe.radius_m < reach).then(|| on_tube(&sample, pipe))
        })
        .max_by(|a, b| a.share.total_cmp(&b.share))
}

/// How many of `points` lie on `pipe`, and how far around it.
fn on_tube(points: &[Point3<f32>], pipe: Pipe) -> Tube {
    let n = pipe.direction();
    let e1 = perpendicular(&n);
    let e2 = n.cross(&e1);
    let band = TUBE_BAND * pipe.radius_m;
    let mut sectors = [0usize; SECTORS];
    for p in points {
        let x = p.cast::<f64>();
        let (_, u, _) = pipe.project(&x);
        if (u.norm() - pipe.radius_m).abs() <= band {
            let angle = u.dot(&e2).atan2(u.dot(&e1)) + std::f64::consts::PI;
            let k = ((angle / std::f64::consts::TAU * SECTORS as f64) as usize).min(SECTORS - 1);
            sectors[k] += 1;
        }
    }
    let on: usize = sectors.iter().sum();
    let floor = 0.2 * on as f64 / SECTORS as f64;
    let filled = sectors.iter().filter(|&&k| on > 0 && k as f64 >= floor).count();
    Tube { pipe, share: on as f64 / points.len() as f64, around: filled as f64 / SECTORS as f64 }
}

/// What a group of deviating points is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnomalyKind {
    /// Inside the tube: an obstacle or an inward deformation.
    Intrusion,
    /// Outside the tube: an outward deformation, a joint gap or a hole.
    Bulge,
}

/// A group of points deviating beyond the threshold.
#[derive(Debug, Clone, PartialEq)]
pub struct Anomaly {
    /// Inward or outward.
    pub kind: AnomalyKind,
    /// Number of points.
    pub points: usize,
    /// Mean of the points.
    pub centroid: Point3<f64>,
    /// Axial position range (distance from the fitted tube's end a), metres.
    pub axial_m: (f64, f64),
    /// Axis-aligned bounding box (min, max) in the points' frame.
    pub bounds: (Point3<f64>, Point3<f64>),
    /// The largest |deviation|, metres (a single point: the noise adds).
    pub max_deviation_m: f64,
    /// The 95th percentile of |deviation|, metres: the anomaly's depth (or
    /// height) robust to a few noisy points.
    pub depth_m: f64,
}

/// Signed deviation of every point from the fitted surface, metres.
pub fn deviation_map(points: &[Point3<f32>], pipe: &Pipe) -> Vec<f32> {
    points.iter().map(|p| pipe.deviation_m(&p.cast()) as f32).collect()
}

/// Groups the points whose |deviation| exceeds `threshold_m` into
/// anomalies: points of the same sign within `link_m` of each other belong
/// together; groups under `min_points` are dropped. Largest first.
pub fn anomalies(
    points: &[Point3<f32>],
    pipe: &Pipe,
    threshold_m: f64,
    link_m: f64,
    min_points: usize,
) -> Result<Vec<Anomaly>> {
    FusionError::require_positive("anomaly threshold (m)", threshold_m)?;
    FusionError::require_positive("anomaly link distance (m)", link_m)?;
    let dev = deviation_map(points, pipe);
    let mut out = Vec::new();
    for kind in [AnomalyKind::Intrusion, AnomalyKind::Bulge] {
        let selected: Vec<usize> = (0..points.len())
            .filter(|&i| match kind {
                AnomalyKind::Intrusion => f64::from(dev[i]) < -threshold_m,
                AnomalyKind::Bulge => f64::from(dev[i]) > threshold_m,
            })
            .collect();
        if selected.is_empty() {
            continue;
        }
        let coords: Vec<[f32; 3]> = selected.iter().map(|&i| points[i].coords.into()).collect();
        let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&coords)
            .map_err(|e| FusionError::Degenerate { what: format!("k-d tree: {e:?}") })?;
        let mut group = vec![usize::MAX; coords.len()];
        let link2 = (link_m * link_m) as f32;
        for seed in 0..coords.len() {
            if group[seed] != usize::MAX {
                continue;
            }
            group[seed] = seed;
            let mut members = vec![seed];
            let mut k = 0;
            while k < members.len() {
                for nb in tree.query(&coords[members[k]]).within::<SquaredEuclidean<f32>>(link2).execute() {
                    let j = nb.item as usize;
                    if group[j] == usize::MAX {
                        group[j] = seed;
                        members.push(j);
                    }
                }
                k += 1;
            }
            if members.len() >= min_points {
                out.push(summarise(kind, members.iter().map(|&m| selected[m]), points, &dev, pipe));
            }
        }
    }
    out.sort_by_key(|a| std::cmp::Reverse(a.points));
    Ok(out)
}

fn summarise(
    kind: AnomalyKind,
    members: impl Iterator<Item = usize>,
    points: &[Point3<f32>],
    dev: &[f32],
    pipe: &Pipe,
) -> Anomaly {
    let n_axis = pipe.direction();
    let mut a = Anomaly {
        kind,
        points: 0,
        centroid: Point3::origin(),
        axial_m: (f64::INFINITY, f64::NEG_INFINITY),
        bounds: (Point3::from([f64::INFINITY; 3]), Point3::from([f64::NEG_INFINITY; 3])),
        max_deviation_m: 0.0,
        depth_m: 0.0,
    };
    let mut sum = Vector3::zeros();
    let mut depths = Vec::new();
    for i in members {
        let p = points[i].cast::<f64>();
        sum += p.coords;
        a.points += 1;
        let s = (p - pipe.a).dot(&n_axis);
        a.axial_m = (a.axial_m.0.min(s), a.axial_m.1.max(s));
        a.bounds = (a.bounds.0.inf(&p), a.bounds.1.sup(&p));
        a.max_deviation_m = a.max_deviation_m.max(f64::from(dev[i].abs()));
        depths.push(f64::from(dev[i].abs()));
    }
    depths.sort_unstable_by(f64::total_cmp);
    a.depth_m = depths[((depths.len() - 1) as f64 * 0.95).round() as usize];
    a.centroid = Point3::from(sum / a.points as f64);
    a
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// The closest point lies on the surface, and no random surface point is
    /// closer — for a tube whose end `a` is far from the origin (where the
    /// seed's eq (3) without `a` would fail).
    #[test]
    fn closest_point_is_on_the_surface_and_closest() {
        let pipe = Pipe { a: Point3::new(3.0, -2.0, 5.0), b: Point3::new(7.0, 1.0, 6.0), radius_m: 0.4 };
        let n = pipe.direction();
        let e1 = perpendicular(&n);
        let e2 = n.cross(&e1);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..200 {
            let x = Point3::new(rng.random_range(2.0..8.0), rng.random_range(-3.0..2.0), rng.random_range(4.0..7.0));
            let c = pipe.closest_point(&x);
            // On the surface: radius r from the axis, within the ends.
            let (s, u, _) = pipe.project(&c);
            assert!((u.norm() - 0.4).abs() < 1e-12 && (0.0..=pipe.length_m()).contains(&s));
            // Closest among a dense sampling of the lateral surface.
            let d = (x - c).norm();
            for i in 0..=100 {
                for j in 0..72 {
                    let t = f64::from(j) * std::f64::consts::TAU / 72.0;
                    let q = pipe.a + pipe.length_m() * f64::from(i) / 100.0 * n + 0.4 * (t.cos() * e1 + t.sin() * e2);
                    assert!((x - q).norm() >= d - 1e-9, "{x}: {q} is closer than {c}");
                }
            }
            // The seed's eq (3) as printed differs once a ≠ 0.
            let s_seed = (x - pipe.a).dot(&n);
            let seed = s_seed * n + 0.4 * (x.coords - s_seed * n).normalize();
            assert!((seed - c.coords).norm() > 1e-3);
        }
        // On the axis: a point at distance r, perpendicular to the axis.
        let on_axis = pipe.a + 0.5 * (pipe.b - pipe.a);
        let c = pipe.closest_point(&on_axis);
        assert!(((c - on_axis).norm() - 0.4).abs() < 1e-12 && (c - on_axis).dot(&n).abs() < 1e-12);
    }

    #[test]
    fn deviation_sign() {
        let pipe = Pipe { a: Point3::origin(), b: Point3::new(10.0, 0.0, 0.0), radius_m: 0.5 };
        assert!((pipe.deviation_m(&Point3::new(2.0, 0.0, 0.45)) + 0.05).abs() < 1e-12);
        assert!((pipe.deviation_m(&Point3::new(2.0, 0.6, 0.0)) - 0.1).abs() < 1e-12);
    }

    /// Points on a tube seen from inside: `around` of the way about its
    /// axis, `length` along it, with 2 % of the radius of noise; turned
    /// and 50 radii from the origin.
    fn inside_a_tube(radius: f64, length: f64, around: f64, seed: u64) -> Vec<Point3<f32>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let turn = nalgebra::Isometry3::new(Vector3::new(30.0, -41.0, 1.2) * radius, Vector3::new(0.3, -0.7, 1.1));
        (0..30_000)
            .map(|_| {
                let t = rng.random_range(0.0..around * std::f64::consts::TAU);
                let r = radius * (1.0 + 0.02 * (rng.random::<f64>() - 0.5) * 2.0);
                let x = Point3::new(rng.random_range(-0.5..0.5) * length, r * t.cos(), r * t.sin());
                (turn * x).cast::<f32>()
            })
            .collect()
    }

    /// A pipe's scan is found a pipe at any scale, position and turn, long
    /// or short (its axis then the points' least spread); a box, a plane
    /// and half a pipe are not.
    #[test]
    fn a_pipes_scan_is_a_tube_all_round_and_nothing_else_is() {
        for (radius, length) in [(0.5, 4.0), (0.005, 0.04), (50.0, 400.0), (0.5, 0.3)] {
            let tube = tube_of(&inside_a_tube(radius, length, 1.0, 5)).expect("a tube");
            assert!(tube.is_pipe(), "r {radius}, length {length}: {tube:?}");
            assert!((tube.pipe.radius_m / radius - 1.0).abs() < 0.01, "r {radius}: {tube:?}");
            assert!(tube.share > 0.99 && tube.around == 1.0, "{tube:?}");
        }
        // Half a pipe (a culvert's vault) is not one all round; three
        // quarters (a pipe a quarter under water) is, just.
        let half = tube_of(&inside_a_tube(0.5, 4.0, 0.5, 6));
        assert!(half.as_ref().is_none_or(|t| !t.is_pipe() && t.around <= 0.55), "{half:?}");
        let wet = tube_of(&inside_a_tube(0.5, 4.0, 0.76, 6)).expect("a tube");
        assert!(wet.is_pipe() && (wet.pipe.radius_m / 0.5 - 1.0).abs() < 0.01, "{wet:?}");
        // A corridor's box, 2 m × 2.5 m × 10 m, and a flat ground patch.
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let walls: Vec<Point3<f32>> = (0..30_000)
            .map(|k| {
                let x = rng.random_range(-5.0..5.0);
                let (a, b) = (rng.random_range(-1.0..1.0), rng.random_range(-1.25..1.25));
                match k % 4 {
                    0 => Point3::new(x, -1.0, b),
                    1 => Point3::new(x, 1.0, b),
                    2 => Point3::new(x, a, -1.25),
                    _ => Point3::new(x, a, 1.25),
                }
            })
            .collect();
        assert!(tube_of(&walls).is_none_or(|t| !t.is_pipe() && t.share < 0.6), "{:?}", tube_of(&walls));
        let ground: Vec<Point3<f32>> = (0..30_000)
            .map(|_| {
                Point3::new(rng.random_range(-30.0..30.0), rng.random_range(-30.0..30.0), rng.random_range(-0.02..0.02))
            })
            .collect();
        assert!(tube_of(&ground).is_none_or(|t| !t.is_pipe()), "{:?}", tube_of(&ground));
        assert!(tube_of(&[Point3::origin(); 3]).is_none());
    }

    #[test]
    fn bad_tubes_are_errors() {
        let p = Point3::new(1.0, 2.0, 3.0);
        let bad = [
            Pipe { a: p, b: p, radius_m: 0.5 },
            Pipe { a: p, b: Point3::origin(), radius_m: f64::NAN },
            Pipe { a: Point3::new(f64::NAN, 0.0, 0.0), b: p, radius_m: 0.5 },
        ];
        for pipe in bad {
            assert!(fit_pipe(&[Point3::origin(); 10], &pipe, &PipeConfig::default()).is_err());
        }
        let good = Pipe { a: Point3::origin(), b: p, radius_m: 0.5 };
        let no_iterations = PipeConfig { max_iterations: 0, ..PipeConfig::default() };
        let e = fit_pipe(&[Point3::origin(); 10], &good, &no_iterations).expect_err("cap 0");
        assert!(e.to_string().contains("iteration cap"), "{e}");
    }
}
