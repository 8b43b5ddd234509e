//! One pass of correspondences: every source point's nearest target point
//! within the distance (back faces left out on request), summed into what
//! both metrics' normal equations need.

use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Vector3, Vector6};
use rayon::prelude::*;

use super::config::{IcpConfig, Method};
use super::target::{Target, point};
use crate::se3::{adjoint, skew};

/// Sums over the correspondences of one iteration.
#[derive(Clone, Default)]
pub(crate) struct Sums {
    pub(crate) n: usize,
    /// Σ w (point-to-point; equals n without a kernel).
    pub(crate) sw: f64,
    pub(crate) sq: f64,
    pub(crate) h: Matrix6<f64>,
    pub(crate) b: Vector6<f64>,
    pub(crate) sp: Vector3<f64>,
    pub(crate) sq_t: Vector3<f64>,
    pub(crate) spq: Matrix3<f64>,
    pub(crate) spp: Matrix3<f64>,
    /// Point-to-plane with [`IcpConfig::edge_bias`]: the share of `h` and
    /// `b` of the pairs beyond the target's sampled edge
    /// ([`Target::beyond`](super::Target::beyond)), those
    /// [`IcpConfig::only_covered`] leaves out.
    pub(crate) edge_h: Matrix6<f64>,
    pub(crate) edge_b: Vector6<f64>,
    /// [`edge_zone`]: the share of `h` and `b` of the covered pairs
    /// within [`EDGE_ZONE_SPACINGS`] spacings of a pair beyond the edge;
    /// zero from [`accumulate`].
    pub(crate) zone_h: Matrix6<f64>,
    pub(crate) zone_b: Vector6<f64>,
    /// With [`IcpConfig::range_noise`] too: the share of `scores` of the
    /// pairs beyond the edge, and of the edge's zone ([`edge_zone`]) —
    /// what the edge's pull would scatter by were it the pairs' noise.
    pub(crate) edge_scores: Matrix6<f64>,
    pub(crate) zone_scores: Matrix6<f64>,
    /// Point-to-plane with [`IcpConfig::line_ratio`]: the share of `h` of
    /// the pairs whose partner lies on one scan line (its middle share
    /// below the ratio: [`Target::middle_shares`](super::Target::middle_shares)),
    /// whose normal may not be the surface's: the blind-direction analysis
    /// judges without it.
    pub(crate) line_h: Matrix6<f64>,
    /// Point-to-plane with [`IcpConfig::range_noise`]: Σ (w·r)²·JJᵀ, each
    /// pair's score by its own squared residual — the middle of the
    /// estimate's sandwich covariance (zero otherwise).
    pub(crate) scores: Matrix6<f64>,
}

impl Sums {
    /// RMS of the residuals summed, metres (zero with none).
    pub(crate) fn rmse(&self) -> f64 {
        (self.sq / self.n.max(1) as f64).sqrt()
    }

    pub(crate) fn merge(mut self, o: Sums) -> Sums {
        self.n += o.n;
        self.sw += o.sw;
        self.sq += o.sq;
        self.h += o.h;
        self.b += o.b;
        self.sp += o.sp;
        self.sq_t += o.sq_t;
        self.spq += o.spq;
        self.spp += o.spp;
        self.edge_h += o.edge_h;
        self.edge_b += o.edge_b;
        self.zone_h += o.zone_h;
        self.zone_b += o.zone_b;
        self.edge_scores += o.edge_scores;
        self.zone_scores += o.zone_scores;
        self.line_h += o.line_h;
        self.scores += o.scores;
        self
    }

    /// A symmetric match's sums: these (the source's points into the
    /// target) and `back`'s (the target's points into the source, summed at
    /// `target_from_source⁻¹`), in this match's ξ. The reverse pass's ξ′
    /// (left, on `source_from_target`) is −Ad(T⁻¹)·ξ, so its H′ and b′ enter
    /// as AᵀH′A and Aᵀb′. H and b are the two ways' mean — each pair is seen
    /// about twice, once from either scan, and is one measurement, not two —
    /// the residuals' count and squares their sum (σ̂² per residual), and
    /// the scores' squares (Σ (w·r)²·JJᵀ) the two ways' mean as H is.
    pub(crate) fn both_ways(self, back: &Sums, target_from_source: &Isometry3<f64>) -> Sums {
        let a = -adjoint(&target_from_source.inverse());
        Sums {
            scores: 0.5 * (self.scores + a.transpose() * back.scores * a),
            n: self.n + back.n,
            sq: self.sq + back.sq,
            h: 0.5 * (self.h + a.transpose() * back.h * a),
            b: 0.5 * (self.b + a.transpose() * back.b),
            edge_h: 0.5 * (self.edge_h + a.transpose() * back.edge_h * a),
            edge_b: 0.5 * (self.edge_b + a.transpose() * back.edge_b),
            zone_h: 0.5 * (self.zone_h + a.transpose() * back.zone_h * a),
            zone_b: 0.5 * (self.zone_b + a.transpose() * back.zone_b),
            edge_scores: 0.5 * (self.edge_scores + a.transpose() * back.edge_scores * a),
            zone_scores: 0.5 * (self.zone_scores + a.transpose() * back.zone_scores * a),
            line_h: 0.5 * (self.line_h + a.transpose() * back.line_h * a),
            ..self
        }
    }

    /// Σ w JᵀJ of the pairs, with J = [−[p]×, I] for point-to-point (derived
    /// from Σw, Σwp and Σwppᵀ: [p]×ᵀ[p]× = |p|²I − ppᵀ) and the accumulated
    /// `h` for point-to-plane.
    pub(crate) fn normal_matrix(&self, method: Method) -> Matrix6<f64> {
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

/// What one pass keeps of each source point for the next: its nearest
/// target point (where the next search starts; `u32::MAX` before the
/// first pass) and a lower bound on its distance to the target, metres —
/// or, from [`Partners::at`], the first pass's own answers.
pub(crate) struct Partners {
    nearest: Vec<u32>,
    lower_m: Vec<f32>,
    /// The squared distances to `nearest`, when those are exactly the
    /// nearest points at the first pass's estimate.
    known_sq: Option<Vec<f32>>,
}

impl Partners {
    /// Nothing known of `n` source points.
    pub(crate) fn new(n: usize) -> Self {
        Self { nearest: vec![u32::MAX; n], lower_m: vec![0.0; n], known_sq: None }
    }

    /// Every `source` point's nearest `target` point at `estimate`
    /// (`target_from_source`), searched as ICP's first pass searches it:
    /// counting an overlap with these and then matching from the same
    /// estimate with [`crate::icp::solve::align_from`] searches each point once.
    pub(crate) fn at(source: &[Point3<f32>], target: &Target, estimate: &Isometry3<f64>) -> Self {
        let r: Matrix3<f64> = estimate.rotation.to_rotation_matrix().into_inner();
        let t = estimate.translation.vector;
        let (nearest, known): (Vec<u32>, Vec<f32>) = source
            .par_iter()
            .map(|p| {
                let pt = r * p.coords.cast::<f64>() + t;
                let (i, d2) = target.nearest_from(&[pt.x as f32, pt.y as f32, pt.z as f32], u32::MAX);
                (i as u32, d2 as f32)
            })
            .unzip();
        let lower_m = known.iter().map(|d2| d2.sqrt()).collect();
        Self { nearest, lower_m, known_sq: Some(known) }
    }

    /// How many points have their nearest target point within
    /// `max_distance_m` (the correspondences ICP would use).
    pub(crate) fn within(&self, max_distance_m: f64) -> usize {
        let max_sq = max_distance_m * max_distance_m;
        self.known_sq.as_ref().map_or(0, |k| k.iter().filter(|&&d2| f64::from(d2) <= max_sq).count())
    }

    /// Whether source point `i`'s nearest target point lies within
    /// `max_distance_m` (false when not known).
    pub(crate) fn is_within(&self, i: usize, max_distance_m: f64) -> bool {
        self.known_sq
            .as_ref()
            .is_some_and(|k| k.get(i).is_some_and(|&d2| f64::from(d2) <= max_distance_m * max_distance_m))
    }

    /// Number of source points.
    pub(crate) fn len(&self) -> usize {
        self.nearest.len()
    }
}

/// Source points per parallel chunk of a pass.
const CHUNK: usize = 4096;

/// One pass over the source: nearest neighbours within the distance and
/// the sums both metrics need, updating `partners`. `moved` is how the
/// estimate changed since the last pass — (rotation angle, translation
/// length) of `estimate · last⁻¹` in the source's terms: a point moved by
/// at most angle·|p| + length — or `None` on the first pass. A point whose
/// distance bound, less that motion, still exceeds the correspondence
/// distance cannot have a partner and is not searched (where scans overlap
/// partly, that is most of the points beyond the overlap). `own`: the
/// source points' own model, for [`IcpConfig::normal_agreement_cos`]
/// ([`own_model`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn accumulate(
    source: &[Point3<f32>],
    target: &Target,
    estimate: &Isometry3<f64>,
    max_sq: f64,
    config: &IcpConfig,
    partners: &mut Partners,
    moved: Option<(f64, f64)>,
    own: Option<&Target>,
) -> Sums {
    let agreement = config.normal_agreement_cos.zip(own);
    let r: Matrix3<f64> = estimate.rotation.to_rotation_matrix().into_inner();
    let t = estimate.translation.vector;
    // The source scanner in the target frame.
    let back_faces = config.reject_back_faces.then(|| r * config.source_viewpoint.coords + t);
    let max_m = max_sq.sqrt();
    let corner_reach_sq = config.corner_reach_m().powi(2);
    // The first pass's answers, when known (`Partners::at` at this estimate).
    let known = partners.known_sq.take().filter(|_| moved.is_none());
    source
        .par_chunks(CHUNK)
        .enumerate()
        .zip(partners.nearest.par_chunks_mut(CHUNK).zip(partners.lower_m.par_chunks_mut(CHUNK)))
        .map(|((c, chunk), (partners, lower))| {
            let mut s = Sums::default();
            for (k, ((p, partner), lower)) in chunk.iter().zip(partners).zip(lower).enumerate() {
                if let Some((angle, length)) = moved {
                    // The bound less the motion (and a margin for f32).
                    let bound = f64::from(*lower) - angle * f64::from(p.coords.norm()) - length - 1e-4;
                    *lower = bound.max(0.0) as f32;
                    if bound > max_m {
                        continue;
                    }
                }
                let pt = r * p.coords.cast::<f64>() + t;
                let (i, d2) = match &known {
                    Some(sq) => (*partner as usize, f64::from(sq[c * CHUNK + k])),
                    None => target.nearest_from(&[pt.x as f32, pt.y as f32, pt.z as f32], *partner),
                };
                *partner = i as u32;
                *lower = d2.sqrt() as f32;
                if d2 > max_sq {
                    continue;
                }
                let q = point(&target.points[i]);
                if let Some(eye) = back_faces
                    && target.normal(i).dot(&(eye - q)) < 0.0
                {
                    continue;
                }
                match config.method {
                    Method::PointToPlane => {
                        if disagree(agreement, &r, c * CHUNK + k, target, i) {
                            continue;
                        }
                        if let Some(ratio) = config.corner_ratio
                            && f64::from(target.corner_share_beyond(i, corner_reach_sq)) > ratio
                        {
                            continue;
                        }
                        let (res, j, edge) = plane_pair(target, i, &pt, config);
                        if edge && config.only_covered {
                            continue;
                        }
                        s.n += 1;
                        let w = config.kernel.weight(res);
                        let (h, b) = (w * j * j.transpose(), w * res * j);
                        s.h += h;
                        s.b += b;
                        if edge {
                            s.edge_h += h;
                            s.edge_b += b;
                        }
                        if let Some(ratio) = config.line_ratio
                            && f64::from(target.middle_share(i)) < ratio
                        {
                            s.line_h += h;
                        }
                        if config.range_noise {
                            s.scores += (w * res * res) * h;
                            if edge {
                                s.edge_scores += (w * res * res) * h;
                            }
                        }
                        s.sq += res * res;
                    }
                    Method::PointToPoint => {
                        s.n += 1;
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
        // Merged in chunk order, so that a match gives the same estimate
        // every time (a parallel reduction associates as the threads
        // steal work, and a float sum's rounding follows it).
        .collect::<Vec<Sums>>()
        .into_iter()
        .fold(Sums::default(), Sums::merge)
}

/// `model` as `points`' own for [`IcpConfig::normal_agreement_cos`]
/// (asked for): the same points, in the same order, with normals; `None`
/// otherwise (a model of other points is not used). Checked once a match.
pub(crate) fn own_model<'a>(config: &IcpConfig, points: &[Point3<f32>], model: &'a Target) -> Option<&'a Target> {
    let theirs = model.len() == points.len() && model.has_normals() && model.points().eq(points.iter().copied());
    (config.normal_agreement_cos.is_some() && theirs).then_some(model)
}

/// Whether source point `k`'s own normal, turned by `r` into the target's
/// frame, meets target point `i`'s at a cosine below the agreement's
/// (either side); false without one.
fn disagree(agreement: Option<(f64, &Target)>, r: &Matrix3<f64>, k: usize, target: &Target, i: usize) -> bool {
    agreement.is_some_and(|(cos, own)| (r * own.normal(k)).dot(&target.normal(i)).abs() < cos)
}

/// A point-to-plane pair: source point `pt` (target frame) on target
/// point `i`'s plane — its residual, its Jacobian row and whether it lies
/// beyond the target's sampled edge (asked only with
/// [`IcpConfig::only_covered`] or [`IcpConfig::edge_bias`]).
fn plane_pair(target: &Target, i: usize, pt: &Vector3<f64>, config: &IcpConfig) -> (f64, Vector6<f64>, bool) {
    let q = point(&target.points[i]);
    let n = target.normal(i);
    let res = n.dot(&(pt - q));
    let edge = (config.only_covered || config.edge_bias) && target.beyond(i, &(pt - q - res * n));
    // r = nᵀ(T̂p + ω × T̂p + v − q): ∂r/∂ω = T̂p × n, ∂r/∂v = n.
    let c = pt.cross(&n);
    (res, Vector6::new(c.x, c.y, c.z, n.x, n.y, n.z), edge)
}

/// How far from the pairs beyond the target's edge [`edge_zone`] reaches,
/// in target spacings. The pairs there are covered, but the edge cuts
/// their partners' neighbourhoods too (normals from one side, nearest
/// samples all inward), and they lean the match as the pairs beyond it
/// pull it: the pull with the zone left out too was 1.2, 1.5 and 1.55×
/// the pull alone (medians) at 1, 2 and 3 spacings on a real room's
/// wedges, in its direction (cos 0.995), 1.1, 1.3 and 1.4× on a street's
/// (BENCHMARKS.md, "The edge's lean").
pub(crate) const EDGE_ZONE_SPACINGS: f64 = 3.0;

/// One pair of the zone's first pass.
struct ZonePair {
    /// The source point in the target frame.
    pt: Vector3<f64>,
    /// Its partner.
    i: usize,
    /// Its point-to-plane residual ([`plane_pair`]).
    res: f64,
    /// Its Jacobian row in ξ = (ω, v) ([`plane_pair`]).
    row: Vector6<f64>,
    /// Whether it lies beyond the target's edge.
    beyond: bool,
}

/// The covered pairs nearest the target's sampled edge: of a pass at
/// `estimate` (each source point on its partner of that pass, `partners`;
/// back faces and the distance as [`accumulate`] takes them), those within
/// [`EDGE_ZONE_SPACINGS`] target spacings (the median distance of the
/// edge's samples to their nearest neighbours) of a pair beyond the edge
/// ([`Target::beyond`]), summed into `zone_h` / `zone_b` / `zone_scores`
/// (the rest of the sums zero). Zero when no pair lies beyond the edge. Pairs whose
/// normals disagree are left out as [`accumulate`] leaves them (`own`).
pub(crate) fn edge_zone(
    source: &[Point3<f32>],
    target: &Target,
    estimate: &Isometry3<f64>,
    max_sq: f64,
    config: &IcpConfig,
    partners: &Partners,
    own: Option<&Target>,
) -> Sums {
    let agreement = config.normal_agreement_cos.zip(own);
    let r: Matrix3<f64> = estimate.rotation.to_rotation_matrix().into_inner();
    let t = estimate.translation.vector;
    let back_faces = config.reject_back_faces.then(|| r * config.source_viewpoint.coords + t);
    let config = IcpConfig { edge_bias: true, only_covered: false, ..*config };
    let pairs: Vec<ZonePair> = source
        .par_iter()
        .zip(&partners.nearest)
        .enumerate()
        .filter_map(|(k, (p, &i))| {
            let i = i as usize;
            let q = point(target.points.get(i)?);
            let pt = r * p.coords.cast::<f64>() + t;
            if (pt - q).norm_squared() > max_sq {
                return None;
            }
            if let Some(eye) = back_faces
                && target.normal(i).dot(&(eye - q)) < 0.0
            {
                return None;
            }
            if disagree(agreement, &r, k, target, i) {
                return None;
            }
            let (res, row, beyond) = plane_pair(target, i, &pt, &config);
            Some(ZonePair { pt, i, res, row, beyond })
        })
        .collect();
    let beyond: Vec<Point3<f32>> =
        pairs.iter().filter(|pair| pair.beyond).map(|pair| Point3::from(pair.pt.cast::<f32>())).collect();
    let Some(edge) = (!beyond.is_empty()).then(|| Target::new(&beyond, 0).ok()).flatten() else {
        return Sums::default();
    };
    let mut spacings: Vec<f64> = pairs.iter().filter(|pair| pair.beyond).map(|pair| target.spacing(pair.i)).collect();
    spacings.sort_by(f64::total_cmp);
    let reach_sq = (EDGE_ZONE_SPACINGS * spacings[spacings.len() / 2]).powi(2);
    pairs
        .par_iter()
        .filter(|pair| {
            let pt = &pair.pt;
            !pair.beyond && edge.nearest_from(&[pt.x as f32, pt.y as f32, pt.z as f32], u32::MAX).1 <= reach_sq
        })
        .map(|&ZonePair { res, row, .. }| {
            let w = config.kernel.weight(res);
            let h = w * row * row.transpose();
            Sums { zone_h: h, zone_b: w * res * row, zone_scores: (w * res * res) * h, ..Sums::default() }
        })
        .collect::<Vec<Sums>>()
        .into_iter()
        .fold(Sums::default(), Sums::merge)
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// Points left out by the distance bound are exactly those with no
    /// target point within the distance: a pass after a move, with the
    /// bounds of the pass before, sums what a pass that searches every
    /// point sums — here with most of the source beyond the target's edge.
    #[test]
    fn the_distance_bound_leaves_out_only_points_without_a_partner() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let plane = |rng: &mut ChaCha8Rng, x0: f32, x1: f32| -> Vec<Point3<f32>> {
            (0..4000)
                .map(|_| {
                    let (x, y) = (rng.random_range(x0..x1), rng.random_range(-3.0..3.0));
                    Point3::new(x, y, 0.02 * (x * 1.3).sin() + 0.01 * y)
                })
                .collect()
        };
        let target = Target::new(&plane(&mut rng, -3.0, 3.0), 10).expect("target");
        let source = plane(&mut rng, -2.0, 9.0);
        let config = IcpConfig { max_correspondence_m: 0.3, ..IcpConfig::default() };
        let max_sq = 0.09;
        let first = Isometry3::translation(0.05, 0.02, 0.01);
        let second =
            Isometry3::rotation(Vector3::new(0.0, 0.0, 0.004)) * Isometry3::translation(0.02, -0.03, 0.0) * first;
        let mut kept = Partners::new(source.len());
        accumulate(&source, &target, &first, max_sq, &config, &mut kept, None, None);
        let step = second * first.inverse();
        let moved = (step.rotation.angle(), (second.translation.vector - first.translation.vector).norm());
        let bounded = accumulate(&source, &target, &second, max_sq, &config, &mut kept, Some(moved), None);
        let skipped = kept.lower_m.iter().filter(|&&l| f64::from(l) > 0.3).count();
        let full = accumulate(&source, &target, &second, max_sq, &config, &mut Partners::new(source.len()), None, None);
        assert!(skipped > source.len() / 3, "{skipped} of {} points known to be beyond the distance", source.len());
        assert_eq!(bounded.n, full.n);
        assert!((bounded.h - full.h).amax() <= 1e-9 * full.h.amax());
        assert!((bounded.b - full.b).amax() <= 1e-9 * full.b.amax().max(1e-12));
        assert!((bounded.sq - full.sq).abs() <= 1e-9 * full.sq);
    }

    /// With a normal agreement asked for, a pair counts only where the
    /// source point's own normal (turned into the target's frame) meets
    /// its partner's within it, either side; without it every pair counts,
    /// and a model of other points is not the source's own.
    #[test]
    fn pairs_whose_normals_disagree_are_left_out_when_asked() {
        let grid: Vec<Point3<f32>> =
            (0..30).flat_map(|i| (0..30).map(move |j| Point3::new(i as f32 * 0.1, j as f32 * 0.1, 0.0))).collect();
        let target = Target::with_normals(&grid, vec![Vector3::z(); grid.len()]).expect("target");
        // The source: the grid turned 90° about x (its plane y = 0 in its
        // own frame), a third of its normals across the plane and the
        // rest along −y, which the turn takes to ±z.
        let turn = Isometry3::rotation(Vector3::x() * std::f64::consts::FRAC_PI_2);
        let source: Vec<Point3<f32>> =
            grid.iter().map(|p| Point3::from((turn.inverse() * p.cast::<f64>()).coords.cast::<f32>())).collect();
        let own_normals: Vec<Vector3<f64>> =
            (0..source.len()).map(|k| if k % 3 == 0 { Vector3::x() } else { -Vector3::y() }).collect();
        let own = Target::with_normals(&source, own_normals).expect("own");
        let asked = IcpConfig { normal_agreement_cos: Some(0.95), max_correspondence_m: 0.05, ..IcpConfig::default() };
        let pass = |config: &IcpConfig, own: Option<&Target>| {
            accumulate(&source, &target, &turn, 0.0025, config, &mut Partners::new(source.len()), None, own).n
        };
        assert_eq!(pass(&asked, Some(&own)), source.len() - source.len().div_ceil(3));
        assert_eq!(pass(&IcpConfig { normal_agreement_cos: None, ..asked }, Some(&own)), source.len());
        assert!(own_model(&asked, &source, &own).is_some());
        assert!(own_model(&IcpConfig { normal_agreement_cos: None, ..asked }, &source, &own).is_none());
        let others = Target::with_normals(&grid, vec![Vector3::x(); grid.len()]).expect("other points");
        assert!(own_model(&asked, &source, &others).is_none(), "a model of other points");
        assert_eq!(pass(&asked, None), source.len());
    }

    /// With a corner ratio asked for, a pair counts only where its target
    /// normal's neighbourhood (the point's 10 nearest, found here by brute
    /// force) has its smallest eigenvalue at most that share of its middle
    /// one: a floor meeting a wall loses the pairs along where they meet,
    /// and only there; without it every pair counts. A model whose
    /// normals were given leaves out the same pairs with the corner shares
    /// of the target they came from, and none without. Unless asked
    /// everywhere, only a neighbourhood reaching beyond the pairs'
    /// distance counts (the farthest of its ten nearest other points), in
    /// the target's own normals and in the shares a model is given.
    #[test]
    fn pairs_at_a_corner_are_left_out_when_asked() {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let mut jitter = || rng.random_range(-0.02f32..0.02);
        let mut cloud = Vec::new();
        for i in 0..30 {
            for j in 0..20 {
                // The floor z = 0 up to the wall x = 3, the wall up to 1.5 m.
                cloud.push(Point3::new(i as f32 * 0.1 + jitter(), j as f32 * 0.1 + jitter(), 0.0));
                if i < 15 {
                    cloud.push(Point3::new(3.0, j as f32 * 0.1 + jitter(), 0.05 + i as f32 * 0.1 + jitter()));
                }
            }
        }
        let target = Target::new(&cloud, 10).expect("target");
        // Each point's corner share and its ten nearest other points'
        // reach, squared.
        let corner = |q: &Point3<f32>| {
            let mut by: Vec<&Point3<f32>> = cloud.iter().collect();
            by.sort_by(|a, b| (*a - q).norm_squared().total_cmp(&(*b - q).norm_squared()));
            let hood: Vec<Vector3<f64>> = by[..10].iter().map(|p| p.coords.cast::<f64>()).collect();
            let mean = hood.iter().sum::<Vector3<f64>>() / 10.0;
            let scatter = hood.iter().fold(Matrix3::zeros(), |a, p| a + (p - mean) * (p - mean).transpose());
            let mut e: Vec<f64> = scatter.symmetric_eigenvalues().iter().copied().collect();
            e.sort_by(f64::total_cmp);
            (e[0] / e[1], f64::from((by[10] - q).norm_squared()))
        };
        let hoods: Vec<(f64, f64)> = cloud.iter().map(corner).collect();
        let at_corner: Vec<bool> = hoods.iter().map(|&(share, _)| share > 0.1).collect();
        let lost = at_corner.iter().filter(|&&c| c).count();
        assert!(lost > 20, "the corner's points: {lost}");
        for (q, _) in cloud.iter().zip(&at_corner).filter(|(_, c)| **c) {
            assert!((3.0 - q.x).abs() + q.z.abs() < 0.45, "a corner point away from the corner: {q}");
        }
        let asked = IcpConfig { corner_ratio: Some(0.1), max_correspondence_m: 0.05, ..IcpConfig::default() };
        let pass_within = |max_sq: f64, config: &IcpConfig, target: &Target| {
            accumulate(
                &cloud,
                target,
                &Isometry3::identity(),
                max_sq,
                config,
                &mut Partners::new(cloud.len()),
                None,
                None,
            )
            .n
        };
        // Every neighbourhood of this 0.1 m grid reaches beyond 0.05 m.
        let pass = |config: &IcpConfig, target: &Target| pass_within(0.0025, config, target);
        assert_eq!(pass(&asked, &target), cloud.len() - lost);
        assert_eq!(pass(&IcpConfig { corner_ratio: None, ..asked }, &target), cloud.len());
        let shares = target.corner_shares();
        for (k, (&s, &c)) in shares.iter().zip(&at_corner).enumerate() {
            assert_eq!(f64::from(s) > 0.1, c, "point {k}: corner share {s}");
        }
        let given = Target::with_normals(&cloud, target.normals()).expect("given");
        assert_eq!(pass(&asked, &given), cloud.len(), "no corner shares given: every point planar");
        let short = Target::with_normals(&cloud, target.normals()).and_then(|t| t.with_corner_shares(vec![0.0; 3]));
        assert!(short.is_err_and(|e| e.to_string().contains("corner share count")));
        let given = given.with_corner_shares(shares).expect("shares");
        assert_eq!(pass(&asked, &given), cloud.len() - lost);
        // Pairs within 0.18–0.21 m: some corner neighbourhoods reach
        // farther, some not.
        let everywhere = IcpConfig { corner_everywhere: true, ..asked };
        for reach_m in [0.18f64, 0.19, 0.21] {
            let reach_sq = reach_m * reach_m;
            let at_reach = hoods.iter().any(|&(share, r)| share > 0.1 && (r - reach_sq).abs() < 1e-5);
            assert!(!at_reach, "a corner's neighbourhood at the reach");
            let sparse = hoods.iter().filter(|&&(share, r)| share > 0.1 && r > reach_sq).count();
            assert!(sparse > 0 && sparse < lost, "{sparse} of the corner's {lost} points beyond {reach_m} m");
            let config = IcpConfig { max_correspondence_m: reach_m, ..asked };
            assert_eq!(pass_within(reach_sq, &config, &target), cloud.len() - sparse, "beyond {reach_m} m");
            assert_eq!(pass_within(reach_sq, &everywhere, &target), cloud.len() - lost, "everywhere");
            let beyond = target.corner_shares_beyond(reach_m);
            for (k, (&s, &(share, r))) in beyond.iter().zip(&hoods).enumerate() {
                assert_eq!(f64::from(s) > 0.1, share > 0.1 && r > reach_sq, "point {k}: corner share {s}");
            }
            let given = Target::with_normals(&cloud, target.normals()).and_then(|t| t.with_corner_shares(beyond));
            assert_eq!(pass_within(reach_sq, &config, &given.expect("shares")), cloud.len() - sparse);
        }
        for bad in [0.0, 1.5, f64::NAN] {
            let config = IcpConfig { corner_ratio: Some(bad), ..asked };
            let e = crate::icp::align(&cloud, &target, &Isometry3::identity(), &config).expect_err("refused");
            assert!(e.to_string().contains("corner eigenvalue ratio"), "{e}");
        }
    }

    /// A match started from the neighbours an overlap count found
    /// (`Partners::at`) is the match that searches them itself, to the last
    /// bit, and the count is the target's own correspondence count.
    #[test]
    fn a_match_from_known_neighbours_is_the_same_match() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut cloud = Vec::new();
        for _ in 0..6000 {
            let (a, b) = (rng.random_range(0.0f32..6.0), rng.random_range(0.0f32..3.0));
            cloud.push(Point3::new(a, b, 0.03 * (a * 1.7).sin()));
            cloud.push(Point3::new(a, 3.0, b));
            cloud.push(Point3::new(0.0, b, a * 0.5));
        }
        let mut target = Target::new(&cloud, 10).expect("target");
        target.orient_normals_towards(&Point3::new(3.0, 1.5, 1.0));
        // The source: the part with x < 4, seen from 10 cm and 1° away.
        let source: Vec<Point3<f32>> = cloud.iter().filter(|p| p.x < 4.0).copied().collect();
        let init = Isometry3::from_parts(
            nalgebra::Translation3::new(0.06, -0.05, 0.03),
            nalgebra::UnitQuaternion::from_euler_angles(0.01, -0.005, 0.015),
        );
        let config = IcpConfig { max_correspondence_m: 0.5, reject_back_faces: true, ..IcpConfig::default() };
        let known = Partners::at(&source, &target, &init);
        assert_eq!(known.within(0.3), target.correspondences(&source, &init, 0.3));
        let searched = crate::icp::align(&source, &target, &init, &config).expect("icp");
        let from_known = crate::icp::solve::align_from(&source, &target, &init, &config, known).expect("icp");
        assert_eq!(searched, from_known);
        assert!(searched.target_from_source.translation.vector.norm() < 1e-3, "{}", searched.target_from_source);
    }

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
}
