//! Registration without a guess: where no start pose is known (a tripod
//! survey without GNSS, a turntable) each scan's start is found from local
//! shape alone — FPFH descriptors (Rusu, Blodow & Beetz 2009, as PCL and
//! Open3D compute them) matched in feature space, and a RANSAC over three
//! correspondences with Open3D's edge-length check, refined on its inliers
//! — then refined by the coarse-to-fine ICP as any start is.
//!
//! Each scan is reduced to cells of [`GlobalConfig::voxel_m`], its normals
//! estimated from its neighbours within twice that and turned towards its
//! scanner (the frame's origin), and each point described within five
//! cells. A correspondence is a mutual nearest neighbour in feature space;
//! RANSAC keeps the transform with the most correspondences within 1.5
//! cells, drawn from a seeded generator (the same input, the same answer).

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use crate::error::{FusionError, Result};

/// Bins per angle of the descriptor; three angles.
const BINS: usize = 11;
/// The descriptor's length.
pub const FPFH_LEN: usize = 3 * BINS;

/// How global registration runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlobalConfig {
    /// Cell of the reduced points the descriptors are computed on, metres.
    pub voxel_m: f64,
    /// RANSAC draws at most.
    pub max_iterations: usize,
    /// Stop when this confidence of having drawn an all-inlier sample is
    /// reached (from the best inlier ratio so far).
    pub confidence: f64,
    /// Seed of the draws.
    pub seed: u64,
}

impl GlobalConfig {
    /// The settings for cells of `voxel_m`: 100,000 draws at most,
    /// confidence 0.999, seed 1.
    pub fn new(voxel_m: f64) -> Self {
        Self { voxel_m, max_iterations: 100_000, confidence: 0.999, seed: 1 }
    }
}

/// A scan's reduced points with their normals and descriptors.
#[derive(Debug, Clone)]
pub struct Features {
    /// The reduced points.
    pub points: Vec<Point3<f32>>,
    /// Their FPFH descriptors (three 11-bin histograms, each summing to
    /// 100, plus the point's own SPFH).
    pub fpfh: Vec<[f32; FPFH_LEN]>,
}

/// The result of [`register`].
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalMatch {
    /// The transform found.
    pub target_from_source: Isometry3<f64>,
    /// Correspondences it brings within 1.5 cells.
    pub inliers: usize,
    /// Correspondences in feature space (mutual nearest neighbours).
    pub correspondences: usize,
    /// RANSAC draws made.
    pub iterations: usize,
}

/// Reduces `points` to cells of `voxel_m` and describes every reduced point.
pub fn features(points: &[Point3<f32>], voxel_m: f64) -> Result<Features> {
    FusionError::require_positive("global registration cell (m)", voxel_m)?;
    let points = scanner::reduced_points(points, voxel_m)?;
    if points.len() < 10 {
        return Err(FusionError::OutOfRange {
            what: format!("reduced points at {voxel_m} m for global registration"),
            value: points.len() as f64,
            expected: "≥ 10 (a finer cell?)".into(),
        });
    }
    let coords: Vec<[f32; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&coords)
        .map_err(|e| FusionError::Degenerate { what: format!("k-d tree: {e:?}") })?;
    // Every point's neighbours within five cells (the descriptor's reach),
    // with their squared distances; the normals take those within two.
    let radius = 5.0 * voxel_m;
    let neighbours: Vec<Vec<(usize, f32)>> = (0..points.len())
        .into_par_iter()
        .map(|i| {
            tree.query(&coords[i])
                .within::<SquaredEuclidean<f32>>((radius * radius) as f32)
                .execute()
                .into_iter()
                .map(|n| (n.item as usize, n.distance))
                .collect()
        })
        .collect();
    // Normals from the neighbours within two cells, towards the scanner.
    let near = (4.0 * voxel_m * voxel_m) as f32;
    let normals: Vec<Vector3<f64>> = (0..points.len())
        .into_par_iter()
        .map(|i| {
            let p: Vec<Vector3<f64>> = neighbours[i]
                .iter()
                .filter(|&&(_, d2)| d2 <= near)
                .map(|&(j, _)| points[j].coords.cast::<f64>())
                .collect();
            let mean = p.iter().sum::<Vector3<f64>>() / p.len().max(1) as f64;
            let cov = p.iter().fold(Matrix3::zeros(), |a, q| a + (q - mean) * (q - mean).transpose());
            let eig = cov.symmetric_eigen();
            let mut n = eig.eigenvectors.column(eig.eigenvalues.imin()).into_owned();
            if p.len() < 3 || !n.iter().all(|v| v.is_finite()) {
                n = Vector3::zeros();
            }
            if n.dot(&points[i].coords.cast::<f64>()) > 0.0 {
                n = -n;
            }
            n
        })
        .collect();
    let spfh: Vec<[f32; FPFH_LEN]> = (0..points.len())
        .into_par_iter()
        .map(|i| {
            let mut h = [0f32; FPFH_LEN];
            let others: Vec<usize> = neighbours[i].iter().map(|&(j, _)| j).filter(|&j| j != i).collect();
            if others.is_empty() {
                return h;
            }
            let step = 100.0 / others.len() as f32;
            for j in others {
                if let Some(f) = pair_features(&points[i], &normals[i], &points[j], &normals[j]) {
                    h[bin(f[0], -std::f64::consts::PI, std::f64::consts::PI)] += step;
                    h[BINS + bin(f[1], -1.0, 1.0)] += step;
                    h[2 * BINS + bin(f[2], -1.0, 1.0)] += step;
                }
            }
            h
        })
        .collect();
    let fpfh = (0..points.len())
        .into_par_iter()
        .map(|i| {
            let mut f = [0f32; FPFH_LEN];
            for &(j, d2) in &neighbours[i] {
                if j == i || d2 <= 0.0 {
                    continue;
                }
                let d = d2.sqrt();
                for (a, b) in f.iter_mut().zip(&spfh[j]) {
                    *a += b / d;
                }
            }
            for part in f.chunks_mut(BINS) {
                let sum: f32 = part.iter().sum();
                if sum > 0.0 {
                    part.iter_mut().for_each(|v| *v *= 100.0 / sum);
                }
            }
            for (a, b) in f.iter_mut().zip(&spfh[i]) {
                *a += b;
            }
            f
        })
        .collect();
    Ok(Features { points, fpfh })
}

/// PCL's `computePairFeatures`: (θ, α, φ) of the pair, the source the
/// point whose normal makes the smaller angle with the line; `None` for a
/// coincident pair or a normal along the line.
fn pair_features(p1: &Point3<f32>, n1: &Vector3<f64>, p2: &Point3<f32>, n2: &Vector3<f64>) -> Option<[f64; 3]> {
    let mut d = (p2 - p1).cast::<f64>();
    let len = d.norm();
    if len <= 0.0 || n1.norm_squared() == 0.0 || n2.norm_squared() == 0.0 {
        return None;
    }
    let (a1, a2) = (n1.dot(&d) / len, n2.dot(&d) / len);
    let (u, n, phi) = if a1.abs().acos() > a2.abs().acos() {
        d = -d;
        (*n2, *n1, -a2)
    } else {
        (*n1, *n2, a1)
    };
    let v = d.cross(&u);
    let vn = v.norm();
    if vn <= 0.0 {
        return None;
    }
    let v = v / vn;
    let w = u.cross(&v);
    let alpha = v.dot(&n);
    let theta = w.dot(&n).atan2(u.dot(&n));
    Some([theta, alpha, phi])
}

/// The bin of `v` in [lo, hi] among [`BINS`].
fn bin(v: f64, lo: f64, hi: f64) -> usize {
    (((v - lo) / (hi - lo) * BINS as f64).floor().max(0.0) as usize).min(BINS - 1)
}

/// Finds `target_from_source` from the descriptors alone: mutual nearest
/// neighbours in feature space, then RANSAC over three of them (each
/// triangle's edges alike within 10 % in both scans), the best transform
/// refined on its inliers.
pub fn register(source: &Features, target: &Features, config: &GlobalConfig) -> Result<GlobalMatch> {
    let tree = |f: &Features| {
        ImmutableKdTree::<f32, FPFH_LEN>::new_from_slice(&f.fpfh)
            .map_err(|e| FusionError::Degenerate { what: format!("feature k-d tree: {e:?}") })
    };
    let (in_source, in_target) = (tree(source)?, tree(target)?);
    let nearest = |t: &ImmutableKdTree<f32, FPFH_LEN>, f: &[f32; FPFH_LEN]| {
        t.query(f).nearest_one::<SquaredEuclidean<f32>>().execute().item as usize
    };
    let forward: Vec<usize> = source.fpfh.par_iter().map(|f| nearest(&in_target, f)).collect();
    let backward: Vec<usize> = target.fpfh.par_iter().map(|f| nearest(&in_source, f)).collect();
    let mut pairs: Vec<(Vector3<f64>, Vector3<f64>)> = forward
        .iter()
        .enumerate()
        .filter(|&(i, &j)| backward[j] == i)
        .map(|(i, &j)| (source.points[i].coords.cast::<f64>(), target.points[j].coords.cast::<f64>()))
        .collect();
    if pairs.len() < 30 {
        // Too few mutual ones: every source point's nearest.
        pairs = forward
            .iter()
            .enumerate()
            .map(|(i, &j)| (source.points[i].coords.cast::<f64>(), target.points[j].coords.cast::<f64>()))
            .collect();
    }
    if pairs.len() < 3 {
        return Err(FusionError::OutOfRange {
            what: "feature correspondences".into(),
            value: pairs.len() as f64,
            expected: "≥ 3".into(),
        });
    }
    let epsilon = 1.5 * config.voxel_m;
    let inliers_of = |t: &Isometry3<f64>| -> Vec<usize> {
        let e2 = epsilon * epsilon;
        (0..pairs.len())
            .filter(|&k| (t * Point3::from(pairs[k].0) - Point3::from(pairs[k].1)).norm_squared() <= e2)
            .collect()
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(config.seed);
    let mut best: Option<(Isometry3<f64>, usize)> = None;
    let mut needed = config.max_iterations;
    let mut iterations = 0;
    while iterations < needed.min(config.max_iterations) {
        iterations += 1;
        let sample = [0, 1, 2].map(|_| rng.random_range(0..pairs.len()));
        if sample[0] == sample[1] || sample[1] == sample[2] || sample[0] == sample[2] {
            continue;
        }
        let alike = (0..3).all(|a| {
            let b = (a + 1) % 3;
            let ls = (pairs[sample[a]].0 - pairs[sample[b]].0).norm();
            let lt = (pairs[sample[a]].1 - pairs[sample[b]].1).norm();
            ls.min(lt) >= 0.9 * ls.max(lt) && ls > epsilon
        });
        if !alike {
            continue;
        }
        let Some(t) = rigid(sample.iter().map(|&k| pairs[k])) else { continue };
        let count = inliers_of(&t).len();
        if best.as_ref().is_none_or(|b| count > b.1) {
            best = Some((t, count));
            let w = count as f64 / pairs.len() as f64;
            let p_good = w.powi(3).clamp(1e-12, 1.0 - 1e-12);
            needed = ((1.0 - config.confidence).ln() / (1.0 - p_good).ln()).ceil().max(1.0) as usize;
        }
    }
    let (mut t, _) = best.ok_or_else(|| FusionError::NoGlobalMatch {
        why: format!(
            "no three of its {} feature correspondences form a triangle alike in both scans (featureless or self-similar surfaces?)",
            pairs.len()
        ),
    })?;
    // Refined on its inliers, a few times.
    for _ in 0..5 {
        let inliers = inliers_of(&t);
        match rigid(inliers.iter().map(|&k| pairs[k])) {
            Some(r) if inliers.len() >= 3 => t = r,
            _ => break,
        }
    }
    Ok(GlobalMatch { inliers: inliers_of(&t).len(), target_from_source: t, correspondences: pairs.len(), iterations })
}

/// The least-squares rigid transform taking each pair's first point onto
/// its second (Kabsch); `None` for fewer than three or a degenerate set.
fn rigid(pairs: impl Iterator<Item = (Vector3<f64>, Vector3<f64>)>) -> Option<Isometry3<f64>> {
    let pairs: Vec<_> = pairs.collect();
    if pairs.len() < 3 {
        return None;
    }
    let n = pairs.len() as f64;
    let cs = pairs.iter().map(|p| p.0).sum::<Vector3<f64>>() / n;
    let ct = pairs.iter().map(|p| p.1).sum::<Vector3<f64>>() / n;
    let h = pairs.iter().fold(Matrix3::zeros(), |a, (s, t)| a + (s - cs) * (t - ct).transpose());
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (v_t.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = v_t.transpose() * d * u.transpose();
    if !r.iter().all(|v| v.is_finite()) {
        return None;
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Some(Isometry3::from_parts(Translation3::from(ct - rotation * cs), rotation))
}

/// Each scan's global match: the earlier scan it was placed against, and
/// the match (none for scan 0).
pub type Placements = Vec<Option<(usize, GlobalMatch)>>;

/// Starts for a set with no guess: scan 0 at the identity, each later scan
/// placed by its best global match (most inliers) against an earlier one.
/// Returns the starts and each scan's match.
pub fn starts<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    config: &GlobalConfig,
) -> Result<(Vec<Isometry3<f64>>, Placements)> {
    let features: Vec<Features> = scans
        .par_iter()
        .enumerate()
        .map(|(i, s)| features(s.as_ref(), config.voxel_m).map_err(|e| crate::multiview::in_scan(i, e)))
        .collect::<Result<_>>()?;
    let mut starts = vec![Isometry3::identity(); scans.len()];
    let mut matches = vec![None; scans.len()];
    for i in 1..scans.len() {
        let found: Vec<(usize, Result<GlobalMatch>)> =
            (0..i).into_par_iter().map(|j| (j, register(&features[i], &features[j], config))).collect();
        // Of the earlier scans, the match with the most inliers; a scan no
        // earlier one matches says why (the first scan's failure).
        let mut best: Option<(usize, GlobalMatch)> = None;
        let mut why = None;
        for (j, r) in found {
            match r {
                Ok(m) if best.as_ref().is_none_or(|(_, b)| m.inliers > b.inliers) => best = Some((j, m)),
                Ok(_) => {}
                Err(e) => {
                    why.get_or_insert(e);
                }
            }
        }
        let (j, m) = best.ok_or_else(|| {
            crate::multiview::in_scan(
                i,
                why.unwrap_or_else(|| FusionError::NoGlobalMatch { why: "no earlier scan to match".into() }),
            )
        })?;
        starts[i] = starts[j] * m.target_from_source;
        matches[i] = Some((j, m));
    }
    Ok((starts, matches))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box room with a pillar and a step: enough shape to register.
    fn room() -> Vec<Point3<f32>> {
        let mut p = Vec::new();
        let step = 0.05f32;
        let n = |a: f32, b: f32| ((b - a) / step) as usize;
        for i in 0..n(-4.0, 6.0) {
            for k in 0..n(0.0, 3.0) {
                let (x, z) = (-4.0 + i as f32 * step, k as f32 * step);
                p.push(Point3::new(x, -3.0, z));
                p.push(Point3::new(x, 2.0, z));
            }
        }
        for j in 0..n(-3.0, 2.0) {
            for k in 0..n(0.0, 3.0) {
                let (y, z) = (-3.0 + j as f32 * step, k as f32 * step);
                p.push(Point3::new(-4.0, y, z));
                p.push(Point3::new(6.0, y, z));
            }
            for i in 0..n(-4.0, 6.0) {
                p.push(Point3::new(-4.0 + i as f32 * step, -3.0 + j as f32 * step, 0.0));
            }
        }
        // A pillar 0.6 m square at (2, -1) and a box on the floor.
        for k in 0..n(0.0, 3.0) {
            for a in 0..12 {
                let (z, s) = (k as f32 * step, a as f32 * step);
                p.push(Point3::new(1.7 + s, -1.3, z));
                p.push(Point3::new(1.7 + s, -0.7, z));
                p.push(Point3::new(1.7, -1.3 + s, z));
                p.push(Point3::new(2.3, -1.3 + s, z));
            }
        }
        for a in 0..16 {
            for b in 0..10 {
                p.push(Point3::new(-2.0 + a as f32 * step, 0.5 + b as f32 * step, 0.5));
            }
        }
        p
    }

    #[test]
    fn a_room_turned_and_moved_is_found_without_a_guess() {
        let target = room();
        for (deg, t) in [(40.0, Vector3::new(1.0, -0.5, 0.1)), (135.0, Vector3::new(-2.0, 1.0, 0.0))] {
            let truth = Isometry3::from_parts(
                Translation3::from(t),
                UnitQuaternion::from_euler_angles(0.02, -0.01, f64::to_radians(deg)),
            );
            let source: Vec<Point3<f32>> =
                target.iter().map(|p| (truth.inverse() * p.cast::<f64>()).cast::<f32>()).collect();
            let config = GlobalConfig::new(0.15);
            let (fs, ft) = (features(&source, 0.15).expect("source"), features(&target, 0.15).expect("target"));
            let m = register(&fs, &ft, &config).expect("found");
            let d = truth.inverse() * m.target_from_source;
            assert!(d.rotation.angle().to_degrees() < 2.0, "{deg}°: {}° off", d.rotation.angle().to_degrees());
            assert!(d.translation.vector.norm() < 0.15, "{deg}°: {} m off", d.translation.vector.norm());
            // Deterministic.
            assert_eq!(register(&fs, &ft, &config).expect("again"), m);
        }
    }

    #[test]
    fn pair_features_are_those_of_pcl() {
        // Two points on a plane with equal normals: θ = 0, α = 0, φ = 0.
        let n = Vector3::z();
        let f = pair_features(&Point3::origin(), &n, &Point3::new(1.0, 0.0, 0.0), &n).expect("features");
        assert!(f.iter().all(|v| v.abs() < 1e-12), "{f:?}");
        // Normals z and y across a line along x: u = z, v = d × u = −y,
        // w = u × v = x, so α = v·n₂ = −1, θ = atan2(w·n₂, u·n₂) = 0, φ = 0.
        let f = pair_features(&Point3::origin(), &Vector3::z(), &Point3::new(1.0, 0.0, 0.0), &Vector3::y())
            .expect("features");
        assert!((f[0]).abs() < 1e-12 && (f[1] + 1.0).abs() < 1e-12 && f[2].abs() < 1e-12, "{f:?}");
        // A normal along the line says nothing (PCL's zeros).
        assert!(pair_features(&Point3::origin(), &Vector3::x(), &Point3::new(1.0, 0.0, 0.0), &Vector3::x()).is_none());
        assert!(pair_features(&Point3::origin(), &n, &Point3::origin(), &n).is_none());
    }
}
