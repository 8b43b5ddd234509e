//! The check of a registered set against its own data: every pair of scans
//! that overlaps at the final poses is matched once more from those poses,
//! and a pair whose match moves away from them is inconsistent — the
//! poses are not where the data agree (issue 38: four wedges of a room
//! from starts 1 m / 10° off landed 90° off, in a room's other symmetric
//! fit, with every link "used" and exit 0).
//!
//! A scan trapped with one partner in a symmetric fit agrees with that
//! partner; it cannot agree with a scan it overlaps only at the wrong pose,
//! or one it should overlap but now meets wrongly. The motion is measured
//! frame-free: how far the match moves the source's points (its
//! centroid's displacement plus the turn times their RMS radius about it).
//!
//! How far is too far was measured. Real sets whose poses are right still
//! disagree pair by pair with their compromise: the 3DTK set's graph
//! solution (within 0.35° of the references) moves 0.07–0.20 m and
//! 0.4–1.2° when its pairs are matched again — up to 2.4 % of the scans'
//! RMS radius, and 500–1,700 in χ² against the matches' own (optimistic)
//! information, so neither the voxel nor χ² can judge. The room wedges
//! trapped 90° off move 3.4–17° and 0.56–1.5 m on at least one pair —
//! 15–40 % of their radius — and a right registration of them under 5 mm.
//! A pair is inconsistent when its match moves the points by more than
//! the finest voxel *and*, along the directions the match sees well, by
//! more than [`MAX_RELATIVE_MOTION`] of their radius, or turns them by more
//! than [`MAX_TURN_RAD`], or moves them by [`MAX_WEAK_MOTION`] of their
//! radius in all, or settles where its residual is more than
//! [`MAX_RESIDUAL_GAIN`] times lower than at the final poses. (Measured on the
//! simulated corridor's 20 scans, registered within 12 mm and 0.016° of the
//! truth: pairs matched alone slid 0.14–0.26 m along the corridor's axis —
//! 5–10 % of their radius — where the set's other links hold them, and six
//! right scans were named "not trusted", exit 1. The axis is weak, not
//! blind: its eigenvalue is above the blind-direction threshold.)

use nalgebra::{Isometry3, Matrix6, Point3, Vector6};
use rayon::prelude::*;

use crate::chi2::chi2_999;
use crate::error::Result;
use crate::free_space::{FreeSpace, MAX_VIOLATION_SHARE, View};
use crate::graph::Edge;
use crate::icp::degeneracy::{Observability, centroid_and_lever_arm};
use crate::links::{LinkConfig, Paired, Pull, pair_links, shared_shares};
pub use crate::links::{MAX_RELATIVE_MOTION, MAX_TURN_RAD};
use crate::multiview::{check, prepare};

/// Directions whose eigenvalue of the match's information (about the
/// source's centroid, rotation scaled by the radius) is below this
/// fraction of the largest are weak: a pair matched alone may slide along
/// them where the set's other links hold it.
pub const SEEN_RATIO: f64 = 0.05;

/// A pair may slide along what it sees weakly, where the set's other
/// links hold it — but not this fraction of the source points' RMS radius
/// or more in all: measured, right pairs of the simulated corridor slide
/// up to 10.4 % (along its axis), of the 3DTK set 2.4 %, of the NEES
/// bench's parts of real scans under 1 %; a room's wedge left 1.8 m off
/// slid 29 % against the first wedge when matched again, along what that
/// pair sees weakly (10 cm along the rest), and passed before.
pub const MAX_WEAK_MOTION: f64 = 0.2;

/// A pair may slide where the set's other links hold it, but not to a fit
/// this much closer: its residual at the final poses above this multiple of
/// the residual its match reaches. Measured: right pairs of the NEES
/// bench's real scans improve by at most 1.24× (seeds 7, 11, 13, 17; a
/// room wedge pair 18 mm off), the 3DTK set's at its own poses at most
/// 1.09× in every mode (the simulated corridor's axis slides are not
/// named either) — they slide along what they see weakly, where the fit
/// hardly changes; a street wedge placed 0.29 m
/// along the street by a link still creeping at its iteration cap, and
/// two wedges left 3.5° off, 3.1–3.4× (their slides 3–9 % of the radius,
/// within the tiers above). Judged where the match settled, and only
/// beyond the σ of the two poses' relative pose
/// ([`weigh_residual_gains`]).
pub const MAX_RESIDUAL_GAIN: f64 = 1.5;

/// In the modes without a link graph, the largest departure of a pose
/// from where the verification's matches agree (their adjustment,
/// [`crate::links::adjust_matches`]), ξᵀ·C⁺·ξ in that adjustment's
/// covariance C, that is still agreement. A strategy that places each scan
/// against partners held stops short of that adjustment by a few tens of
/// its σ² as a rule: measured on 1,784 parts of real scans (the NEES
/// bench's shares and wedges, seeds 7 / 11 / 13 / 17 / 23, pairwise,
/// incremental and simultaneous), right poses (within 0.15° and 10 mm)
/// departed by at most 768 (a street wedge 0.029° off; the next 451,
/// 299), the 3DTK set's by 3–15 (0.36–1.14°: its links are weak and
/// disagree). With the scans' shared noise weighed by the matches'
/// footprints (smaller covariances) two right street wedges reached
/// 2,400 and 2,720 — 0.014° and 1.5–1.7 mm from the adjustment, their
/// points moving a few millimetres: the finest voxel, the other half of
/// the verdict ([`crate::scanset::departs`]), keeps them.
/// Simultaneous matching settled in a compromise of its metascan
/// matches on seed 23's street wedges — 0.19–0.68° and 16–25 mm off, each
/// pair matched again alone moving under 2.4 % of its radius, so no pair
/// names it — departs by 3,022–4,744; two wedges left 2.9° off in the
/// other modes by 2·10⁵ and more; the compromise's points moved
/// 35–130 mm. The limit sits between the first measurements, 2× from
/// either.
pub const MAX_DEPARTURE_CHI2: f64 = 1500.0;

/// What [`check_pairs`] returns.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PairChecks {
    /// Every overlapping pair, in order of (source, target).
    pub pairs: Vec<PairCheck>,
    /// Each scan's used matches' footprint overlap on it: how far they use
    /// the same part of the scan (1 with one match or none;
    /// [`crate::links::adjust_matches`]).
    pub shared: Vec<f64>,
}

/// One overlapping pair matched again from the final poses.
#[derive(Debug, Clone, PartialEq)]
pub struct PairCheck {
    /// The scan whose frame the match is in.
    pub target: usize,
    /// The scan matched onto it.
    pub source: usize,
    /// Correspondences at the final poses.
    pub overlap: usize,
    /// How far the match moved the source's points from the final poses,
    /// metres (the centroid's displacement plus the turn times the RMS
    /// radius); `None` when the match failed.
    pub moved_m: Option<f64>,
    /// The match's turn from the final poses, radians.
    pub angle_rad: Option<f64>,
    /// The match's departure from the final relative pose: ξ = (ω, v),
    /// left, in the target's frame (final ≈ exp(ξ)·match).
    pub departure: Option<Vector6<f64>>,
    /// The motion against the match's own information: δᵀ·I·δ, δ the
    /// match's departure from the final poses (6 degrees of freedom).
    pub chi2: Option<f64>,
    /// The departure in χ² of the two final poses' relative covariance
    /// (their joint covariance's, [`weigh_residual_gains`]), and its
    /// degrees of freedom (the covariance's rank); `None` before it is
    /// known or where the match failed.
    pub relative_chi2: Option<(f64, usize)>,
    /// The motion as a fraction of the source points' RMS radius.
    pub relative_motion: Option<f64>,
    /// The motion along the directions the match sees well (eigenvalue at
    /// least [`SEEN_RATIO`] of the largest, about the source's centroid),
    /// metres: what judges the pair.
    pub seen_motion_m: Option<f64>,
    /// The match's point-to-plane RMS residual, metres.
    pub rmse_m: Option<f64>,
    /// The same residual at the final poses (the match's first pass),
    /// metres.
    pub start_rmse_m: Option<f64>,
    /// Whether the match settled (false: stopped at its iteration cap
    /// still moving); `None` when it failed.
    pub converged: Option<bool>,
    /// What a right registration of these two scans leaves: the RMS of
    /// their noise floors ([`noise_floor`]), metres.
    pub noise_m: f64,
    /// Whether the match's motion agrees with the final poses, the
    /// residual's gain and free space aside: it moved the points by at
    /// most the tolerance, or along what it sees well by at most
    /// [`MAX_RELATIVE_MOTION`] of their radius, turned them by at most
    /// [`MAX_TURN_RAD`] and moved them at most [`MAX_WEAK_MOTION`] of
    /// their radius in all.
    pub motion_agrees: bool,
    /// Whether the match settled (converged) where its residual is more
    /// than [`MAX_RESIDUAL_GAIN`] times lower than at the final poses,
    /// having moved the points beyond the tolerance. (A match stopped at
    /// its cap has settled nowhere: the simulated corridor's pair nine
    /// stations apart, right at the final poses within 0.045°, crept
    /// 0.48° at its cap to where its residual was 1.57× lower, and named
    /// two right scans; its motion is judged by the tiers, and the
    /// restarts take it up where the scans agree no better than at their
    /// starts, [`crate::scanset::Trigger::Creeping`].)
    pub residual_gain: bool,
    /// Whether the pair agrees with the final poses: the match moved the
    /// points by at most the tolerance, or along what it sees well by at
    /// most [`MAX_RELATIVE_MOTION`] of their radius and turned them by at
    /// most [`MAX_TURN_RAD`], moving them at most [`MAX_WEAK_MOTION`] of
    /// their radius in all, settling where its residual is at most
    /// [`MAX_RESIDUAL_GAIN`] times lower — or more where the departure is
    /// within the σ of the poses' relative pose ([`weigh_residual_gains`])
    /// — and no scanner's free space
    /// ([`crate::free_space`]) holds more than
    /// [`MAX_VIOLATION_SHARE`] of
    /// the other scan's points.
    pub consistent: bool,
    /// The free-space test from the pair's scanner whose view the other
    /// scan violates most; `None` when neither scanner's position is known.
    pub free_space: Option<FreeSpace>,
    /// The match as a relative measurement (its `target_from_source` and
    /// information), when it is one a link graph would use: it converged
    /// with more than `min_pairs` correspondences. The set's variance
    /// factor and covariances in the modes without a link graph are
    /// theirs ([`crate::links::adjust_matches`]).
    pub edge: Option<Edge>,
    /// The edge's noise as the link graph takes a link's, before the
    /// variance factor: its covariance by pair, calibrated, or its
    /// information's inverse (target frame; [`crate::links`]). The
    /// covariances of the modes without a link graph rest on it
    /// ([`crate::links::adjust_matches`]).
    pub edge_covariance: Option<Matrix6<f64>>,
    /// What its residuals do not show (target frame; zero without a
    /// match): how the pairs beyond the target's sampled edge pull it (a
    /// bias added to its noise as δδᵀ), how the edge leans it (the bias in
    /// its place where it explains the matches' misfit), and how far its
    /// two ways disagree (its scans' sampling) — [`crate::links::Pull`].
    pub pull: Pull,
}

impl PairCheck {
    /// Whether a scanner's free space holds more than
    /// [`MAX_VIOLATION_SHARE`] of the other scan's points.
    pub fn violates_free_space(&self) -> bool {
        self.free_space.is_some_and(|f| f.share() > MAX_VIOLATION_SHARE)
    }

    /// [`consistent`](Self::consistent) from the other fields: the
    /// motion agrees, the match did not settle [`MAX_RESIDUAL_GAIN`]
    /// times closer ([`residual_gain`](Self::residual_gain)) or its
    /// departure is within the relative pose's σ
    /// ([`weigh_residual_gains`]), and no free space is violated.
    fn judged(&self) -> bool {
        let within = self.relative_chi2.is_some_and(|(chi2, dof)| dof > 0 && chi2 <= chi2_999(dof));
        self.motion_agrees && (!self.residual_gain || within) && !self.violates_free_space()
    }
}

/// Where the final poses' joint covariance is known: each pair's
/// departure in χ² of its two poses' relative covariance
/// ([`PairCheck::relative_chi2`]), and a pair named only by its
/// residual's gain ([`MAX_RESIDUAL_GAIN`]) agrees after all when that
/// departure is within the 99.9 % point of χ² with the covariance's rank
/// ([`chi2_999`]): the poses are not known well enough
/// to say the pair's closer fit is elsewhere. Measured on the simulated
/// corridor (twenty scans within 18 mm of the truth), the modes without
/// a link graph: a pair nine stations apart, matched again, settled 34 mm
/// away with its residual 3× lower (15.6 → 5.1 mm) — within the σ of its
/// relative pose (28 mm) — and named right scans (exit 1); this clears
/// it. (Another, 38 mm and 0.48° away at 1.57×, χ² 500–556 here, is
/// cleared because it stopped at its cap: not a settled gain,
/// [`PairCheck::residual_gain`].) The street's wedges the gain names
/// (0.29 m along the street, 3.5° off) are hundreds of σ away.
///
/// A pair whose relative covariance is zero (rank 0: both poses hold the
/// frame) or that departs along a direction it does not span is never
/// cleared this way ([`crate::chi2::within`]).
pub fn weigh_residual_gains(checks: &mut [PairCheck], poses: &[Isometry3<f64>], joint: &crate::graph::JointCovariance) {
    for c in checks.iter_mut() {
        let (Some(e), Some(target)) = (c.departure, poses.get(c.target)) else { continue };
        if c.target.max(c.source) >= joint.len() {
            continue;
        }
        // ξ_source − ξ_target (world) in the target's frame.
        let ad = crate::se3::adjoint(&target.inverse());
        let relative = ad * joint.relative(c.target, c.source) * ad.transpose();
        c.relative_chi2 = Some(crate::chi2::within(&relative, &e));
        c.consistent = c.judged();
    }
}

/// Matches every pair of `scans` that overlaps at `poses` (their final
/// `world_from_scan`) once more from those poses with `config` (the finest
/// stage's, both ways or one as it says), and judges each: consistent
/// when its match moved the points by at most `tolerance_m` (the finest
/// voxel), or along what it sees well
/// ([`SEEN_RATIO`]) by at most [`MAX_RELATIVE_MOTION`] of their radius,
/// in all by at most [`MAX_WEAK_MOTION`] of it, turned them by at most
/// [`MAX_TURN_RAD`] and did not settle where its residual is more than
/// [`MAX_RESIDUAL_GAIN`] times lower (judged again against the poses'
/// relative σ where their joint covariance is known:
/// [`weigh_residual_gains`]); and, where `viewpoints` gives a scanner's
/// position in its scan's frame, by the free space it saw (margin: the
/// finest correspondence distance). With them, each scan's matches'
/// footprint overlap on it.
pub fn check_pairs<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    poses: &[Isometry3<f64>],
    viewpoints: &[Option<Point3<f64>>],
    config: &LinkConfig,
    tolerance_m: f64,
) -> Result<PairChecks> {
    check(scans, poses, &config.multiview)?;
    crate::FusionError::require_positive("verification tolerance (m)", tolerance_m)?;
    let prepared = prepare(scans, &config.multiview)?;
    // Both ways or one as `config` says: the modes without a link graph
    // match both ways, as graph mode's links are, for their covariances
    // rest on these matches ([`crate::links::adjust_matches`]: one way,
    // the matches' sub-millimetre lean was the strategies' own, and their
    // covariances 1.3–1.5× optimistic); graph mode one way, where the
    // check judges motion at the level of MAX_RELATIVE_MOTION and
    // MAX_TURN_RAD, a lean does not count, and it costs half (the
    // corridor's 77 scans: 22 s both ways, 15 s one).
    //
    // The match reports its covariance by pair and its pull beyond the edge
    // (which change nothing of it) for the covariances built on it.
    let matching = LinkConfig {
        multiview: crate::multiview::MultiviewConfig {
            icp: crate::icp::IcpConfig { edge_bias: true, range_noise: true, ..config.multiview.icp },
            ..config.multiview
        },
        ..*config
    };
    let Paired { links, footprints } = pair_links(&prepared, poses, &matching, &mut |_, _| ());
    let shared = shared_shares(prepared.len(), &links, &footprints);
    let shape: Vec<(Point3<f64>, f64)> = prepared.iter().map(|p| centroid_and_lever_arm(&p.source)).collect();
    let floors: Vec<f64> = scans.par_iter().map(|s| noise_floor(s.as_ref(), config)).collect();
    let views: Vec<Option<View>> = prepared
        .par_iter()
        .enumerate()
        .map(|(i, p)| viewpoints.get(i).copied().flatten().and_then(|v| View::new(&p.local, v).ok()))
        .collect();
    let margin_m = config.multiview.icp.max_correspondence_m;
    // The pair's worse side: the other scan against each known view.
    let free_space = |target: usize, source: usize| -> Option<FreeSpace> {
        let target_from_source = poses[target].inverse() * poses[source];
        let seen = |from: usize, other: usize, from_other: &Isometry3<f64>| {
            views[from].as_ref().map(|v| v.test(&prepared[other].local, from_other, margin_m, from))
        };
        [seen(target, source, &target_from_source), seen(source, target, &target_from_source.inverse())]
            .into_iter()
            .flatten()
            .max_by(|a, b| a.share().total_cmp(&b.share()))
    };
    let pairs = links
        .into_iter()
        .map(|l| {
            let (c, radius) = shape[l.source];
            let free_space = free_space(l.target, l.source);
            // The match as a link graph would use it: converged, enough pairs.
            let used = l.result.as_ref().filter(|_| l.rejected.is_none());
            let at = poses[l.target].inverse() * poses[l.source];
            let motion = l.result.as_ref().map(|r| {
                // δ: what the match did to the final relative pose, in the
                // source's frame.
                let delta = at.inverse() * r.target_from_source;
                let angle = delta.rotation.angle();
                let e = crate::se3::left_difference(&at, &r.target_from_source);
                let chi2 = (e.transpose() * r.information * e)[(0, 0)];
                let moved = crate::se3::motion(&delta, &c, radius);
                // e and the information are the target frame's; the source's
                // centroid is at `at · c` there.
                let seen = Observability::about(&r.information, &(at * c), radius, 0.0).seen_motion(&e, SEEN_RATIO);
                (moved, angle, chi2, moved / radius, seen, e)
            });
            let mut check = PairCheck {
                target: l.target,
                source: l.source,
                overlap: l.overlap,
                moved_m: motion.map(|m| m.0),
                angle_rad: motion.map(|m| m.1),
                departure: motion.map(|m| m.5),
                chi2: motion.map(|m| m.2),
                relative_chi2: None,
                relative_motion: motion.map(|m| m.3),
                seen_motion_m: motion.map(|m| m.4),
                rmse_m: l.result.as_ref().map(|r| r.rmse_m),
                start_rmse_m: l.result.as_ref().map(|r| r.start_rmse_m),
                converged: l.result.as_ref().map(|r| r.converged),
                noise_m: (0.5 * (floors[l.source].powi(2) + floors[l.target].powi(2))).sqrt(),
                // (A match still creeping at its cap but a few millimetres
                // from the poses agrees with them: the motion judges. One
                // that crept farther is judged alike — right pairs of the
                // simulated corridor and of a pipe creep along what they
                // see weakly —, and puts the result in doubt
                // ([`crate::scanset::Trigger::Creeping`]).)
                motion_agrees: motion.is_some_and(|(moved, angle, _, _, seen, _)| {
                    moved <= tolerance_m
                        || (seen <= MAX_RELATIVE_MOTION * radius
                            && angle <= MAX_TURN_RAD
                            && moved <= MAX_WEAK_MOTION * radius)
                }),
                residual_gain: motion.is_some_and(|m| m.0 > tolerance_m)
                    && l.result.as_ref().is_some_and(|r| r.converged && r.start_rmse_m > MAX_RESIDUAL_GAIN * r.rmse_m),
                consistent: false,
                free_space,
                edge: used.map(|r| Edge {
                    target: l.target,
                    source: l.source,
                    target_from_source: r.target_from_source,
                    information: r.information,
                }),
                edge_covariance: used.map(|r| crate::links::link_noise(r, config)),
                pull: l.result.as_ref().map_or_else(Pull::default, |r| Pull::of(r, config)),
            };
            check.consistent = check.judged();
            check
        })
        .collect();
    Ok(PairChecks { pairs, shared })
}

/// The point-to-plane RMS residual between two random halves of `points`
/// (each point dealt to one half by a mixing hash of its index,
/// `noise::share`), reduced and matched as `config` matches scans, at
/// the identity: what the data's noise and sampling leave of a
/// registration that is exactly right. Zero when a half is too small to
/// match. (Until session 72 each half was drawn by a multiplicative hash
/// of its own: the two shared 29 % of the points — the same samples with
/// the same noise in both — and missed as many, interleaved along the
/// scan lines; the floor was 1.85–1.94× lower on the 3DTK set's scans,
/// 1.21× on the PCL room pair's, 1.69× on small_gicp's pair's.)
pub fn noise_floor(points: &[Point3<f32>], config: &LinkConfig) -> f64 {
    let mv = &config.multiview;
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for (i, p) in points.iter().enumerate() {
        if crate::noise::share(i as u64, 1) == 0 { a.push(*p) } else { b.push(*p) }
    }
    let floor = || -> Result<f64> {
        let source = scanner::reduced_points(&a, mv.source_voxel_m)?;
        let model = scanner::reduced_points(&b, mv.target_voxel_m)?;
        let k = if mv.icp.method == crate::icp::Method::PointToPlane { mv.icp.normal_neighbours.max(3) } else { 0 };
        let mut target = crate::icp::Target::new(&model, k)?;
        target.orient_normals_towards(&mv.icp.source_viewpoint);
        let one = crate::icp::IcpConfig { max_iterations: 1, degeneracy_ratio: None, ..mv.icp };
        Ok(crate::icp::align(&source, &target, &Isometry3::identity(), &one)?.rmse_m)
    };
    floor().unwrap_or(0.0)
}

/// The scans of a set of `n` that the inconsistent pairs name: a pair is
/// inconsistent when its match moved from the final poses, or a scanner's
/// free space holds the other scan (a pair whose match failed and whose
/// free space is not violated names none). Scan 0 holds the frame and is
/// never named. The scan in the most inconsistent pairs is named first and
/// its pairs set aside, while some scan is in two or more; the scans of
/// each pair left are all named (a pair alone cannot tell which of its two
/// is wrong). So a hall scan placed among two room scans names the hall
/// scan, not the room scan it disagrees with too. Then a scan that agrees
/// with named scans, and that no chain of agreeing pairs through unnamed
/// scans ties to scan 0, is named too: nothing verified places it (two
/// scans left off together agree with each other, and only one of them
/// may be in a pair that moved).
pub fn untrusted(n: usize, checks: &[PairCheck]) -> Vec<usize> {
    let mut open: Vec<[usize; 2]> = checks
        .iter()
        .filter(|c| !c.consistent && (c.moved_m.is_some() || c.violates_free_space()))
        .map(|c| [c.source, c.target])
        .collect();
    let mut named = vec![false; n];
    while !open.is_empty() {
        let mut count = vec![0usize; n];
        for &i in open.iter().flatten() {
            count[i] += 1;
        }
        let Some(worst) = (1..n).max_by_key(|&i| count[i]) else { break };
        if count[worst] < 2 {
            for &i in open.iter().flatten() {
                named[i] = true;
            }
            break;
        }
        named[worst] = true;
        open.retain(|pair| !pair.contains(&worst));
    }
    let agreeing: Vec<[usize; 2]> = checks.iter().filter(|c| c.consistent).map(|c| [c.source, c.target]).collect();
    // Reached from `from` along agreeing pairs through scans `through` lets.
    let reach = |from: Vec<usize>, through: &dyn Fn(usize) -> bool| {
        let mut reached = vec![false; n];
        let mut queue = from;
        while let Some(i) = queue.pop() {
            if i >= n || reached[i] {
                continue;
            }
            reached[i] = true;
            queue.extend(agreeing.iter().filter(|p| p.contains(&i)).map(|p| p[0] + p[1] - i).filter(|&j| through(j)));
        }
        reached
    };
    let tied = reach(vec![0], &|j| !named[j]);
    let on_named = reach((1..n).filter(|&i| named[i]).collect(), &|j| !tied[j]);
    (1..n).filter(|&i| named[i] || on_named[i]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(target: usize, source: usize, moved_m: Option<f64>, consistent: bool) -> PairCheck {
        PairCheck {
            target,
            source,
            overlap: 1000,
            moved_m,
            angle_rad: moved_m.map(|_| 0.0),
            departure: None,
            chi2: None,
            relative_chi2: None,
            relative_motion: None,
            seen_motion_m: None,
            rmse_m: None,
            start_rmse_m: None,
            converged: moved_m.map(|_| true),
            noise_m: 0.001,
            motion_agrees: consistent,
            residual_gain: false,
            consistent,
            free_space: None,
            edge: None,
            edge_covariance: None,
            pull: Pull::default(),
        }
    }

    /// The relative pose's χ² is the departure against the scatter of
    /// the relative pose when the two poses are drawn from their joint
    /// covariance (Monte Carlo, through the poses themselves): its mean
    /// over draws is the covariance's rank; a pair named by its residual's
    /// gain alone agrees within the 99.9 % point, and stays named beyond
    /// it or where its motion is named too.
    #[test]
    fn a_residual_gain_within_the_relative_poses_sigma_agrees() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let pose = |x: f64, y: f64, yaw: f64| {
            Isometry3::from_parts(
                nalgebra::Translation3::new(x, y, 0.3),
                nalgebra::UnitQuaternion::from_euler_angles(0.02, -0.01, yaw),
            )
        };
        let poses = [pose(0.0, 0.0, 0.0), pose(12.0, 3.0, 0.7), pose(20.0, -4.0, 2.1)];
        // Poses 1 and 2 share much of their error (placed by the same links).
        let own = |k: f64| Matrix6::from_diagonal(&Vector6::new(1e-6, 2e-6, 4e-6 * k, 1e-4, 4e-4 * k, 2e-4));
        let mut joint = crate::graph::JointCovariance::zeros(3);
        joint.add(1, 1, &own(1.0));
        joint.add(2, 2, &own(2.0));
        joint.add(1, 2, &(0.6 * own(1.0)));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // Poses 1 and 2 drawn together (pose 0 holds the frame).
        let both = nalgebra::DMatrix::from_fn(12, 12, |r, c| joint.block(1 + r / 6, 1 + c / 6)[(r % 6, c % 6)]);
        let l = both.cholesky().expect("positive definite").l();
        let at = poses[1].inverse() * poses[2];
        let (draws, mut sum, mut beyond) = (4000, 0.0, 0);
        for _ in 0..draws {
            let z = nalgebra::DVector::from_fn(12, |_, _| StandardNormal.sample(&mut rng));
            let xi = &l * z;
            let moved = |k: usize| crate::se3::exp(&Vector6::from_fn(|r, _| xi[6 * k + r])) * poses[1 + k];
            // The "match": the relative pose of the drawn poses.
            let matched = moved(0).inverse() * moved(1);
            let mut c = pair(1, 2, Some(0.3), true);
            c.departure = Some(crate::se3::left_difference(&at, &matched));
            c.residual_gain = true;
            let mut checks = [c];
            weigh_residual_gains(&mut checks, &poses, &joint);
            let (chi2, dof) = checks[0].relative_chi2.expect("weighed");
            assert_eq!(dof, 6);
            assert_eq!(checks[0].consistent, chi2 <= chi2_999(6));
            sum += chi2;
            beyond += usize::from(chi2 > chi2_999(6));
        }
        // χ² with 6 degrees of freedom: mean 6 (σ of the mean 0.055),
        // 0.1 % beyond the limit.
        let mean = sum / f64::from(draws);
        assert!((mean - 6.0).abs() < 0.25, "mean χ² {mean}");
        assert!(beyond < 15, "{beyond} of {draws} beyond the 99.9 % point");
        // Ten σ away along the first axis: named; its motion named
        // besides: named however small the departure.
        let sigma = (crate::se3::adjoint(&poses[1].inverse())
            * joint.relative(1, 2)
            * crate::se3::adjoint(&poses[1].inverse()).transpose())[(0, 0)]
            .sqrt();
        let mut far = pair(1, 2, Some(0.3), true);
        (far.departure, far.residual_gain) = (Some(Vector6::new(10.0 * sigma, 0.0, 0.0, 0.0, 0.0, 0.0)), true);
        let mut slid = pair(1, 2, Some(0.3), true);
        (slid.departure, slid.residual_gain, slid.motion_agrees) = (Some(Vector6::zeros()), false, false);
        let mut checks = [far, slid];
        weigh_residual_gains(&mut checks, &poses, &joint);
        assert!(checks[0].relative_chi2.is_some_and(|(c, _)| c >= 100.0), "{:?}", checks[0].relative_chi2);
        assert!(!checks[0].consistent && !checks[1].consistent);
        // Against pose 0, which holds the frame, the other's own covariance.
        let mut first = pair(0, 1, Some(0.3), true);
        (first.departure, first.residual_gain) = (Some(Vector6::zeros()), true);
        let mut checks = [first];
        weigh_residual_gains(&mut checks, &poses, &joint);
        assert_eq!(checks[0].relative_chi2, Some((0.0, 6)));
        assert!(checks[0].consistent);
        // Two poses known exactly (rank 0): nothing clears the gain.
        let mut exact = pair(1, 2, Some(0.3), true);
        (exact.departure, exact.residual_gain) = (Some(Vector6::zeros()), true);
        let mut checks = [exact];
        weigh_residual_gains(&mut checks, &poses, &crate::graph::JointCovariance::zeros(3));
        assert_eq!(checks[0].relative_chi2, Some((0.0, 0)));
        assert!(!checks[0].consistent);
    }

    /// Four wedges, 2 and 3 left off together: they agree with each
    /// other; 1 and 3, which the truth does not overlap, move 1 m against
    /// each other; 2 overlaps neither 0 nor 1 any more. Named: 1 and 3 by
    /// their pair, and 2, which only agrees with 3; wedge 1's agreeing
    /// pair with wedge 0 does not clear it (a pair alone cannot tell which
    /// of its two is wrong).
    #[test]
    fn a_scan_placed_only_on_named_scans_is_named() {
        let checks = [
            pair(0, 1, Some(0.001), true),
            pair(1, 3, Some(0.97), false),
            pair(3, 2, Some(0.001), true),
            pair(0, 3, None, false),
        ];
        assert_eq!(untrusted(4, &checks), [1, 2, 3]);
        // With 2 also tied to the frame through 0, it stays trusted.
        let mut tied = checks.to_vec();
        tied.push(pair(0, 2, Some(0.001), true));
        assert_eq!(untrusted(4, &tied), [1, 3]);
        // A failed match names no one, and nothing agrees with a named scan.
        let failed = [pair(0, 1, Some(0.001), true), pair(1, 2, None, false), pair(0, 2, Some(0.002), true)];
        assert!(untrusted(3, &failed).is_empty());
        // A scan agreeing with a scan in the most inconsistent pairs, which
        // is named alone, and with nothing else.
        let hub = [
            pair(0, 1, Some(0.5), false),
            pair(2, 1, Some(0.5), false),
            pair(0, 2, Some(0.001), true),
            pair(1, 3, Some(0.001), true),
        ];
        assert_eq!(untrusted(4, &hub), [1, 3]);
    }
}
