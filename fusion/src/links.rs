//! A scan set adjusted over every overlapping pair: each pair is matched
//! (ICP from the current poses) and becomes a relative measurement — a
//! *link* — and the links are adjusted together in a pose graph
//! ([`crate::graph`]) with the first scan holding the frame. This is the
//! cps-icp machinery without CPS priors, for scans that come with nothing
//! but a guess of their poses (odometry, a scanner's registration, or
//! none).
//!
//! - **Blind directions.** With [`IcpConfig::degeneracy_ratio`] a link
//!   carries no information along the directions its pair cannot see (a
//!   corridor's axis, a pipe's roll: [`crate::icp::degeneracy`]). What
//!   holds the graph there is the start: consecutive scans are tied by the
//!   start's increment `start[i−1]⁻¹ · start[i]` with σ
//!   [`step_sigma_m`](LinkConfig::step_sigma_m) /
//!   [`step_sigma_rad`](LinkConfig::step_sigma_rad) per step — weak beside
//!   any match, so it decides only what no match sees, and the covariance
//!   there is the start's. Each scan's unobservable directions are those
//!   of the information its accepted links give it (the other scans held).
//! - **Pairs.** Two scans are a candidate pair when more than
//!   `min_pairs` correspondences lie within the overlap distance at the
//!   current poses; each scan keeps its
//!   [`max_partners`](LinkConfig::max_partners) best-overlapping earlier
//!   scans.
//! - **Rejected links.** A match that fails (too few correspondences, a
//!   singular system), or whose correspondences fall to
//!   [`min_pairs`](crate::multiview::MultiviewConfig::min_pairs) or fewer,
//!   is no link. After the adjustment the link that disagrees most with
//!   the others — χ² of its residual over the variance factor of the rest
//!   above [`gate_chi2`](LinkConfig::gate_chi2) — is left out and the graph
//!   solved again, while each of its scans keeps another link.
//! - **Variance factor.** ICP's covariance treats point errors as
//!   independent, and is optimistic; the adjustment's σ̂₀² = χ²/redundancy
//!   of the links (when there is redundancy and it exceeds 1) scales
//!   their covariance — not the start's steps', which hold only what no
//!   link sees. The redundancy is the links' own: 6 per link less 6 per
//!   scan they place. Where the links pass their global test, σ̂₀² is
//!   pooled with the calibration's ([`pooled_factor`]): one ring's chance
//!   misfit does not widen every direction.
//! - **Covariances.** The adjustment weighs each link by its information;
//!   each scan's covariance is that adjustment's with each link's own
//!   covariance ([`crate::graph::sandwich_covariance`]): its match's with
//!   each pair's variance its own squared residual (the covariance by
//!   pair), times σ̂₀², plus
//!   its pull by the pairs past the other scan's sampled edge (a bias its
//!   residuals do not show) — or, where the links corrected by their
//!   edges' lean agree better than as measured and as measured fail their
//!   global test, that lean, with the corrected links' σ̂₀² ([`Pull`]) —
//!   and, when σ̂₀² is below 1, the
//!   scans' shared noise (`shared_own`), and where a scan's links' two
//!   ways disagree beyond their noise, its own sampling (`sampling_own`).

use nalgebra::{Isometry3, Matrix6, Point3, Vector6};
use rayon::prelude::*;

use crate::error::{FusionError, Result};
use crate::graph::{Edge, JointCovariance};
use crate::icp::correspondences::Partners;
use crate::icp::degeneracy::{Observability, centroid_and_lever_arm};
use crate::icp::solve::{Reverse, align_both, align_from};
use crate::icp::{IcpConfig, IcpResult, Method};
use crate::multiview::{MultiviewConfig, Prepared, check, in_scan, prepare};
use crate::priors::GATE_CHI2;
use crate::se3::{Prior, adjoint, left_difference};

/// The link graph's settings (documented defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkConfig {
    /// Matching: the ICP settings, the voxels of the data and model sets,
    /// `min_pairs` and `overlap_m` (two scans are a candidate pair when
    /// more than `min_pairs` correspondences lie within `overlap_m`, or
    /// the ICP distance, at the current poses).
    pub multiview: MultiviewConfig,
    /// σ of the start's increment between consecutive scans, metres.
    /// Default 0.1.
    pub step_sigma_m: f64,
    /// … and radians. Default 1°.
    pub step_sigma_rad: f64,
    /// A link is an outlier above this normalised χ² (6 degrees of
    /// freedom). Default [`GATE_CHI2`] (99.9 %).
    pub gate_chi2: f64,
    /// Each scan is linked to at most this many earlier scans, those it
    /// overlaps most. Default 10 (on the simulated corridor's 20 scans, 2,
    /// 4, 6, 10 and all partners give 24, 24, 17, 12 and 12 mm RMS).
    pub max_partners: usize,
    /// Point-to-plane: match each pair both ways (each scan's points on
    /// the other's planes, in one set of normal equations), so that the
    /// link does not depend on which scan is the source. Default true
    /// (one way, the links of two random halves of one real scan were
    /// off by about 0.4 mm along the same direction whichever half was the
    /// source: BENCHMARKS, "Matching both ways").
    pub both_ways: bool,
    /// The factor on the links' covariance by pair
    /// ([`crate::icp::IcpResult::range_covariance`]) measured on the scans
    /// ([`crate::noise::Calibration::range_scale`]) — in the modes without
    /// a link graph, on each placing match's. Default 1.
    pub range_scale: f64,
    /// Factors on top of [`range_scale`](Self::range_scale) for the
    /// covariance by pair's rotation and its translation apart, about the
    /// source's centroid ([`crate::noise::by_blocks`]): the calibration's
    /// [`rotation_scale`](crate::noise::Calibration::rotation_scale) and
    /// [`translation_scale`](crate::noise::Calibration::translation_scale)
    /// over its `range_scale`. Default (1, 1).
    pub range_blocks: (f64, f64),
    /// What the scans' noise alone makes of a match's two ways'
    /// disagreement ([`crate::noise::Calibration::asymmetry`]): beyond it
    /// the links' asymmetry is their scans' sampling, each scan's own in
    /// every one of its links (the covariances in the [module
    /// docs](crate::links)). `None` (the default): not modelled.
    pub asymmetry: Option<f64>,
    /// The degrees of freedom of the calibration behind
    /// [`range_scale`](Self::range_scale)
    /// ([`crate::noise::Calibration::dof`]): where the links disagree more
    /// than their calibrated noise says (σ̂₀² above 1), the factor on
    /// their noise is the two estimates pooled by their degrees of
    /// freedom ([`pooled_factor`]). 0 (the default): σ̂₀² alone.
    pub calibration_dof: usize,
}

impl LinkConfig {
    /// The information of one step of the start (σ `step_sigma_rad` about
    /// each axis, `step_sigma_m` along it), order ξ = (ω, v).
    pub fn step_information(&self) -> Matrix6<f64> {
        let (r, t) = (self.step_sigma_rad.powi(-2), self.step_sigma_m.powi(-2));
        Matrix6::from_diagonal(&Vector6::new(r, r, r, t, t, t))
    }
}

/// The largest motion of a pair matched again from the final poses, as a
/// fraction of the source points' RMS radius, that is still agreement
/// ([`crate::verify`]); a cycle of links that misses by more is gross.
pub const MAX_RELATIVE_MOTION: f64 = 0.05;

/// The largest turn of a pair matched again that is still agreement,
/// radians (5°): however weakly a pair sees a turn, a room's wedges
/// trapped 90° off turned 12° when matched again, where right real sets
/// turn at most 2.5° (the 3DTK set's weakest pair in the single-strategy
/// modes; 1.2° in graph mode) and the corridor's pairs 0.7°. A cycle of
/// links that misses by more is gross.
pub const MAX_TURN_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// The default eigenvalue ratio below which a match's direction is blind
/// (`match --degeneracy-ratio`), between the measured noise and the real
/// scans' weakest informative direction (see [`LinkConfig::default`]).
pub const DEFAULT_DEGENERACY_RATIO: f64 = 2e-3;

/// The blind-direction threshold a pipe or a tunnel needs (`match
/// --degeneracy-ratio 0.01`, the sewer mission's `degeneracy_ratio`):
/// their axis, seen weakly through a dent or a brick, is held by the
/// start there (docs/match.md, Known limits).
pub const PIPE_DEGENERACY_RATIO: f64 = 1e-2;

/// The line test's ratio with a threshold of one's own
/// ([`crate::icp::IcpConfig::line_ratio`]: `match --line-ratio` with
/// `--degeneracy-ratio`, a mission's `[fusion] line_ratio` with its
/// `degeneracy_ratio`): a scanner that takes its scans in slices far
/// apart (fewer `slices`) made a pipe's axis look seen through its
/// lines' normals (docs/fusion.md, the sewer at 60 slices).
pub const DEFAULT_LINE_RATIO: f64 = 0.1;

impl Default for LinkConfig {
    fn default() -> Self {
        let multiview = MultiviewConfig::default();
        Self {
            multiview: MultiviewConfig {
                // Analysed about the source's centroid: noise in the
                // normals (1 mm on a 5 cm grid) gives a corridor's axis a
                // spurious ratio up to 1.2e-3 (the sewer's axis 1.4e-3);
                // the real scans here have no direction below 3.1e-3 (the
                // 3DTK set's coarse stages; 1.6e-2 at its last, the room
                // and small_gicp pairs 8e-2).
                icp: IcpConfig { degeneracy_ratio: Some(DEFAULT_DEGENERACY_RATIO), ..multiview.icp },
                ..multiview
            },
            step_sigma_m: 0.1,
            step_sigma_rad: 1f64.to_radians(),
            gate_chi2: GATE_CHI2,
            max_partners: 10,
            both_ways: true,
            range_scale: 1.0,
            range_blocks: (1.0, 1.0),
            asymmetry: None,
            calibration_dof: 0,
        }
    }
}

/// One candidate pair of scans and its match.
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// The scan whose frame the match is in.
    pub target: usize,
    /// The scan matched onto it.
    pub source: usize,
    /// Correspondences at the start poses (the overlap that made the pair).
    pub overlap: usize,
    /// The match, when ICP ran to the end.
    pub result: Option<IcpResult>,
    /// Why the link is not used; `None` when it is.
    pub rejected: Option<String>,
    /// For a link that disagrees with the others beyond the gate: the
    /// shortest cycle of used links it closes (scans from its target round
    /// to its source), with how far that path and the link disagree. The
    /// link is rejected when other cycles can tell that it is the wrong
    /// one, or its cycle misses grossly; else (a triangle's, a ring's
    /// link) it is kept and the variance factor carries the miss.
    pub cycle: Option<Cycle>,
}

/// A cycle of used links that a link disagreeing with the others closes.
#[derive(Debug, Clone, PartialEq)]
pub struct Cycle {
    /// The scans from the link's target to its source along used links.
    pub scans: Vec<usize>,
    /// The turn between the path's `target_from_source` and the link's,
    /// radians.
    pub angle_rad: f64,
    /// How far their difference moves the source's points: the
    /// displacement of the points' centroid, metres — frame-free, as the
    /// verification's motion ([`crate::verify`]): at the scan's origin a
    /// scan seen from 60 m turned a 2° miss into half a metre.
    pub translation_m: f64,
}

/// What [`adjust`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkGraph {
    /// Every scan's adjusted `world_from_scan`; scan 0 stays at its pose.
    pub world_from_scan: Vec<Isometry3<f64>>,
    /// Each pose's 6×6 covariance (ξ = (ω, v), left perturbation, world
    /// frame) relative to scan 0 (zero: it is the frame), the links'
    /// information scaled down by the variance factor when it exceeds 1
    /// (the start's steps, which hold what no link sees, are not).
    pub covariance: Vec<Matrix6<f64>>,
    /// The poses' joint covariance, [`covariance`](Self::covariance) its
    /// diagonal (scan 0's rows and columns zero).
    pub joint_covariance: JointCovariance,
    /// Each pose's share of [`covariance`](Self::covariance) that is the
    /// scans' own sampling ([`Adjusted::sampling`]): left out of every
    /// judgement of a pose.
    pub sampling: Vec<Matrix6<f64>>,
    /// The share of [`joint_covariance`](Self::joint_covariance) that is
    /// the pairs' rest ([`Adjusted::pairs_rest`]): left out of every
    /// judgement of a pose; `None` where there is none.
    pub pairs_rest: Option<JointCovariance>,
    /// Every candidate pair, used or not, in order of (source, target).
    pub links: Vec<Link>,
    /// Each scan's directions its links do not see (unit ξ = (ω, v), world
    /// frame), by the ICP settings' `degeneracy_ratio` (none without it):
    /// held by the start's increments.
    pub unobservable: Vec<Vec<Vector6<f64>>>,
    /// σ̂₀² = χ² / redundancy of the used links in the final adjustment
    /// (1 without redundancy).
    pub variance_factor: f64,
    /// σ̂₀² of the used links each corrected by its edge's lean
    /// ([`LEAN_SHORTFALL`]× [`crate::icp::IcpResult::edge_lean`]) and
    /// adjusted again; `None` without redundancy or a lean. Below
    /// [`variance_factor`](Self::variance_factor), where the links as
    /// measured fail their global test ([`GLOBAL_TEST_LEVEL`]), the lean
    /// explains the links' misfit, and the covariances take it ([`Pull`]).
    pub lean_variance_factor: Option<f64>,
    /// The used links' redundancy: 6 per link less 6 per scan they place
    /// (the start's steps take no part).
    pub redundancy: usize,
    /// The factor the covariances take on the links' noise: σ̂₀² (or the
    /// lean's, [`Pull`]), above 1 and within the links' global test
    /// pooled with the calibration's ([`pooled_factor`]), never below
    /// 0.05 (the least share of the noise taken as independent); 1
    /// without redundancy.
    pub noise_factor: f64,
}

/// Matches every overlapping pair of `scans` from `poses` (their current
/// `world_from_scan`, e.g. a coarser stage's result) and adjusts the links
/// in a pose graph, the increments of `starts` (the guesses the set came
/// with, or the coarser stage's poses) holding what no link sees. `progress(done,
/// total)` is called as each scan's pairs (those whose boxes meet) are
/// counted and matched.
pub fn adjust<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    poses: &[Isometry3<f64>],
    starts: &[Isometry3<f64>],
    config: &LinkConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<LinkGraph> {
    check(scans, poses, &config.multiview)?;
    check(scans, starts, &config.multiview)?;
    FusionError::require_positive("step σ (m)", config.step_sigma_m)?;
    FusionError::require_positive("step σ (rad)", config.step_sigma_rad)?;
    FusionError::require_positive("link gate χ²", config.gate_chi2)?;
    if config.max_partners == 0 {
        return Err(FusionError::OutOfRange { what: "partners per scan".into(), value: 0.0, expected: "≥ 1".into() });
    }
    let prepared = prepare(scans, &config.multiview)?;
    let Paired { links, footprints } = pair_links(&prepared, poses, config, progress);
    let shape: Vec<(Point3<f64>, f64)> = prepared.iter().map(|p| centroid_and_lever_arm(&p.source)).collect();
    let shared = shared_shares(prepared.len(), &links, &footprints);
    solve(poses, starts, links, &shape, &shared, config)
}

/// A link's footprint on one of its scans: the scan's points within the
/// overlap distance of the partner, counted in cubes of twice that
/// distance in the scan's frame ([`shared_shares`]).
pub(crate) type Footprint = std::collections::HashMap<(i64, i64, i64), f64>;

/// What [`pair_links`] returns.
pub(crate) struct Paired {
    /// The links, in order of (source, target).
    pub links: Vec<Link>,
    /// Each link's footprints on its source and on its target, at the
    /// poses they were paired at.
    pub footprints: Vec<[Footprint; 2]>,
}

/// The footprints of a link on its source and its target
/// (`target_from_source`), from the source points' nearest target points
/// (`partners`) found there: the source points within `overlap_m`, in
/// the source's frame and in the target's.
fn footprints(
    source: &[Point3<f32>],
    target_from_source: &Isometry3<f64>,
    partners: &Partners,
    overlap_m: f64,
) -> [Footprint; 2] {
    let cell = 2.0 * overlap_m;
    let key = |p: &Point3<f64>| -> (i64, i64, i64) {
        ((p.x / cell).floor() as i64, (p.y / cell).floor() as i64, (p.z / cell).floor() as i64)
    };
    let (mut on_source, mut on_target) = (Footprint::new(), Footprint::new());
    for (i, p) in source.iter().enumerate() {
        if partners.is_within(i, overlap_m) {
            let p = p.cast::<f64>();
            *on_source.entry(key(&p)).or_default() += 1.0;
            *on_target.entry(key(&(target_from_source * p))).or_default() += 1.0;
        }
    }
    [on_source, on_target]
}

/// Each of `n` scans' links' footprint overlap: how much one used link's
/// footprint on the scan (`footprints`, [`pair_links`]) its other used
/// links share, the mean over its pairs of links of the counts' cosine
/// Σ a·b / √(Σ a² · Σ b²): 1 for random shares of one scan, whose every
/// link uses all of it; about 0 for wedges, each of whose links uses
/// another part; and 1 for a scan with one link. A scan's own noise is
/// common to its links in that share ([`shared_own`]).
pub(crate) fn shared_shares(n: usize, links: &[Link], footprints: &[[Footprint; 2]]) -> Vec<f64> {
    let mut of_scan: Vec<Vec<&Footprint>> = vec![Vec::new(); n];
    for (l, [on_source, on_target]) in links.iter().zip(footprints).filter(|(l, _)| l.rejected.is_none()) {
        of_scan[l.source].push(on_source);
        of_scan[l.target].push(on_target);
    }
    let cosine = |a: &Footprint, b: &Footprint| {
        let dot: f64 = a.iter().filter_map(|(k, x)| b.get(k).map(|y| x * y)).sum();
        let norm = (a.values().map(|x| x * x).sum::<f64>() * b.values().map(|x| x * x).sum::<f64>()).sqrt();
        if norm > 0.0 { dot / norm } else { 0.0 }
    };
    of_scan
        .iter()
        .map(|sets| {
            let (mut sum, mut pairs) = (0.0, 0usize);
            for (k, a) in sets.iter().enumerate() {
                for b in &sets[k + 1..] {
                    sum += cosine(a, b);
                    pairs += 1;
                }
            }
            if pairs == 0 { 1.0 } else { sum / pairs as f64 }
        })
        .collect()
}

/// Every pair of `prepared` scans whose boxes meet at `poses` and that share
/// more than `min_pairs` correspondences there (each scan with its
/// `max_partners` best-overlapping earlier scans), matched from those poses:
/// the links, in order of (source, target), with their footprints there
/// ([`footprints`]). `progress(done, total)` as in [`adjust`].
pub(crate) fn pair_links(
    prepared: &[Prepared],
    poses: &[Isometry3<f64>],
    config: &LinkConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Paired {
    let mv = &config.multiview;
    let n = prepared.len();
    let overlap_m = mv.overlap_distance();
    // Pairs whose world boxes (grown by the overlap distance) meet: the
    // correspondences are counted only for those.
    let boxes: Vec<(Point3<f64>, Point3<f64>)> = prepared
        .par_iter()
        .zip(poses)
        .map(|(p, pose)| {
            p.source.iter().fold(
                (Point3::from([f64::INFINITY; 3]), Point3::from([f64::NEG_INFINITY; 3])),
                |(lo, hi), q| {
                    let w = pose * q.cast::<f64>();
                    (lo.inf(&w), hi.sup(&w))
                },
            )
        })
        .collect();
    let meet = |a: usize, b: usize| {
        (0..3).all(|k| boxes[a].0[k] - overlap_m <= boxes[b].1[k] && boxes[b].0[k] - overlap_m <= boxes[a].1[k])
    };
    // Each scan's earlier scans whose boxes meet its own and that share
    // cells of twice the overlap distance with it, the best-ranked few
    // ([`crate::candidates`]: counting against every earlier scan was
    // quadratic where all see one another).
    let occupancy = crate::candidates::Occupancy::new(
        &prepared.iter().map(|p| p.source.as_slice()).collect::<Vec<_>>(),
        poses,
        2.0 * overlap_m,
    );
    let earlier: Vec<Vec<usize>> = (0..n)
        .map(|c| {
            let mut e = occupancy.ranked(c, |j| j < c && meet(j, c), crate::candidates::SCREEN * config.max_partners);
            e.sort_unstable();
            e
        })
        .collect();
    let total: usize = earlier.iter().map(Vec::len).sum();
    let mut done = 0;
    progress(0, total);
    let (mut links, mut prints) = (Vec::new(), Vec::new());
    // Scan by scan: the overlap with every earlier scan counted (each
    // source point's nearest neighbour searched once and kept), then the
    // best-overlapping ones matched from those same neighbours.
    for (c, earlier) in earlier.iter().enumerate().filter(|(_, e)| !e.is_empty()) {
        let source = &prepared[c].source;
        let mut found: Vec<(usize, usize, Partners)> = earlier
            .par_iter()
            .map(|&j| {
                let partners = Partners::at(source, &prepared[j].local, &(poses[j].inverse() * poses[c]));
                (j, partners.within(overlap_m), partners)
            })
            .filter(|(_, overlap, _)| *overlap > mv.min_pairs)
            .collect();
        found.sort_by_key(|&(j, overlap, _)| std::cmp::Reverse((overlap, j)));
        found.truncate(config.max_partners);
        found.sort_by_key(|&(j, _, _)| j);
        let matched: Vec<(Link, [Footprint; 2])> = found
            .into_par_iter()
            .map(|(j, overlap, partners)| {
                let init = poses[j].inverse() * poses[c];
                let footprints = footprints(source, &init, &partners, overlap_m);
                let target = &prepared[j].local;
                let r = if config.both_ways && mv.icp.method == Method::PointToPlane {
                    let reverse = Reverse { points: &prepared[j].source, model: &prepared[c].local };
                    align_both(source, target, &init, &mv.icp, partners, reverse)
                } else {
                    align_from(source, target, &init, &mv.icp, partners)
                }
                .map_err(|e| in_scan(c, e));
                let (result, rejected) = match r {
                    Ok(r) if r.inliers <= mv.min_pairs => {
                        let why = format!(
                            "{} correspondences after matching: expected more than {}",
                            r.inliers, mv.min_pairs
                        );
                        (Some(r), Some(why))
                    }
                    // A match stopped by the iteration cap is still moving:
                    // its pose is not one the data agree on (a 1e-4 m Huber
                    // width left a scan 1.1 m off, its link "accepted").
                    Ok(r) if !r.converged => {
                        let why = format!(
                            "did not converge in {} iterations: its updates still moved more than the tolerance",
                            r.iterations
                        );
                        (Some(r), Some(why))
                    }
                    Ok(r) => (Some(r), None),
                    Err(e) => (None, Some(format!("the match failed: {e}"))),
                };
                (Link { target: j, source: c, overlap, result, rejected, cycle: None }, footprints)
            })
            .collect();
        let (l, f): (Vec<_>, Vec<_>) = matched.into_iter().unzip();
        links.extend(l);
        prints.extend(f);
        done += earlier.len();
        progress(done, total);
    }
    Paired { links, footprints: prints }
}

/// The shortest path of `used` links other than `k` from link `k`'s target
/// to its source (breadth first), and how its composed transform and the
/// link's disagree at `centroid` (of the source's points, in its frame);
/// `None` when no such path exists.
fn cycle(links: &[Link], used: &[usize], k: usize, centroid: &Point3<f64>) -> Option<Cycle> {
    let (from, to) = (links[k].target, links[k].source);
    // Each scan reached: (the scan it was reached from, target_from_this).
    let mut reached: std::collections::HashMap<usize, (usize, Isometry3<f64>)> = std::collections::HashMap::new();
    reached.insert(from, (from, Isometry3::identity()));
    let mut queue = std::collections::VecDeque::from([from]);
    while let Some(a) = queue.pop_front() {
        if a == to {
            break;
        }
        let at = reached[&a].1;
        for &u in used.iter().filter(|&&u| u != k) {
            let (l, r) = (&links[u], links[u].result.as_ref()?);
            let next = if l.target == a {
                Some((l.source, at * r.target_from_source))
            } else if l.source == a {
                Some((l.target, at * r.target_from_source.inverse()))
            } else {
                None
            };
            if let Some((b, pose)) = next
                && let std::collections::hash_map::Entry::Vacant(e) = reached.entry(b)
            {
                e.insert((a, pose));
                queue.push_back(b);
            }
        }
    }
    let (_, path_pose) = *reached.get(&to)?;
    let mut scans = vec![to];
    while let Some(&last) = scans.last()
        && last != from
    {
        scans.push(reached[&last].0);
    }
    scans.reverse();
    let link = links[k].result.as_ref()?.target_from_source;
    let d = path_pose.inverse() * link;
    Some(Cycle { scans, angle_rad: d.rotation.angle(), translation_m: (d * centroid - centroid).norm() })
}

/// Whether the `used` links other than `k` tell whether link `k` is the
/// wrong one of its cycles: without it its scans are still joined, and
/// still without it and any one other link (no link is in series with
/// it).
fn identifiable(links: &[Link], used: &[usize], k: usize) -> bool {
    // Each scan's used links other than k: (link, the scan at its other end).
    let mut around: std::collections::HashMap<usize, Vec<(usize, usize)>> = std::collections::HashMap::new();
    for &m in used.iter().filter(|&&m| m != k) {
        let (a, b) = (links[m].target, links[m].source);
        around.entry(a).or_default().push((m, b));
        around.entry(b).or_default().push((m, a));
    }
    let joined = |without: Option<usize>| {
        let (from, to) = (links[k].target, links[k].source);
        let mut seen = std::collections::HashSet::from([from]);
        let mut queue = std::collections::VecDeque::from([from]);
        while let Some(s) = queue.pop_front() {
            for &(m, next) in around.get(&s).map_or(&[][..], Vec::as_slice) {
                if Some(m) != without && seen.insert(next) {
                    queue.push_back(next);
                }
            }
        }
        seen.contains(&to)
    };
    joined(None) && used.iter().filter(|&&m| m != k).all(|&m| joined(Some(m)))
}

/// Each scan's covariance from the start's steps alone (those
/// [`adjust_matches`] holds the poses with; world frame, ξ = (ω, v),
/// left; zero for scan 0, the frame): what the start
/// says of scan i is the chain of steps 1..=i, each step's error in the
/// frame of the scan before it — Σ Ad(Tⱼ₋₁)·S⁻¹·Ad(Tⱼ₋₁)ᵀ at `poses`.
/// Beside an adjustment's covariance it tells which directions the
/// matches hold less than the start does
/// ([`crate::scanset::held_by_start`]).
pub fn steps_covariance(poses: &[Isometry3<f64>], config: &LinkConfig) -> Vec<Matrix6<f64>> {
    let step = config.step_information().try_inverse().unwrap_or_else(Matrix6::zeros);
    let mut sum = Matrix6::zeros();
    let mut out = Vec::with_capacity(poses.len());
    for (i, _) in poses.iter().enumerate() {
        if i > 0 {
            let a = crate::se3::adjoint(&poses[i - 1]);
            sum += a * step * a.transpose();
        }
        out.push(sum);
    }
    out
}

/// What holds a graph of `poses`' scans besides its links: scan 0's
/// prior at its pose (1 µm / 1 µrad: it holds the frame), and consecutive
/// scans tied by the increments of `starts` with the step information.
fn frame_and_steps(
    poses: &[Isometry3<f64>],
    starts: &[Isometry3<f64>],
    config: &LinkConfig,
) -> (Vec<Option<Prior>>, Vec<Edge>) {
    let n = poses.len();
    let step_information = config.step_information();
    let steps: Vec<Edge> = (1..n)
        .map(|i| Edge {
            target: i - 1,
            source: i,
            target_from_source: starts[i - 1].inverse() * starts[i],
            information: step_information,
        })
        .collect();
    let mut priors = vec![None; n];
    if let Some(first) = poses.first() {
        priors[0] = Some(Prior { target_from_source: *first, information: Matrix6::identity() * 1e12 });
    }
    (priors, steps)
}

/// What relative measurements between scans placed by a strategy say of
/// their poses ([`adjust_matches`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Adjusted {
    /// The measurements' variance factor σ̂₀² = χ²/redundancy (1 without
    /// redundancy): how much more they disagree with one another than
    /// their information allows.
    pub variance_factor: f64,
    /// σ̂₀² of the measurements each corrected by its edge's lean, as
    /// [`LinkGraph::lean_variance_factor`].
    pub lean_variance_factor: Option<f64>,
    /// The measurements' redundancy ([`LinkGraph::redundancy`]).
    pub redundancy: usize,
    /// The factor the covariances take on their noise
    /// ([`LinkGraph::noise_factor`]).
    pub noise_factor: f64,
    /// How far each pose is from the measurements' adjustment: ξ with
    /// pose ≈ exp(ξ)·adjusted (world frame; zero for scan 0, the frame).
    pub departure: Vec<Vector6<f64>>,
    /// Each pose's covariance (ξ = (ω, v), left, world frame; zero for
    /// scan 0): the adjustment's in the link graph's model ([`adjust`]'s
    /// covariances), plus its departure's w·ξξᵀ
    /// ([`departure_weight`](Self::departure_weight)).
    pub covariance: Vec<Matrix6<f64>>,
    /// The poses' joint covariance, [`covariance`](Self::covariance) its
    /// diagonal: the adjustment's, plus the stacked departures' w·ξξᵀ
    /// (scan 0's rows and columns zero).
    pub joint_covariance: JointCovariance,
    /// Each departure against the adjustment's covariance C (without
    /// w·ξξᵀ): ξᵀ·C⁺·ξ — how far the strategy stopped from where its pairs
    /// agree, in the σ of that agreement (zero for scan 0;
    /// [`crate::verify::MAX_DEPARTURE_CHI2`]), C less its
    /// [`sampling`](Self::sampling) and [`pairs_rest`](Self::pairs_rest).
    pub departure_chi2: Vec<f64>,
    /// The share of the departures' ξξᵀ in
    /// [`covariance`](Self::covariance) ([`departure_weight`]).
    pub departure_weight: f64,
    /// Each pose's share of [`covariance`](Self::covariance) that is the
    /// scans' own sampling (its scan's and the first's,
    /// [`LinkConfig::asymmetry`]; zero without it): left out of every
    /// judgement of a pose — a wrong pose's two ways disagree by far more
    /// than a right one's, and a covariance grown by that would hide it.
    pub sampling: Vec<Matrix6<f64>>,
    /// The share of [`joint_covariance`](Self::joint_covariance) that is
    /// the pairs' rest: where the links agree better than their noise
    /// says (σ̂₀² below 1) but their scans' footprints do not share that
    /// noise, the part of it that stays the pairs' (of a link's noise,
    /// the pair's share is f + (1 − f)·(1 − s̄) rather than the factor f,
    /// s̄ the mean of its two scans' footprint overlaps: `pair_share`;
    /// scan 0's rows and columns zero); `None` where every link's noise
    /// takes the factor alone. Left out of every judgement of a pose, as
    /// the sampling is: the judgements (departures, moves along what only
    /// the start holds, residual gains) were tuned on the narrower
    /// covariance, and a wrong registration grown into the wider one
    /// passed them (BENCHMARKS.md, session 65).
    pub pairs_rest: Option<JointCovariance>,
}

/// `edges` — relative measurements between the scans at `poses`, e.g. the
/// verification's matches ([`crate::verify::PairCheck::edge`]), with each
/// one's `noise` before the variance factor
/// ([`crate::verify::PairCheck::edge_covariance`]) and its `pulls`
/// ([`crate::verify::PairCheck::pull`]), and each scan's
/// `shared` footprint overlap of its edges
/// ([`crate::verify::PairChecks::shared`]; empty: 1 for every scan) —
/// adjusted from `poses` as [`adjust`] adjusts its links, the
/// poses' own increments holding what no edge sees, whichever strategy
/// placed the scans. A strategy that places each scan against partners
/// held stops short of where all its pairs agree (simultaneous matching
/// re-matches a scan only when a partner moved beyond a tolerance; a chain
/// never closes its cycles): its poses are the adjustment's plus their
/// departure from it, which is measured — so their error is the
/// adjustment's (whose covariance the link graph's model gives) plus the
/// departure, and their covariance the adjustment's plus ξξᵀ (with
/// independent errors and the adjustment the best linear estimate, its
/// error is uncorrelated with any other estimate's difference from it) —
/// whole or as far as the departures exceed the adjustment's noise
/// (`departures`, [`Departures`]).
pub fn adjust_matches(
    poses: &[Isometry3<f64>],
    edges: &[Edge],
    noise: &[Matrix6<f64>],
    pulls: &[Pull],
    shared: &[f64],
    config: &LinkConfig,
    departures: Departures,
) -> Result<Adjusted> {
    if noise.len() != edges.len() || pulls.len() != edges.len() {
        return Err(FusionError::OutOfRange {
            what: "noise and pulls of the matches".into(),
            value: noise.len().min(pulls.len()) as f64,
            expected: format!("one of each per match: {}", edges.len()),
        });
    }
    let (priors, mut all) = frame_and_steps(poses, poses, config);
    let steps = all.len();
    all.extend_from_slice(edges);
    let g = crate::graph::optimize(poses, &priors, &all, 20)?;
    let Judged { variance_factor, redundancy, .. } = judged(&g.world_from_scan, edges);
    let lean_variance_factor = lean_factor(&g.world_from_scan, &priors, &all, steps, pulls)?;
    let agreement = Agreement::of(variance_factor, lean_variance_factor, redundancy, shared, config);
    let Spread { mut joint, sampling, pairs_rest, noise_factor } =
        adjusted_covariance(&g.world_from_scan, &priors, &all, steps, noise, pulls, &agreement)?;
    // The departures are judged without the scans' sampling (a wrong pose's
    // two ways disagree by far more than a right one's, and a covariance
    // grown by that would hide it) nor the pairs' rest.
    let adjusted: Vec<Matrix6<f64>> = joint
        .diagonal()
        .iter()
        .enumerate()
        .map(|(i, c)| judged_covariance(c, &sampling, pairs_rest.as_ref(), i))
        .collect();
    // Scan 0's prior leaves it within 1e-20 m of its pose: the departures
    // are the others'.
    let departure: Vec<Vector6<f64>> = poses
        .iter()
        .zip(&g.world_from_scan)
        .enumerate()
        .map(|(i, (p, a))| if i == 0 { Vector6::zeros() } else { left_difference(p, a) })
        .collect();
    let departure_chi2 = adjusted
        .iter()
        .zip(&departure)
        .enumerate()
        .map(
            |(i, (c, d))| if i == 0 { 0.0 } else { (d.transpose() * crate::icp::solve::pseudo_inverse(c) * d)[(0, 0)] },
        )
        .collect();
    // The departures as one stacked error, as far as it exceeds the
    // adjustment's own noise: each pair's w·ξᵢξⱼᵀ.
    let departure_weight = match departures {
        Departures::Whole => 1.0,
        Departures::BeyondNoise => departure_weight(&joint, &departure),
    };
    for i in 1..poses.len() {
        for j in 1..=i {
            joint.add(i, j, &(departure_weight * departure[i] * departure[j].transpose()));
        }
    }
    Ok(Adjusted {
        variance_factor,
        lean_variance_factor,
        redundancy,
        noise_factor,
        departure,
        covariance: joint.diagonal(),
        joint_covariance: joint,
        departure_chi2,
        departure_weight,
        sampling,
        pairs_rest,
    })
}

/// How the poses' covariance carries their departures' ξξᵀ
/// ([`adjust_matches`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Departures {
    /// Whole: each pose placed on one partner's match (pairwise matching,
    /// a tree of its own links), the worse estimate of the two, its error
    /// uncorrelated with the adjustment's (a chain of four scans, Monte
    /// Carlo unit test below: mean NEES 5.0, the adjustment's own 4.8).
    Whole,
    /// As far as they exceed the adjustment's noise
    /// ([`departure_weight`]): each pose placed on several partners'
    /// matches (incremental and simultaneous matching), nearly as good an
    /// estimate as the adjustment.
    BeyondNoise,
}

/// How much of the stacked departures' ξξᵀ the poses' joint covariance
/// carries ([`Departures::BeyondNoise`]), from their χ² in the
/// adjustment's joint σ (`joint`, the frame's pose held; scan 0's
/// departure is zero): w = (1 − k/χ²)₊, k = 6 per pose but the first —
/// the departures scaled so that their size in that σ, w·χ² = χ² − k, is
/// the unbiased estimate of how far they reach beyond the adjustment's
/// noise (which alone would make χ² ≈ k of them). The covariance is then,
/// on average, the departures' own, cov(ξ) — a strategy's error ε's
/// where it shares half the adjustment's, cov(ε, εₐ) = Σₐ/2 (Monte Carlo
/// unit test). Whole ([`Departures::Whole`]), Σₐ + ξξᵀ is right where it
/// shares all of it — the adjustment the better estimate, its error
/// uncorrelated with the departure (a chain of links); where the strategy
/// placed each scan on several partners' matches — incremental and
/// simultaneous matching — its pose is nearly as good as the adjustment
/// and ξξᵀ whole counts part of the adjustment's error twice: on real
/// scans' parts the room's shares in those modes were 1.5× pessimistic
/// with it (mean NEES 4.3 on thirteen seeds, 1 of 26 cells in the χ²
/// interval; BENCHMARKS, session 62). Departures within the adjustment's
/// noise add nothing; a compromise's (1,000 σ² a pose) nearly all of
/// themselves. Where the adjustment's joint covariance is singular,
/// whole.
pub fn departure_weight(joint: &JointCovariance, departure: &[Vector6<f64>]) -> f64 {
    let k = 6.0 * departure.len().saturating_sub(1) as f64;
    match joint.chi2(departure, 1) {
        Some(chi2) if chi2 > k => 1.0 - k / chi2,
        Some(_) => 0.0,
        None => 1.0,
    }
}

/// Links (as graph edges) judged at their adjusted `poses`.
struct Judged {
    /// Each link's χ²: eᵀ·I·e, e its measurement's departure from the
    /// poses' relative pose.
    chi2: Vec<f64>,
    /// Their sum.
    total: f64,
    /// The links' redundancy ([`link_redundancy`]).
    redundancy: usize,
    /// σ̂₀² = total / redundancy; 1 without redundancy.
    variance_factor: f64,
}

fn judged(poses: &[Isometry3<f64>], links: &[Edge]) -> Judged {
    let chi2: Vec<f64> = links
        .iter()
        .map(|e| {
            let predicted = poses[e.target].inverse() * poses[e.source];
            let d = left_difference(&predicted, &e.target_from_source);
            (d.transpose() * e.information * d)[(0, 0)]
        })
        .collect();
    let total: f64 = chi2.iter().sum();
    let redundancy = link_redundancy(poses.len(), links.iter().map(|e| (e.target, e.source)));
    let variance_factor = if redundancy > 0 { total / redundancy as f64 } else { 1.0 };
    Judged { chi2, total, redundancy, variance_factor }
}

/// The redundancy of links between `n` scans (`pairs`: each link's two
/// scans): 6 per link less 6 per scan they place — all but one scan of
/// each set of scans the links join. The start's steps, which hold only
/// what no link sees, are no part of it: counted as observations (6 per
/// step, with χ² near 0: a step's σ is far wider than the poses move) they
/// made the variance factor of a triangle of links a third of their χ²
/// per degree of freedom, and of a chain with no cycle a small number
/// where there is nothing to judge.
fn link_redundancy(n: usize, pairs: impl Iterator<Item = (usize, usize)>) -> usize {
    let mut part: Vec<usize> = (0..n).collect();
    fn root(part: &mut [usize], mut i: usize) -> usize {
        while part[i] != i {
            part[i] = part[part[i]];
            i = part[i];
        }
        i
    }
    let (mut links, mut placed) = (0, 0);
    for (a, b) in pairs {
        links += 1;
        let (ra, rb) = (root(&mut part, a), root(&mut part, b));
        if ra != rb {
            part[ra] = rb;
            placed += 1;
        }
    }
    6 * (links - placed)
}

/// Adjusts the accepted links, leaving out outliers one at a time.
fn solve(
    poses: &[Isometry3<f64>],
    starts: &[Isometry3<f64>],
    mut links: Vec<Link>,
    shape: &[(Point3<f64>, f64)],
    shared: &[f64],
    config: &LinkConfig,
) -> Result<LinkGraph> {
    let n = poses.len();
    let (priors, steps) = frame_and_steps(poses, starts, config);
    loop {
        let used: Vec<usize> = (0..links.len()).filter(|&k| links[k].rejected.is_none()).collect();
        let mut edges = steps.clone();
        edges.extend(used.iter().map(|&k| {
            let r = links[k].result.as_ref().expect("an accepted link has its match");
            Edge {
                target: links[k].target,
                source: links[k].source,
                target_from_source: r.target_from_source,
                information: r.information,
            }
        }));
        let g = crate::graph::optimize(poses, &priors, &edges, 20)?;
        let Judged { chi2, total, redundancy, variance_factor } = judged(&g.world_from_scan, &edges[steps.len()..]);
        // Each scan's used links: one that is its scan's only link is never
        // left out.
        let mut degree = vec![0usize; n];
        for &k in &used {
            degree[links[k].target] += 1;
            degree[links[k].source] += 1;
        }
        // The links beyond the gate, the worst first, each judged by the
        // variance factor of the rest.
        let mut beyond: Vec<(usize, f64)> = used
            .iter()
            .zip(&chi2)
            .filter(|(k, _)| degree[links[**k].target] > 1 && degree[links[**k].source] > 1)
            .map(|(&k, &c)| (k, c))
            .collect();
        beyond.sort_by(|a, b| b.1.total_cmp(&a.1));
        // A cycle named on a kept link is this solution's.
        for &k in &used {
            links[k].cycle = None;
        }
        let mut left_out = false;
        // Without a cycle there is nothing to judge; with one alone, only
        // a gross miss (below).
        if redundancy < 6 {
            beyond.clear();
        }
        // The scan pairs along the cycles kept links have named: a link in
        // series on one of them misses by that same cycle, named once.
        let mut named: Vec<[usize; 2]> = Vec::new();
        let pair = |a: usize, b: usize| [a.min(b), a.max(b)];
        for (k, c) in beyond {
            let rest = if redundancy > 6 { ((total - c) / (redundancy - 6) as f64).max(1.0) } else { 1.0 };
            if c / rest <= config.gate_chi2 {
                break;
            }
            let (target, source) = (links[k].target, links[k].source);
            let told = identifiable(&links, &used, k);
            if !told && named.contains(&pair(target, source)) {
                continue;
            }
            // Which link of a cycle is wrong only other cycles can tell: a
            // link in series with another (every cycle through one runs
            // through the other: a triangle's, a ring's) is left out only
            // when its cycle misses grossly — then the set is wrong
            // somewhere and the verification names where. A statistical
            // miss there is the links' common error, which the variance
            // factor carries (the 3DTK triangle's long link, 22.9 > 22.5,
            // left out moved the other two 0.4°): it is kept, its cycle
            // named, and the next link beyond the gate is judged.
            let found = cycle(&links, &used, k, &shape[source].0);
            let gross = found
                .as_ref()
                .is_some_and(|f| f.angle_rad > MAX_TURN_RAD || f.translation_m > MAX_RELATIVE_MOTION * shape[source].1);
            if let Some(f) = &found {
                named.extend(f.scans.windows(2).map(|w| pair(w[0], w[1])));
                named.push(pair(target, source));
            }
            links[k].cycle = found;
            if gross || told {
                links[k].rejected = Some(format!(
                    "disagrees with the other links (χ² = {:.1} > {:.1} after the variance factor {rest:.3})",
                    c / rest,
                    config.gate_chi2
                ));
                left_out = true;
                break;
            }
        }
        if left_out {
            continue;
        }
        // Each scan's information from its links, in its own frame, analysed
        // about its points' centroid (frame-free) — only when blind
        // directions are asked for, and never for scan 0, which holds the
        // frame.
        let unobservable = match config.multiview.icp.degeneracy_ratio {
            None => vec![Vec::new(); n],
            Some(ratio) => (0..n)
                .map(|i| {
                    if i == 0 {
                        return Vec::new();
                    }
                    let t = &g.world_from_scan[i];
                    let mut h = Matrix6::zeros();
                    for &k in &used {
                        let l = &links[k];
                        if l.target == i || l.source == i {
                            let j = adjoint(&g.world_from_scan[l.target].inverse()) * adjoint(t);
                            h += j.transpose() * links[k].result.as_ref().expect("accepted").information * j;
                        }
                    }
                    let to_world = adjoint(t);
                    Observability::about(&h, &shape[i].0, shape[i].1, ratio)
                        .unobservable()
                        .into_iter()
                        .map(|d| (to_world * d).normalize())
                        .collect()
                })
                .collect(),
        };
        // Each link's covariance: its covariance by pair, calibrated, times
        // σ̂₀², and its edge's pull or lean ([`adjusted_covariance`]).
        let (noise, pulls): (Vec<Matrix6<f64>>, Vec<Pull>) = used
            .iter()
            .map(|&k| {
                let r = links[k].result.as_ref().expect("an accepted link has its match");
                (link_noise(r, config), Pull::of(r, config))
            })
            .unzip();
        let lean_variance_factor = lean_factor(&g.world_from_scan, &priors, &edges, steps.len(), &pulls)?;
        let Spread { joint, sampling, pairs_rest, noise_factor } = adjusted_covariance(
            &g.world_from_scan,
            &priors,
            &edges,
            steps.len(),
            &noise,
            &pulls,
            &Agreement::of(variance_factor, lean_variance_factor, redundancy, shared, config),
        )?;
        // Scan 0's prior leaves it within 1e-20 m of its pose: put it there.
        let shift = poses[0] * g.world_from_scan[0].inverse();
        return Ok(LinkGraph {
            world_from_scan: g.world_from_scan.iter().map(|p| shift * p).collect(),
            covariance: joint.diagonal(),
            joint_covariance: joint,
            sampling,
            pairs_rest,
            links,
            unobservable,
            variance_factor,
            lean_variance_factor,
            redundancy,
            noise_factor,
        });
    }
}

/// The covariances of `poses` adjusted to `edges` (the start's `steps`
/// first, then the links) with `priors`, as the adjustment weighs the
/// links by their information (the poses stay the links' own):
/// - each link's noise: `noise` (its match's covariance by pair, each
///   pair's variance its own squared residual,
///   [`crate::icp::IcpResult::range_covariance`] — far points and some
///   surfaces are noisier, which one variance for all pairs hides — calibrated on the
///   scans' halves and quarters, `LinkConfig::range_scale`; or, without
///   it, its information's inverse: [`link_noise`]) times σ̂₀²
///   (`variance_factor`): above 1 the links disagree more than their
///   noise says; below 1 they agree better, and the share of their noise
///   that is each scan's own, in every one of its links, closes the
///   cycles ([`shared_own`]) — as far as its links use the same part of
///   it (`shared`); the rest stays the pair's ([`pair_share`]). (σ̂₀² is
///   exactly 1 without redundancy.)
///   The start's steps, which hold only what no link sees, are taken as
///   they are weighed.
/// - its edge's pull (`pulls`, [`Pull`]): a bias that its residuals do not
///   show, nor — where the pulls close the cycles — σ̂₀²; each link's an
///   independent error. Where the links each corrected by their lean
///   ([`LEAN_SHORTFALL`] × [`Pull::lean`]) agree better than as measured
///   (`lean_variance_factor` below σ̂₀²) and the links as measured fail
///   their global test ([`beyond_global_test`]), the lean is what they
///   miss by — where they pass it, their noise explains their misfit, and
///   a lean taken for it had the street's wedges 1.4× pessimistic
///   (BENCHMARKS.md, session 66):
///   each link's bias is that, and the factor on the noise the corrected
///   links' σ̂₀² (not below min(1, σ̂₀²): below 1 as measured, the rest
///   of the noise stays the scans' own); otherwise the pull by the pairs
///   beyond the edge alone ([`Pull::bias`]), and σ̂₀².
fn adjusted_covariance(
    poses: &[Isometry3<f64>],
    priors: &[Option<Prior>],
    edges: &[Edge],
    steps: usize,
    noise: &[Matrix6<f64>],
    pulls: &[Pull],
    agreement: &Agreement,
) -> Result<Spread> {
    let (variance_factor, shared) = (agreement.variance_factor, agreement.shared);
    let (variance_factor, bias): (f64, Vec<Vector6<f64>>) = match agreement.lean_variance_factor {
        Some(lean) if lean < variance_factor && beyond_global_test(variance_factor, agreement.redundancy) => {
            (lean.max(variance_factor.min(1.0)), pulls.iter().map(|p| LEAN_SHORTFALL * p.lean).collect())
        }
        _ => (variance_factor, pulls.iter().map(|p| p.bias).collect()),
    };
    let f = noise_factor(pooled_factor(variance_factor, agreement.redundancy, agreement.calibration_dof));
    let overlap = |k: usize| shared.get(k).copied().unwrap_or(1.0);
    let shares: Vec<f64> = edges[steps..].iter().map(|e| pair_share(f, overlap(e.source), overlap(e.target))).collect();
    let at = |share: &dyn Fn(usize) -> f64| {
        let mut covariances = vec![None; steps];
        covariances
            .extend(noise.iter().zip(&bias).enumerate().map(|(i, (c, d))| Some(c * share(i) + d * d.transpose())));
        crate::graph::sandwich_joint(poses, priors, edges, &covariances)
    };
    let covariance = at(&|i| shares[i])?;
    // What the pairs' rest adds: left out where a pose is judged.
    let pairs_rest = if shares.iter().any(|&s| s != f) { Some(covariance.less(&at(&|_| f)?)) } else { None };
    let links = &edges[steps..];
    let n = poses.len();
    let mut own = if f < 1.0 { shared_own(poses, links, noise, f, shared) } else { vec![Matrix6::zeros(); n] };
    // What the scans' sampling adds beyond the shared noise, each scan's.
    let mut sampled = vec![Matrix6::zeros(); n];
    if let Some(floor) = agreement.asymmetry {
        for ((s, m), added) in own.iter_mut().zip(sampling_own(poses, links, noise, pulls, floor)).zip(&mut sampled) {
            *added = positive_part(&(m - *s));
            *s += *added;
        }
    }
    // Its share of each pose's covariance: the scan's own and the first's.
    let sampling = (0..n).map(|k| if k == 0 { Matrix6::zeros() } else { sampled[k] + sampled[0] }).collect();
    // Scan 0 is the frame: the others' covariances are relative to it.
    let held = |mut c: JointCovariance| {
        c.hold(0);
        c
    };
    Ok(Spread { joint: held(with_own(covariance, &own)), sampling, pairs_rest: pairs_rest.map(held), noise_factor: f })
}

/// Pose `i`'s `covariance` as a judgement of the pose takes it: less its
/// share of the scans' own sampling and of the pairs' rest (where given).
pub(crate) fn judged_covariance(
    covariance: &Matrix6<f64>,
    sampling: &[Matrix6<f64>],
    pairs_rest: Option<&JointCovariance>,
    i: usize,
) -> Matrix6<f64> {
    let rest = pairs_rest.filter(|rest| i < rest.len()).map_or_else(Matrix6::zeros, |rest| rest.block(i, i));
    covariance - sampling.get(i).copied().unwrap_or_else(Matrix6::zeros) - rest
}

/// What [`adjusted_covariance`] returns, relative to scan 0 (its rows
/// and columns zero).
struct Spread {
    /// The poses' joint covariance.
    joint: JointCovariance,
    /// Each pose's share of it that is the scans' own sampling.
    sampling: Vec<Matrix6<f64>>,
    /// The share of it that is the pairs' rest ([`pair_share`]): `None`
    /// where every link's share is the factor.
    pairs_rest: Option<JointCovariance>,
    /// The factor on the links' noise.
    noise_factor: f64,
}

/// How far a link's error runs along its edge's lean
/// ([`crate::icp::IcpResult::edge_lean`]), in lean lengths: on a real
/// room's wedges (four 150° wedges, a ring of links) each link's error lay
/// along its pull by the pairs beyond the edge, 2–2.5× its length (cos
/// 0.975); the lean, 1.55× the pull at the median, takes most of that.
/// Of 1.25, 1.5 and 2, the NEES bench (graph mode) judged 1.25 best on
/// seeds 7 and 13, and it held on 11, 17 and 23 (BENCHMARKS.md, "The
/// edge's lean").
pub const LEAN_SHORTFALL: f64 = 1.25;

/// How the other scan's sampled edge pulls a match (target frame, ξ =
/// (ω, v), left).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pull {
    /// By the pairs beyond the edge ([`crate::icp::IcpResult::edge_bias`]).
    pub bias: Vector6<f64>,
    /// By those and the covered pairs nearest the edge
    /// ([`crate::icp::IcpResult::edge_lean`]).
    pub lean: Vector6<f64>,
    /// Its two ways' disagreement ([`crate::icp::IcpResult::asymmetry`]).
    pub asymmetry: Vector6<f64>,
}

impl Pull {
    /// A match's, its bias and lean each as far as it is more than the
    /// match's pairs' noise ([`beyond_noise`], that noise judged by the
    /// covariance by pair calibrated: `config.range_scale`).
    pub fn of(r: &IcpResult, config: &LinkConfig) -> Self {
        let dof = 6 - r.unobservable.len().min(6);
        Self {
            bias: beyond_noise(&r.edge_bias, r.edge_bias_chi2, dof, config.range_scale),
            lean: beyond_noise(&r.edge_lean, r.edge_lean_chi2, dof, config.range_scale),
            asymmetry: r.asymmetry,
        }
    }
}

/// An edge's pull δ (`pull`: [`crate::icp::IcpResult::edge_bias`] or
/// `edge_lean`) as far as it is more than its pairs' noise: δ·√(1 −
/// k/χ²)⁺, χ² its square against what that noise alone would scatter it
/// by (`chi2`, from the covariance by pair's model, which the data's
/// calibration scales by `scale`: χ²/`scale`) on `dof` k degrees of
/// freedom. A covariance takes δ's square as the pull's, but δ is
/// measured with the pairs' noise, δδᵀ averaging ββᵀ + V for a pull β:
/// its square beyond the noise, χ² − k against a mean χ² of k + βᵀV⁺β, is
/// what the pull adds (a positive-part estimate, as `sampling_own`'s). On a
/// street's LiDAR wedges half the pulls were much of them noise (χ²
/// 7–11 against 6) and the links' covariances 1.23× pessimistic (now
/// 1.10×); a real room's wedges, whose edges lean by more (χ² 20–110),
/// keep nearly all (BENCHMARKS.md, "The edge's pull beyond its noise").
pub fn beyond_noise(pull: &Vector6<f64>, chi2: f64, dof: usize, scale: f64) -> Vector6<f64> {
    let chi2 = chi2 / scale;
    if !(chi2.is_finite() && chi2 > 0.0) || dof == 0 {
        return *pull;
    }
    pull * (1.0 - dof as f64 / chi2).max(0.0).sqrt()
}

/// σ̂₀² of the links (`edges` after the start's `steps`) each corrected by
/// its lean — its measurement moved by exp([`LEAN_SHORTFALL`] ·
/// [`Pull::lean`]), where the covered fit would take it — and adjusted
/// again from `poses` with `priors`; `None` without redundancy, or without
/// a lean (no pair beyond an edge: nothing to correct).
fn lean_factor(
    poses: &[Isometry3<f64>],
    priors: &[Option<Prior>],
    edges: &[Edge],
    steps: usize,
    pulls: &[Pull],
) -> Result<Option<f64>> {
    if pulls.iter().all(|p| p.lean == Vector6::zeros()) {
        return Ok(None);
    }
    let mut corrected = edges.to_vec();
    for (e, p) in corrected[steps..].iter_mut().zip(pulls) {
        e.target_from_source = crate::se3::exp(&(LEAN_SHORTFALL * p.lean)) * e.target_from_source;
    }
    let g = crate::graph::optimize(poses, priors, &corrected, 20)?;
    let j = judged(&g.world_from_scan, &corrected[steps..]);
    Ok((j.redundancy > 0).then_some(j.variance_factor))
}

/// What the links' agreement says of their noise ([`adjusted_covariance`]).
struct Agreement<'a> {
    /// σ̂₀².
    variance_factor: f64,
    /// σ̂₀² of the links corrected by their lean ([`lean_factor`]).
    lean_variance_factor: Option<f64>,
    /// The degrees of freedom both rest on (the links' redundancy).
    redundancy: usize,
    /// [`LinkConfig::calibration_dof`].
    calibration_dof: usize,
    /// Each scan's links' footprint overlap ([`shared_shares`]); empty: 1
    /// for every scan.
    shared: &'a [f64],
    /// [`LinkConfig::asymmetry`].
    asymmetry: Option<f64>,
}

impl<'a> Agreement<'a> {
    /// The links' σ̂₀² (and the lean's) on their `redundancy`, with
    /// `config`'s calibration and each scan's `shared` footprint overlap.
    fn of(
        variance_factor: f64,
        lean_variance_factor: Option<f64>,
        redundancy: usize,
        shared: &'a [f64],
        config: &LinkConfig,
    ) -> Self {
        Self {
            variance_factor,
            lean_variance_factor,
            redundancy,
            calibration_dof: config.calibration_dof,
            shared,
            asymmetry: config.asymmetry,
        }
    }
}

/// The least share of the links' noise taken as independent ([`shared_own`]).
const MIN_INDEPENDENT_SHARE: f64 = 0.05;

/// A match's noise as the link graph takes it, before the variance
/// factor: its covariance by pair (`range_covariance`) times the
/// calibration's `range_scale`, its rotation and translation about the
/// source's centroid each times its own factor (`range_blocks`); or
/// without it its `information`'s inverse (nothing along what it cannot
/// see). Its frame is the match's.
pub(crate) fn link_noise(r: &crate::icp::IcpResult, config: &LinkConfig) -> Matrix6<f64> {
    r.range_covariance.map_or_else(
        || r.information.pseudo_inverse(1e-12 * r.information.amax()).unwrap_or_else(|_| Matrix6::zeros()),
        |c| range_noise(&c, r, config),
    )
}

/// A match's covariance by pair `c` as calibrated ([`link_noise`]). A
/// match with blind directions takes `range_scale` alone: its covariance
/// is empty along them, and the blocks' factors would turn that empty
/// direction (the calibration's blocks come from halvings without
/// blind directions).
pub(crate) fn range_noise(c: &Matrix6<f64>, r: &crate::icp::IcpResult, config: &LinkConfig) -> Matrix6<f64> {
    let (rotation, translation) = config.range_blocks;
    if r.unobservable.is_empty() && (rotation, translation) != (1.0, 1.0) {
        crate::noise::by_blocks(c, &r.source_centroid, rotation, translation) * config.range_scale
    } else {
        c * config.range_scale
    }
}

/// The factor on the links' noise for a variance factor σ̂₀²: σ̂₀² itself,
/// but never below [`MIN_INDEPENDENT_SHARE`] (below 1 the rest is the
/// scans' own, [`shared_own`]), and exactly 1 without redundancy.
fn noise_factor(variance_factor: f64) -> f64 {
    if variance_factor == 1.0 { 1.0 } else { variance_factor.max(MIN_INDEPENDENT_SHARE) }
}

/// The share of a link's noise that is its pair's, for the factor `f` on
/// the links' noise ([`noise_factor`]) and its two scans' footprint
/// overlaps ([`shared_shares`]): above 1, `f`; below 1, the links agree
/// better than their noise says, and the rest, 1 − f, is the scans' own
/// ([`shared_own`]) as far as each scan's links use the same part of it,
/// half each — what no scan shares stays the pair's: f + (1 − f)·(1 −
/// (s₁ + s₂)/2). Random shares of one scan (s = 1) keep f; wedges, whose
/// links each use another part of a scan (s ≈ 0), keep their noise whole
/// — a ring's σ̂₀² below 1 is its chance on 6 degrees of freedom, not a
/// noise their scans share (taken as f, the street's wedges below 1 were
/// 1.5–3× optimistic; BENCHMARKS.md, session 65).
fn pair_share(f: f64, source_overlap: f64, target_overlap: f64) -> f64 {
    if f < 1.0 { f + (1.0 - f) * (1.0 - 0.5 * (source_overlap + target_overlap)) } else { f }
}

/// The links' global test ([`pooled_factor`]): χ² = ν·σ̂₀² against the
/// upper 1 − α/2 point of χ²_ν, α = 0.05 as the network adjustment's
/// (`cps::batch`).
pub const GLOBAL_TEST_LEVEL: f64 = 0.975;

/// The factor on the links' noise where they disagree more than it says
/// (`variance_factor` σ̂₀² above 1, on `redundancy` ν degrees of
/// freedom). The calibration measured the same scale as 1 on ν₀ =
/// `calibration_dof` degrees of freedom (its shares matched where the
/// truth is known). Where the links pass their global test — χ² = ν·σ̂₀²
/// within the upper [`GLOBAL_TEST_LEVEL`] point of χ²_ν, as a network
/// adjustment's a priori σ₀ stands when its global test passes — the two
/// estimates are of one scale and are pooled by their degrees of freedom,
/// (ν₀ + ν·σ̂₀²) / (ν₀ + ν); beyond it the links disagree by more than
/// the calibrated noise can, and σ̂₀² is taken whole (the 3DTK set's
/// triangle, 2.1° apart: 306). A linear adjustment's residuals say
/// nothing of its estimate's error beyond the links' scale, and one
/// ring of four scans has ν = 6: its σ̂₀² scatters by a factor of 8
/// (χ²₆/6 from 0.27 to 2.1 at 90 %), and taken whole above 1 — below 1
/// the rest of the noise is the scans' own, shared by their links, and
/// the scale stays — it widened every direction by its chance (real rooms'
/// wedges 1.2× pessimistic, their tilt and height 1.75×; BENCHMARKS.md,
/// session 64). Many links outweigh the calibration (the simulated
/// hall's ν 738). At or below 1, or without a calibration, σ̂₀² as it is.
pub fn pooled_factor(variance_factor: f64, redundancy: usize, calibration_dof: usize) -> f64 {
    if variance_factor <= 1.0 || calibration_dof == 0 || redundancy == 0 {
        return variance_factor;
    }
    if beyond_global_test(variance_factor, redundancy) {
        return variance_factor;
    }
    let (nu0, nu) = (calibration_dof as f64, redundancy as f64);
    (nu0 + nu * variance_factor) / (nu0 + nu)
}

/// Whether links whose σ̂₀² is `variance_factor` on `redundancy` ν
/// degrees of freedom fail their global test: χ² = ν·σ̂₀² beyond the upper
/// [`GLOBAL_TEST_LEVEL`] point of χ²_ν (never without redundancy).
fn beyond_global_test(variance_factor: f64, redundancy: usize) -> bool {
    let nu = redundancy as f64;
    redundancy > 0 && nu * variance_factor > cps::stats::chi2_quantile(GLOBAL_TEST_LEVEL, nu)
}

/// Each scan's own share of the noise of a graph whose links agree
/// better than their covariances say (σ̂₀² = `independent_share` < 1),
/// world axes, for [`with_own`]. A link's error is
/// partly each of its two scans' own — a scan's noise and sampling move
/// it the same way against every partner (on random shares of one real
/// scan, almost wholly so) — and partly the pair's. The graph takes its
/// links as independent, so the scans' shares close every cycle and only
/// the pairs' show in σ̂₀²: of each link's covariance C, the share σ̂₀² is
/// the pair's and 1 − σ̂₀² the scans', half each. `noise` is each link's
/// C; the graph's covariance takes the links' C times σ̂₀² (the pairs'
/// share, which the adjustment averages down); a scan's own share S_k —
/// the mean over its links of ½(1 − σ̂₀²)·C, in world axes — passes
/// through it whole ([`with_own`]). Four parts of one scan, all
/// linked, were up to 2× optimistic without it (BENCHMARKS.md). S_k is
/// weighed by `shared[k]` (1 where missing): how far scan k's links use
/// the same part of it ([`shared_shares`]) — wedges' links use each
/// another part, and their whole S_k made them 2.35× pessimistic; what
/// it leaves is the pairs' ([`pair_share`]).
fn shared_own(
    poses: &[Isometry3<f64>],
    links: &[Edge],
    noise: &[Matrix6<f64>],
    independent_share: f64,
    shared: &[f64],
) -> Vec<Matrix6<f64>> {
    let n = poses.len();
    let mut own = vec![Matrix6::zeros(); n];
    let mut count = vec![0usize; n];
    for (e, covariance) in links.iter().zip(noise) {
        // The link's covariance (nothing along what it cannot see), its ξ
        // in the target's frame carried to the world's axes.
        let a = adjoint(&poses[e.target]);
        let c = a * covariance * a.transpose() * (0.5 * (1.0 - independent_share));
        for k in [e.source, e.target] {
            own[k] += c;
            count[k] += 1;
        }
    }
    for (k, (s, &c)) in own.iter_mut().zip(&count).enumerate() {
        *s *= shared.get(k).copied().unwrap_or(1.0) / c.max(1) as f64;
    }
    own
}

/// Each scan's own error `own` (world axes) added to the poses' joint
/// covariance, which took the links as independent: it passes through
/// the adjustment whole, as does the first scan's, against which every
/// pose is — P_k += S_k + S_0, P_kl += S_0.
fn with_own(mut covariance: JointCovariance, own: &[Matrix6<f64>]) -> JointCovariance {
    for k in 1..own.len() {
        covariance.add(k, k, &own[k]);
        for l in 1..=k {
            covariance.add(k, l, &own[0]);
        }
    }
    covariance
}

/// The share of [`sampling_own`]'s estimate that is each scan's own: all
/// of it. Were the two ways' biases independent, half of ΔΔᵀ would be
/// each scan's; they are not — four of five of the hall's pairs erred the
/// same way both ways, which Δ does not show —, and half left the hall's
/// NEES at 25–41 against 23–32 (an earlier estimate; BENCHMARKS.md, "The
/// two ways' disagreement").
const SAMPLING_SHARE: f64 = 1.0;

/// The level of [`sampling_own`]'s test: a scan's links disagree with
/// themselves beyond their noise at 99 %.
const SAMPLING_LEVEL: f64 = 0.99;

/// Each scan's own sampling error, which its links lean on alike. Each
/// way of a match leans on one scan's sampled surfaces (its normals, its
/// nearest samples); a scan sampled sparsely or at grazing angles — a
/// wall 30 m along it, seen from another station — bends them alike in
/// every one of its links, a bias that no cycle shows (σ̂₀² 1.3–1.5 on a
/// simulated hall's 165 links, its 22 scans 3.6 m apart NEES 75–130 for
/// it). The match's two ways disagree by it: each link's asymmetry Δ
/// ([`Pull::asymmetry`]) is its scans' sampling plus their noise, and the
/// noise's part is what one scan's halves, which share their sampling,
/// make of Δ — E[ΔᵀC⁻¹Δ] = `floor` ([`LinkConfig::asymmetry`]) for a
/// link whose covariance by pair is C (`noise`). A scan whose links' Σ
/// ΔᵀC⁻¹Δ = χ² stays within that noise (χ²·6/`floor` below the χ²
/// distribution's [`SAMPLING_LEVEL`] quantile for 6 per link) has none;
/// beyond it, its own error is the mean over its links of ΔΔᵀ (world
/// axes), less the noise's share (× (1 − `floor`·links/χ²)), times
/// [`SAMPLING_SHARE`]. (Tested so, not estimated from every scan: the
/// positive part of a noisy estimate of nothing is not nothing, and one
/// real scan's parts, which share their viewpoint, came out 1.3×
/// pessimistic.)
fn sampling_own(
    poses: &[Isometry3<f64>],
    links: &[Edge],
    noise: &[Matrix6<f64>],
    pulls: &[Pull],
    floor: f64,
) -> Vec<Matrix6<f64>> {
    let n = poses.len();
    let mut own = vec![Matrix6::zeros(); n];
    if !(floor > 0.0 && floor.is_finite()) {
        return own;
    }
    let mut chi2 = vec![0.0; n];
    let mut count = vec![0usize; n];
    for ((e, c), p) in links.iter().zip(noise).zip(pulls) {
        let d = p.asymmetry;
        let x = (d.transpose() * crate::icp::solve::pseudo_inverse(c) * d)[0];
        if !x.is_finite() {
            continue;
        }
        let a = adjoint(&poses[e.target]) * d;
        for k in [e.source, e.target] {
            own[k] += a * a.transpose();
            chi2[k] += x;
            count[k] += 1;
        }
    }
    for ((s, &x), &m) in own.iter_mut().zip(&chi2).zip(&count) {
        let expected = floor * m as f64;
        let beyond = m > 0 && x * 6.0 / floor > cps::stats::chi2_quantile(SAMPLING_LEVEL, 6.0 * m as f64);
        *s = if beyond { *s * (SAMPLING_SHARE * (1.0 - expected / x) / m as f64) } else { Matrix6::zeros() };
    }
    own
}

/// A symmetric 6×6 with its negative eigenvalues set to zero.
fn positive_part(m: &Matrix6<f64>) -> Matrix6<f64> {
    let e = (0.5 * (m + m.transpose())).symmetric_eigen();
    let values = e.eigenvalues.map(|v| v.max(0.0));
    e.eigenvectors * Matrix6::from_diagonal(&values) * e.eigenvectors.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Monte Carlo: a pull δ = β + noise (covariance V) kept beyond its
    /// noise ([`beyond_noise`]) keeps, on average, β's square: its χ² (δ
    /// kept, against V) averages βᵀV⁻¹β = 100 within 2 %; of a pull of
    /// noise alone (β = 0) what is kept averages E[(χ²₆ − 6)⁺] =
    /// 6·(P(χ²₈ > 6) − P(χ²₆ > 6)) = 1.34 against the 6 the whole δ has.
    /// A calibration's scale on V divides χ² by it.
    #[test]
    fn a_pull_beyond_its_noise_keeps_the_pulls_square() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let a: Matrix6<f64> = Matrix6::from_fn(|_, _| StandardNormal.sample(&mut rng));
        let v = a * a.transpose() + Matrix6::identity() * 0.5;
        let (l, inverse) = (v.cholesky().expect("positive definite").l(), v.try_inverse().expect("invertible"));
        let chi2 = |d: &Vector6<f64>| (d.transpose() * inverse * d)[0];
        let u = Vector6::new(0.3, -1.0, 0.4, 0.8, 0.1, -0.6);
        let beta = u * (100.0 / chi2(&u)).sqrt();
        let kept_mean = |beta: &Vector6<f64>, rng: &mut rand_chacha::ChaCha8Rng| {
            let n = 20_000;
            (0..n)
                .map(|_| {
                    let z = Vector6::from_fn(|_, _| StandardNormal.sample(&mut *rng));
                    let d = beta + l * z;
                    chi2(&beyond_noise(&d, chi2(&d), 6, 1.0))
                })
                .sum::<f64>()
                / n as f64
        };
        let pulled = kept_mean(&beta, &mut rng);
        assert!((pulled / 100.0 - 1.0).abs() < 0.02, "a pull of χ² 100 keeps {pulled}");
        let expected = 6.0 * ((1.0 - cps::stats::chi2_cdf(6.0, 8.0)) - (1.0 - cps::stats::chi2_cdf(6.0, 6.0)));
        assert!((expected - 1.344).abs() < 1e-3, "E[(χ²₆ − 6)⁺] {expected}");
        let noise = kept_mean(&Vector6::zeros(), &mut rng);
        assert!((noise - expected).abs() < 0.06, "noise alone keeps {noise}, expected {expected}");
        // A scale on V: χ² against the scaled V is χ²/scale.
        let d = beta * 0.3;
        let scaled = beyond_noise(&d, chi2(&d), 6, 2.0);
        assert!((scaled - beyond_noise(&d, chi2(&d) / 2.0, 6, 1.0)).norm() < 1e-15);
        assert!(scaled.norm() < beyond_noise(&d, chi2(&d), 6, 1.0).norm());
        // No measure of its noise: the pull whole; none at all: nothing.
        assert_eq!(beyond_noise(&d, f64::INFINITY, 6, 1.0), d);
        assert_eq!(beyond_noise(&Vector6::zeros(), 0.0, 6, 1.0), Vector6::zeros());
    }

    /// Monte Carlo: four scans apart and turned, far from the origin, each
    /// placed on the one before by its start's step with an error of the
    /// step's σ (2 mrad, 3 cm) in the frame of the scan before: their
    /// scatter in the world (ξ, left) is what [`steps_covariance`] says —
    /// each step's turn swings every later scan about the earlier one's
    /// origin.
    #[test]
    fn the_starts_steps_covariance_is_what_monte_carlo_scatters() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let pose = |x: f64, y: f64, yaw: f64| {
            Isometry3::from_parts(
                nalgebra::Translation3::new(500.0 + x, 300.0 + y, 0.2 * x),
                nalgebra::UnitQuaternion::from_euler_angles(0.02, -0.01, yaw),
            )
        };
        let poses = [pose(0.0, 0.0, 0.0), pose(6.0, 1.0, 0.4), pose(9.0, 7.0, 1.2), pose(2.0, 11.0, 2.0)];
        let config = LinkConfig { step_sigma_rad: 2e-3, step_sigma_m: 0.03, ..LinkConfig::default() };
        let predicted = steps_covariance(&poses, &config);
        assert_eq!(predicted[0], Matrix6::zeros());
        let sigma = Vector6::new(2e-3, 2e-3, 2e-3, 0.03, 0.03, 0.03);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(50);
        let draws = 6000;
        let mut scatter = vec![Matrix6::zeros(); poses.len()];
        for _ in 0..draws {
            let mut placed = poses[0];
            for i in 1..poses.len() {
                let e = Vector6::from_fn(|k, _| sigma[k] * Distribution::<f64>::sample(&StandardNormal, &mut rng));
                placed = placed * crate::se3::exp(&e) * (poses[i - 1].inverse() * poses[i]);
                let xi = crate::se3::left_difference(&placed, &poses[i]);
                scatter[i] += xi * xi.transpose() / draws as f64;
            }
        }
        for i in 1..poses.len() {
            let p = &predicted[i];
            for k in 0..6 {
                // (Monte Carlo's own error on a variance: √(2/6000) ≈ 2 %.)
                let r = scatter[i][(k, k)] / p[(k, k)];
                assert!((r - 1.0).abs() < 0.08, "scan {i}, ξ[{k}]: scatter/predicted = {r}");
            }
            assert!((scatter[i] - p).norm() < 0.08 * p.norm(), "scan {i}: {} vs {}", scatter[i], p);
        }
    }

    /// Monte Carlo: four scans all linked, each link's error the two
    /// scans' own shifts (σ 1 mrad / 1 mm each, the same in all of a
    /// scan's links) plus the pair's own (σ 0.5): the graph that takes the
    /// links as independent is 2× optimistic, the covariance with the
    /// scans' shared noise what 4,000 draws scatter — each pose's, and
    /// what any two share (scan 0's own noise moves them all alike).
    #[test]
    fn the_scans_shared_noise_is_what_monte_carlo_scatters() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(30);
        let (own, pair) = (Normal::new(0.0, 1e-3).expect("σ"), Normal::new(0.0, 0.5e-3).expect("σ"));
        let n = 4;
        let pairs: Vec<(usize, usize)> = (0..n).flat_map(|j| (j + 1..n).map(move |i| (j, i))).collect();
        // A link's covariance: two shifts and the pair's, per component.
        let information = Matrix6::identity() / (2.0 * 1e-6 + 0.25e-6);
        let poses = vec![Isometry3::identity(); n];
        let mut priors = vec![None; n];
        priors[0] = Some(Prior { target_from_source: Isometry3::identity(), information: Matrix6::identity() * 1e12 });
        let draws = 4000;
        let mut scatter = vec![vec![Matrix6::zeros(); n]; n];
        let mut factor = 0.0;
        for _ in 0..draws {
            let shift: Vec<Vector6<f64>> = (0..n).map(|_| Vector6::from_fn(|_, _| own.sample(&mut rng))).collect();
            let edges: Vec<Edge> = pairs
                .iter()
                .map(|&(target, source)| {
                    let e = shift[source] - shift[target] + Vector6::from_fn(|_, _| pair.sample(&mut rng));
                    Edge { target, source, target_from_source: crate::se3::exp(&e), information }
                })
                .collect();
            let g = crate::graph::optimize(&poses, &priors, &edges, 20).expect("adjusts");
            factor += judged(&g.world_from_scan, &edges).variance_factor / draws as f64;
            let xi: Vec<Vector6<f64>> =
                g.world_from_scan.iter().map(|pose| left_difference(pose, &Isometry3::identity())).collect();
            for k in 1..n {
                for l in 1..n {
                    scatter[k][l] += xi[k] * xi[l].transpose() / draws as f64;
                }
            }
        }
        // The pairs' share of a link's variance: 0.25 of 2.25.
        assert!((factor - 0.25 / 2.25).abs() < 0.01, "σ̂₀² {factor}");
        let edges: Vec<Edge> = pairs
            .iter()
            .map(|&(target, source)| Edge { target, source, target_from_source: Isometry3::identity(), information })
            .collect();
        let plain = crate::graph::optimize(&poses, &priors, &edges, 1).expect("adjusts").covariance;
        let noise = vec![information.try_inverse().expect("invertible"); edges.len()];
        let scaled: Vec<Option<Matrix6<f64>>> = noise.iter().map(|c| Some(c * factor)).collect();
        let independent = crate::graph::sandwich_joint(&poses, &priors, &edges, &scaled).expect("adjusts");
        let shared = with_own(independent, &shared_own(&poses, &edges, &noise, factor, &[]));
        for k in 1..n {
            for d in 0..6 {
                let (mc, model, naive) = (scatter[k][k][(d, d)], shared.block(k, k)[(d, d)], plain[k][(d, d)]);
                assert!((model / mc - 1.0).abs() < 0.08, "scan {k} [{d}]: {model:e} against Monte Carlo {mc:e}");
                assert!(mc / naive > 1.8, "scan {k} [{d}]: independent links {naive:e}, Monte Carlo {mc:e}");
            }
            // Two poses' errors: correlated by about a half here (scan
            // 0's noise in both, and the links they share).
            for l in 1..k {
                for d in 0..6 {
                    let scale = (scatter[k][k][(d, d)] * scatter[l][l][(d, d)]).sqrt();
                    let (mc, model) = (scatter[k][l][(d, d)] / scale, shared.block(k, l)[(d, d)] / scale);
                    assert!(
                        (model - mc).abs() < 0.06,
                        "scans {k}, {l} [{d}]: correlation {model:.3}, Monte Carlo {mc:.3}"
                    );
                    assert!(mc > 0.3, "scans {k}, {l} [{d}]: Monte Carlo correlation {mc:.3}");
                }
            }
        }
    }

    fn links(pairs: &[(usize, usize)]) -> Vec<Link> {
        pairs
            .iter()
            .map(|&(target, source)| Link { target, source, overlap: 0, result: None, rejected: None, cycle: None })
            .collect()
    }

    /// Which link of a lone cycle is wrong no test can tell: a triangle's
    /// links are in series, as are a ring's; in four scans all linked
    /// (every link in three cycles) each link is told apart; a bridge
    /// closes no cycle at all.
    #[test]
    fn only_a_link_that_other_cycles_check_is_identifiable() {
        let triangle = links(&[(0, 1), (1, 2), (0, 2)]);
        assert!((0..3).all(|k| !identifiable(&triangle, &[0, 1, 2], k)));
        let ring = links(&[(0, 1), (1, 2), (2, 3), (0, 3)]);
        assert!((0..4).all(|k| !identifiable(&ring, &[0, 1, 2, 3], k)));
        let all = links(&[(0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3)]);
        let used: Vec<usize> = (0..6).collect();
        assert!((0..6).all(|k| identifiable(&all, &used, k)));
        // Without (1, 3) and (0, 2), the rest is a ring again.
        assert!(!identifiable(&all, &[0, 2, 3, 5], 0));
        let bridged = links(&[(0, 1), (1, 2), (0, 2), (2, 3)]);
        assert!(!identifiable(&bridged, &[0, 1, 2, 3], 3));
    }

    /// Four scans apart and turned.
    fn four_scans() -> Vec<Isometry3<f64>> {
        (0..4)
            .map(|i| {
                let i = f64::from(i);
                crate::se3::exp(&Vector6::new(0.1 * i, -0.05 * i, 0.3 * i, 2.0 * i, 0.5 * i, -0.2 * i))
            })
            .collect()
    }

    /// The six links between four scans, (target, source).
    const ALL_PAIRS: [(usize, usize); 6] = [(0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3)];

    /// Links (target, source) between `truth`'s scans measured with exactly
    /// the noise their information states: σ 1 mrad and 2–4 mm,
    /// correlated, a little different link by link.
    fn measured(rng: &mut rand_chacha::ChaCha8Rng, truth: &[Isometry3<f64>], pairs: &[(usize, usize)]) -> Vec<Edge> {
        use rand_distr::{Distribution, StandardNormal};
        pairs
            .iter()
            .enumerate()
            .map(|(k, &(t, s))| {
                let k = k as f64;
                let mut l = Matrix6::from_diagonal(&Vector6::new(1e-3, 1e-3, 1e-3, 2e-3 + 4e-4 * k, 3e-3, 4e-3));
                l[(4, 0)] = 1e-3;
                l[(5, 1)] = -5e-4;
                let z = Vector6::from_fn(|_, _| StandardNormal.sample(rng));
                let exact = truth[t].inverse() * truth[s];
                Edge {
                    target: t,
                    source: s,
                    target_from_source: crate::se3::exp(&(l * z)) * exact,
                    information: (l * l.transpose()).try_inverse().expect("positive definite"),
                }
            })
            .collect()
    }

    /// [`adjust_matches`] of `edges` from `poses`, each link's noise its
    /// information's inverse, no pull.
    fn adjusted(poses: &[Isometry3<f64>], edges: &[Edge]) -> Adjusted {
        let noise: Vec<Matrix6<f64>> =
            edges.iter().map(|e| e.information.try_inverse().expect("positive definite")).collect();
        adjust_matches(
            poses,
            edges,
            &noise,
            &vec![Pull::default(); edges.len()],
            &[],
            &LinkConfig::default(),
            Departures::Whole,
        )
        .expect("adjusted")
    }

    /// Four scans a quarter turn apart in a ring, its links measured
    /// ([`measured`], seed `seed`), and the generator after them.
    fn turning_ring(seed: u64) -> (Vec<Isometry3<f64>>, Vec<Edge>, rand_chacha::ChaCha8Rng) {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let truth: Vec<Isometry3<f64>> = (0..4)
            .map(|k| crate::se3::exp(&Vector6::new(0.0, 0.0, 1.57 * k as f64, 0.2 * k as f64, 0.1, 0.0)))
            .collect();
        let clean = measured(&mut rng, &truth, &[(0, 1), (1, 2), (2, 3), (3, 0)]);
        (truth, clean, rng)
    }

    /// `edges` each missing by [`LEAN_SHORTFALL`]× its lean.
    fn missed_by(edges: &[Edge], leans: &[Vector6<f64>]) -> Vec<Edge> {
        edges
            .iter()
            .zip(leans)
            .map(|(e, l)| Edge {
                target_from_source: crate::se3::exp(&(-LEAN_SHORTFALL * l)) * e.target_from_source,
                ..*e
            })
            .collect()
    }

    /// A ring of four scans whose links each miss by their edge's lean
    /// (1.25× it, 12–20 mm, 3–10 σ, across the ring) besides their noise:
    /// corrected by it, the links agree as they do without it (σ̂₀² of the
    /// same links measured without the lean), so the covariances take the
    /// lean, with that σ̂₀² — where σ̂₀² alone, one factor on every
    /// direction, widens the poses' tilt and height too, which the leans
    /// do not touch (2.7–6×). Where the leans are not what the links miss
    /// by, the covariances are exactly those of the pulls beyond the edge
    /// alone.
    #[test]
    fn a_ring_that_misses_by_its_leans_takes_them_as_its_links_bias() {
        use nalgebra::Vector3;
        use rand::Rng;
        let (truth, clean, mut rng) = turning_ring(43);
        let leans: Vec<Vector6<f64>> = (0..clean.len())
            .map(|_| {
                let v = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), 0.0).normalize();
                let length = rng.random_range(12e-3..20e-3) / LEAN_SHORTFALL;
                Vector6::new(0.0, 0.0, 2e-3 * rng.random_range(-1.0..1.0), v.x * length, v.y * length, 0.0)
            })
            .collect();
        let edges = missed_by(&clean, &leans);
        let noise: Vec<Matrix6<f64>> =
            edges.iter().map(|e| e.information.try_inverse().expect("positive definite")).collect();
        let at = |edges: &[Edge], pulls: &[Pull]| {
            adjust_matches(&truth, edges, &noise, pulls, &[], &LinkConfig::default(), Departures::Whole)
                .expect("adjusted")
        };
        let pulls: Vec<Pull> = leans.iter().map(|l| Pull { bias: 0.5 * l, lean: *l, ..Pull::default() }).collect();
        let leaning = at(&edges, &pulls);
        let lean = leaning.lean_variance_factor.expect("a ring has redundancy");
        let without = at(&clean, &vec![Pull::default(); clean.len()]);
        assert_eq!(without.lean_variance_factor, None, "no lean, nothing to correct");
        assert!(leaning.variance_factor > 5.0, "σ̂₀² {}", leaning.variance_factor);
        assert!((lean / without.variance_factor - 1.0).abs() < 0.05, "{lean} against {}", without.variance_factor);
        // The pulls beyond the edge alone (no lean), and σ̂₀².
        let unexplained: Vec<Pull> = pulls.iter().map(|p| Pull { lean: Vector6::zeros(), ..*p }).collect();
        let alone = at(&edges, &unexplained);
        for k in 1..4 {
            let (l, a) = (leaning.covariance[k].diagonal(), alone.covariance[k].diagonal());
            for axis in [0, 1, 5] {
                assert!(a[axis] > 2.5 * l[axis], "scan {k}, axis {axis}: {} against {}", a[axis], l[axis]);
            }
        }
        // Leans the other way: the corrected links miss more.
        let wrong: Vec<Pull> = pulls.iter().map(|p| Pull { lean: -p.lean, ..*p }).collect();
        let wrong = at(&edges, &wrong);
        assert!(wrong.lean_variance_factor.expect("redundancy") > wrong.variance_factor);
        for k in 1..4 {
            assert_eq!(wrong.covariance[k], alone.covariance[k], "scan {k}");
        }
    }

    /// The lean only where the links fail their global test without it: a
    /// ring whose links miss by small leans (1.25× them, 1.5–3 mm, about a
    /// σ) agrees better corrected by them, but passes the test as
    /// measured — its noise explains its misfit, and its covariances are
    /// exactly those of the pulls beyond the edge alone; the same leans ten
    /// times as long fail it, and the lean is taken.
    #[test]
    fn a_ring_within_its_noise_takes_no_lean() {
        use nalgebra::Vector3;
        use rand::Rng;
        let (truth, clean, mut rng) = turning_ring(44);
        let directions: Vec<Vector3<f64>> = (0..clean.len())
            .map(|_| Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), 0.0).normalize())
            .collect();
        let lengths: Vec<f64> = (0..clean.len()).map(|_| rng.random_range(1.5e-3..3e-3) / LEAN_SHORTFALL).collect();
        let at = |scale: f64| {
            let leans: Vec<Vector6<f64>> = directions
                .iter()
                .zip(&lengths)
                .map(|(v, &l)| Vector6::new(0.0, 0.0, 0.0, v.x, v.y, 0.0) * (l * scale))
                .collect();
            let edges = missed_by(&clean, &leans);
            let noise: Vec<Matrix6<f64>> =
                edges.iter().map(|e| e.information.try_inverse().expect("positive definite")).collect();
            let pulls: Vec<Pull> = leans.iter().map(|l| Pull { bias: 0.5 * l, lean: *l, ..Pull::default() }).collect();
            let alone: Vec<Pull> = pulls.iter().map(|p| Pull { lean: Vector6::zeros(), ..*p }).collect();
            let adjusted = |pulls: &[Pull]| {
                adjust_matches(&truth, &edges, &noise, pulls, &[], &LinkConfig::default(), Departures::Whole)
                    .expect("adjusted")
            };
            (adjusted(&pulls), adjusted(&alone))
        };
        let (small, small_alone) = at(1.0);
        let lean = small.lean_variance_factor.expect("a ring has redundancy");
        assert!(lean < small.variance_factor, "{lean} against {}", small.variance_factor);
        assert!(!beyond_global_test(small.variance_factor, small.redundancy), "σ̂₀² {}", small.variance_factor);
        for k in 1..4 {
            assert_eq!(small.covariance[k], small_alone.covariance[k], "scan {k}");
        }
        let (long, long_alone) = at(10.0);
        assert!(beyond_global_test(long.variance_factor, long.redundancy), "σ̂₀² {}", long.variance_factor);
        assert!(long.lean_variance_factor.expect("redundancy") < long.variance_factor);
        for k in 1..4 {
            // σ̂₀² whole on every direction widens the tilt and height,
            // which the leans do not touch.
            let (l, a) = (long.covariance[k].diagonal(), long_alone.covariance[k].diagonal());
            for axis in [0, 1, 5] {
                assert!(a[axis] > 2.5 * l[axis], "scan {k}, axis {axis}: {} against {}", a[axis], l[axis]);
            }
        }
    }

    /// A scan's noise common to its matches is weighed by how far they use
    /// the same part of it (`shared`): none where they use other parts —
    /// the links' noise then stays whole, the pairs' ([`pair_share`]), as
    /// if they had agreed as their noise says —, all of it with no
    /// footprints given, and linearly between. Four scans all linked,
    /// whose links agree 10× better than their covariances say (σ̂₀² ≈
    /// 0.1: most of their noise the scans').
    #[test]
    fn a_scans_shared_noise_is_weighed_by_its_matches_footprint_overlap() {
        let (truth, edges, noise) = four_linked(40, 0.0, 0.1, 1.0);
        let at = |edges: &[Edge], shared: &[f64]| {
            adjust_matches(
                &truth,
                edges,
                &noise,
                &vec![Pull::default(); edges.len()],
                shared,
                &LinkConfig::default(),
                Departures::Whole,
            )
            .expect("adjusted")
        };
        let (whole, given, none, half) =
            (at(&edges, &[]), at(&edges, &[1.0; 4]), at(&edges, &[0.0; 4]), at(&edges, &[0.5; 4]));
        assert!(whole.variance_factor < 0.3, "σ̂₀² {}", whole.variance_factor);
        // The same links weighed so that they agree as their information
        // says (σ̂₀² 1): their noise whole. (To 2 %: the start's steps,
        // which hold what no link sees, weigh a little against the links
        // weighed up 10×, and move the adjustment by as much; the noise
        // taken as σ̂₀², 90 % off.)
        let agreeing: Vec<Edge> =
            edges.iter().map(|e| Edge { information: e.information / whole.variance_factor, ..*e }).collect();
        let agreeing = at(&agreeing, &[]);
        assert!((agreeing.variance_factor - 1.0).abs() < 2e-3, "σ̂₀² {}", agreeing.variance_factor);
        for k in 1..4 {
            assert_eq!(whole.covariance[k], given.covariance[k], "scan {k}");
            let expected = agreeing.covariance[k] - agreeing.departure[k] * agreeing.departure[k].transpose()
                + none.departure[k] * none.departure[k].transpose();
            let off = (none.covariance[k] - expected).amax() / expected.amax();
            assert!(off <= 0.02, "scan {k}: {off} of the noise whole");
            // The shared share is most of these poses' variance.
            assert!(none.covariance[k].trace() < 0.6 * whole.covariance[k].trace(), "scan {k}");
            let middle = (none.covariance[k] + whole.covariance[k]) * 0.5;
            assert!((half.covariance[k] - middle).amax() <= 1e-12 * middle.amax(), "scan {k}");
        }
    }

    /// The pairs' rest ([`pair_share`]) widens the reported covariance,
    /// not the one a pose is judged by: where the links agree 10× better
    /// than their noise says and their scans' footprints do not overlap
    /// (wedges), the departures are judged on the covariance with the
    /// noise taken as the factor — exactly the covariance reported when
    /// that noise is given, whose own rest is then its factor's share of
    /// it — and the rest is all of the difference.
    #[test]
    fn a_pose_is_judged_without_the_pairs_rest() {
        let (truth, edges, noise) = four_linked(42, 0.0, 0.1, 1.0);
        // (Poses off the adjustment a little: their departures are judged.)
        let poses: Vec<Isometry3<f64>> = truth
            .iter()
            .enumerate()
            .map(|(k, t)| crate::se3::exp(&(Vector6::new(2e-3, -1e-3, 0.0, 1e-3, 4e-3, -2e-3) * k as f64)) * t)
            .collect();
        let at = |noise: &[Matrix6<f64>], shared: &[f64]| {
            let pulls = vec![Pull::default(); edges.len()];
            adjust_matches(&poses, &edges, noise, &pulls, shared, &LinkConfig::default(), Departures::Whole)
                .expect("adjusted")
        };
        let (shares, wedges) = (at(&noise, &[1.0; 4]), at(&noise, &[0.0; 4]));
        assert!(wedges.noise_factor < 0.3, "factor {}", wedges.noise_factor);
        // Footprints shared: every link's share is the factor.
        assert!(shares.pairs_rest.is_none());
        let rest = wedges.pairs_rest.as_ref().expect("the wedges' rest");
        // The noise taken as the factor, given so.
        let scaled: Vec<Matrix6<f64>> = noise.iter().map(|c| c * wedges.noise_factor).collect();
        let narrow = at(&scaled, &[0.0; 4]);
        assert_eq!(narrow.noise_factor, wedges.noise_factor);
        for k in 1..4 {
            let d = wedges.departure[k];
            let judged = wedges.covariance[k] - d * d.transpose() - rest.block(k, k);
            let reported = narrow.covariance[k] - d * d.transpose();
            assert!((judged - reported).amax() <= 1e-9 * reported.amax(), "scan {k}");
            let chi2 = (d.transpose() * crate::icp::solve::pseudo_inverse(&reported) * d)[(0, 0)];
            assert!((wedges.departure_chi2[k] - chi2).abs() <= 1e-6 * chi2, "scan {k}: {}", wedges.departure_chi2[k]);
            // Wider by most of the noise: 1 − f of it.
            assert!(rest.block(k, k).trace() > 2.0 * judged.trace(), "scan {k}");
            assert!(wedges.departure_chi2[k] > 0.0);
        }
        assert_eq!(rest.block(0, 0), Matrix6::zeros());
    }

    /// Four scans turned `roll` and apart along x, every pair linked
    /// ([`measured`] with seed `seed`), each link's information × `scale`
    /// and its noise the inverse of that × `noise_scale`.
    fn four_linked(
        seed: u64,
        roll: f64,
        scale: f64,
        noise_scale: f64,
    ) -> (Vec<Isometry3<f64>>, Vec<Edge>, Vec<Matrix6<f64>>) {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let truth: Vec<Isometry3<f64>> =
            (0..4).map(|k| crate::se3::exp(&Vector6::new(roll, 0.0, 0.3 * k as f64, k as f64, 0.5, 0.0))).collect();
        let edges: Vec<Edge> = measured(&mut rng, &truth, &ALL_PAIRS)
            .into_iter()
            .map(|e| Edge { information: e.information * scale, ..e })
            .collect();
        let noise =
            edges.iter().map(|e| e.information.try_inverse().expect("positive definite") * noise_scale).collect();
        (truth, edges, noise)
    }

    /// A scan's own sampling error is its links' asymmetry beyond what
    /// their noise makes of it ([`sampling_own`]): links that do not
    /// disagree with themselves, or no more than the noise's `floor`,
    /// change nothing; where scan 3's three links each lean by v (world
    /// axes), every scan with such a link gets (1 − floor·m/χ²) times
    /// their mean vvᵀ (m links, χ² their Σ ΔᵀC⁻¹Δ), and every pose
    /// scan 0's besides — against hand-made sums.
    #[test]
    fn a_scans_sampling_error_is_its_links_asymmetry_beyond_their_noise() {
        // The links disagree 10× beyond their information (σ̂₀² > 1: no
        // shared share of the noise to weigh against).
        let (truth, edges, noise) = four_linked(41, 0.02, 10.0, 10.0);
        let floor = 3.0;
        // (Poses off the adjustment a little: their departures are judged.)
        let poses: Vec<Isometry3<f64>> = truth
            .iter()
            .enumerate()
            .map(|(k, t)| crate::se3::exp(&(Vector6::new(1e-3, 0.0, -2e-3, 3e-3, 1e-3, 0.0) * k as f64)) * t)
            .collect();
        let adjusted = |pulls: &[Pull], asymmetry: Option<f64>| {
            let config = LinkConfig { asymmetry, ..LinkConfig::default() };
            adjust_matches(&poses, &edges, &noise, pulls, &[], &config, Departures::Whole).expect("adjusted")
        };
        let at = |pulls: &[Pull], asymmetry: Option<f64>| adjusted(pulls, asymmetry).covariance;
        let plain = at(&vec![Pull::default(); edges.len()], None);
        assert!(plain[1].trace() > 0.0);
        // No asymmetry, and asymmetry at the noise's own size: nothing.
        assert_eq!(at(&vec![Pull::default(); edges.len()], Some(floor)), plain);
        let at_floor: Vec<Pull> = noise
            .iter()
            .map(|c| {
                let u = Vector6::new(0.3, -0.2, 0.5, 0.1, 0.7, -0.4);
                let x = (u.transpose() * c.try_inverse().expect("invertible") * u)[0];
                Pull { asymmetry: u * (floor / x).sqrt(), ..Pull::default() }
            })
            .collect();
        assert_eq!(at(&at_floor, Some(floor)), plain);
        // Scan 3's links lean by v, in the world's axes.
        let v = Vector6::new(2e-3, -1e-3, 4e-3, 3e-3, -2e-3, 1e-3);
        let leaning: Vec<Pull> = edges
            .iter()
            .map(|e| Pull {
                asymmetry: if e.source == 3 || e.target == 3 {
                    adjoint(&truth[e.target]).try_inverse().expect("invertible") * v
                } else {
                    Vector6::zeros()
                },
                ..Pull::default()
            })
            .collect();
        let chi2 = |k: usize| -> f64 {
            edges
                .iter()
                .zip(&noise)
                .zip(&leaning)
                .filter(|((e, _), _)| e.source == k || e.target == k)
                .map(|((_, c), p)| (p.asymmetry.transpose() * c.try_inverse().expect("invertible") * p.asymmetry)[0])
                .sum()
        };
        // Each scan has three links; scan 3's all lean, the others' one.
        let own = |k: usize| {
            let share = if k == 3 { 1.0 } else { 1.0 / 3.0 };
            v * v.transpose() * (SAMPLING_SHARE * share * (1.0 - floor * 3.0 / chi2(k)))
        };
        let leant = at(&leaning, Some(floor));
        for k in 1..4 {
            // (Δ is carried to the world's axes by the adjusted poses, not
            // the truth: 1e-3 apart here.)
            let expected = plain[k] + own(k) + own(0);
            assert!(
                (leant[k] - expected).amax() <= 1e-2 * (own(k) + own(0)).amax(),
                "scan {k}: {:?} against {:?}",
                leant[k] - plain[k],
                own(k) + own(0)
            );
        }
        // The departures are judged without it, as without the model.
        let (with, without) = (adjusted(&leaning, Some(floor)), adjusted(&leaning, None));
        assert!(with.sampling[3].amax() > 0.0);
        for k in 1..4 {
            let (a, b) = (with.departure_chi2[k], without.departure_chi2[k]);
            assert!(b > 1.0 && (a - b).abs() <= 1e-9 * b, "scan {k}: departure χ² {a} against {b}");
        }
    }

    /// A room's walls, floor and ceiling (8 × 6 × 3 m) sampled every 5 cm
    /// about the scanner at its centre.
    fn room() -> Vec<Point3<f32>> {
        let mut points = Vec::new();
        let step = 0.05;
        let (hx, hy, hz) = (4.0f32, 3.0f32, 1.5f32);
        let grid = |a: f32, b: f32| {
            let (na, nb) = ((2.0 * a / step) as i32, (2.0 * b / step) as i32);
            (0..=na).flat_map(move |i| (0..=nb).map(move |j| (-a + i as f32 * step, -b + j as f32 * step)))
        };
        for (y, z) in grid(hy, hz) {
            points.extend([Point3::new(-hx, y, z), Point3::new(hx, y, z)]);
        }
        for (x, z) in grid(hx, hz) {
            points.extend([Point3::new(x, -hy, z), Point3::new(x, hy, z)]);
        }
        for (x, y) in grid(hx, hy) {
            points.extend([Point3::new(x, y, -hz), Point3::new(x, y, hz)]);
        }
        points
    }

    /// Random shares of one scan share their footprints wholly — every
    /// link uses all of the scan — and wedges hardly: each link of a wedge
    /// uses the side it shares with that neighbour.
    #[test]
    fn shares_share_their_links_footprints_and_wedges_do_not() {
        // Each scan's shares for links between `scans` (all at the
        // identity) given as (target, source).
        let shares_of = |scans: &[Vec<Point3<f32>>], pairs: &[(usize, usize)]| {
            let config = LinkConfig::default();
            let overlap_m = config.multiview.overlap_distance();
            let prepared = prepare(scans, &config.multiview).expect("prepared");
            let prints: Vec<[Footprint; 2]> = pairs
                .iter()
                .map(|&(t, s)| {
                    let partners = Partners::at(&prepared[s].source, &prepared[t].local, &Isometry3::identity());
                    footprints(&prepared[s].source, &Isometry3::identity(), &partners, overlap_m)
                })
                .collect();
            shared_shares(scans.len(), &links(pairs), &prints)
        };
        let points = room();
        let all_pairs: Vec<(usize, usize)> = (0..4).flat_map(|j| (j + 1..4).map(move |i| (j, i))).collect();
        let shares: Vec<Vec<Point3<f32>>> = (0..4)
            .map(|k| {
                points
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| (*i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 62 == k)
                    .map(|(_, p)| *p)
                    .collect()
            })
            .collect();
        let rho = shares_of(&shares, &all_pairs);
        assert!(rho.iter().all(|&r| r > 0.9), "{rho:?}");
        // Four 150° wedges about the vertical, centred 90° apart: each
        // overlaps its two neighbours, on either side.
        let wedges: Vec<Vec<Point3<f32>>> = (0..4)
            .map(|k| {
                let centre = std::f32::consts::FRAC_PI_2 * k as f32;
                points
                    .iter()
                    .filter(|p| {
                        let d = p.y.atan2(p.x) - centre;
                        d.sin().atan2(d.cos()).abs() <= 75f32.to_radians()
                    })
                    .copied()
                    .collect()
            })
            .collect();
        let rho = shares_of(&wedges, &[(0, 1), (1, 2), (2, 3), (0, 3)]);
        assert!(rho.iter().all(|&r| r < 0.2), "{rho:?}");
        // A scan with one link has nothing to share it with: 1.
        let rho = shares_of(&wedges, &[(0, 1), (1, 2)]);
        assert_eq!((rho[0], rho[2]), (1.0, 1.0), "{rho:?}");
        assert!(rho[1] < 0.2, "{rho:?}");
    }

    /// Links measured with exactly the noise their information states give
    /// a variance factor whose mean is 1 (Monte Carlo): the redundancy is
    /// the links' — counting the start's steps as observations halved it
    /// on four fully linked scans. A tree of links has none: its factor is
    /// 1 whatever the measurements.
    #[test]
    fn the_variance_factor_of_honest_links_is_one_on_average() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(38);
        let truth = four_scans();
        let pairs = ALL_PAIRS;
        assert_eq!(link_redundancy(4, pairs.iter().copied()), 18);
        assert_eq!(link_redundancy(4, pairs[..3].iter().copied()), 6);
        assert_eq!(link_redundancy(5, pairs[..2].iter().chain(&[(3, 4)]).copied()), 0);
        let factor = |edges: &[Edge]| adjusted(&truth, edges).variance_factor;
        let trials = 400;
        let mean = (0..trials).map(|_| factor(&measured(&mut rng, &truth, &pairs))).sum::<f64>() / f64::from(trials);
        // σ of the mean: √(2/18/400) = 0.017.
        assert!((mean - 1.0).abs() < 0.06, "mean variance factor {mean}");
        let tree = [(0, 1), (1, 2), (1, 3)];
        let f = factor(&measured(&mut rng, &truth, &tree));
        assert_eq!(f, 1.0);
    }

    /// A ring of four scans — one cycle, ν = 6 — whose links are exactly
    /// as noisy as their calibrated covariance says. σ̂₀² then scatters as
    /// χ²₆/6, and taken whole above 1 it widens every pose by its chance:
    /// over 2,000 draws (873 above 1) the adjustment's errors against its
    /// covariance had mean NEES 4.2 on the draws above 1 (6 when honest),
    /// 4.8 on all. Pooled with a calibration of 96 degrees of freedom
    /// where the ring passes its global test (σ̂₀² 2 → 1.06; beyond 2.41,
    /// 2.5 % of the draws, whole): 5.5 and 5.4 — the draws below 1, read
    /// as the scans' shared noise, which these links do not have, stay a
    /// little pessimistic. Many links outweigh the calibration. Where the
    /// ring's links use other parts of their scans (wedges: footprint
    /// overlap 0), the draws below 1 keep their noise whole
    /// ([`pair_share`]): mean NEES 5.9 on them (taken as σ̂₀², the rule
    /// before, 12.5; read as the scans' shared noise, 5.3).
    #[test]
    fn a_rings_variance_factor_is_pooled_with_the_calibrations() {
        use rand::SeedableRng;
        // χ²₆'s 97.5 % point is 14.45: σ̂₀² up to 2.41 on a ring passes.
        assert!((pooled_factor(2.0, 6, 96) - 108.0 / 102.0).abs() < 1e-12);
        assert_eq!(pooled_factor(2.5, 6, 96), 2.5, "beyond the global test: as it is");
        assert_eq!(pooled_factor(306.0, 6, 72), 306.0, "the 3DTK set's triangle");
        assert_eq!(pooled_factor(0.5, 6, 96), 0.5, "at or below 1 as it is");
        assert_eq!(pooled_factor(2.0, 6, 0), 2.0, "without a calibration as it is");
        assert!((pooled_factor(1.05, 900, 96) - 1041.0 / 996.0).abs() < 1e-12, "many links outweigh it");
        assert_eq!(pooled_factor(1.0, 0, 96), 1.0, "no redundancy");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(64);
        let truth = four_scans();
        let ring = [(0, 1), (1, 2), (2, 3), (0, 3)];
        assert_eq!(link_redundancy(4, ring.iter().copied()), 6);
        let draws = 2000u32;
        let (mut whole, mut pooled, mut above) = (0.0, 0.0, 0u32);
        // The draws whose σ̂₀² is above 1: whole, pooled.
        let (mut whole_above, mut pooled_above) = (0.0, 0.0);
        // The draws below 1: as the scans' shared noise (footprint overlap
        // 1), as wedges' (0), and with the noise taken as σ̂₀².
        let (mut shared_below, mut wedges_below, mut scaled_below) = (0.0, 0.0, 0.0);
        for _ in 0..draws {
            let edges = measured(&mut rng, &truth, &ring);
            let noise: Vec<Matrix6<f64>> =
                edges.iter().map(|e| e.information.try_inverse().expect("positive definite")).collect();
            let pulls = vec![Pull::default(); edges.len()];
            let at = |calibration_dof, noise: &[Matrix6<f64>], shared: &[f64]| {
                let config = LinkConfig { calibration_dof, ..LinkConfig::default() };
                adjust_matches(&truth, &edges, noise, &pulls, shared, &config, Departures::Whole).expect("adjusted")
            };
            let (w, p, wedges) = (at(0, &noise, &[]), at(96, &noise, &[]), at(96, &noise, &[0.0; 4]));
            let scaled: Vec<Matrix6<f64>> = noise.iter().map(|c| c * w.variance_factor).collect();
            let scaled = at(96, &scaled, &[0.0; 4]);
            above += u32::from(w.variance_factor > 1.0);
            // The adjustment's own error against its covariance (less the
            // departure's ξξᵀ, which `Whole` adds).
            for s in 1..4 {
                let d = w.departure[s];
                let own = |a: &Adjusted| nees(&-d, &(a.covariance[s] - d * d.transpose()));
                let (a, b) = (own(&w), own(&p));
                (whole, pooled) = (whole + a, pooled + b);
                if w.variance_factor > 1.0 {
                    (whole_above, pooled_above) = (whole_above + a, pooled_above + b);
                } else {
                    shared_below += b;
                    wedges_below += own(&wedges);
                    scaled_below += own(&scaled);
                }
            }
        }
        let n = f64::from(3 * draws);
        let (whole, pooled) = (whole / n, pooled / n);
        let m = f64::from(3 * above);
        let (whole_above, pooled_above) = (whole_above / m, pooled_above / m);
        // Residuals and the estimate's error are independent in a linear
        // adjustment: σ̂₀² above 1 says nothing of this draw's error beyond
        // the links' scale, which the calibration knows better.
        assert!(above > draws / 4 && above < 3 * draws / 4, "σ̂₀² above 1 in {above} draws");
        assert!(whole_above < 4.6, "σ̂₀² above 1 taken whole: mean NEES {whole_above}");
        assert!((5.2..6.5).contains(&pooled_above), "σ̂₀² above 1 pooled: mean NEES {pooled_above}");
        assert!(whole < 5.2 && pooled > whole + 0.4, "every draw: pooled {pooled}, whole {whole}");
        let b = f64::from(3 * (draws - above));
        let (shared_below, wedges_below, scaled_below) = (shared_below / b, wedges_below / b, scaled_below / b);
        assert!((5.5..6.5).contains(&wedges_below), "σ̂₀² below 1, wedges: mean NEES {wedges_below}");
        assert!(shared_below < wedges_below - 0.4, "σ̂₀² below 1, shares: mean NEES {shared_below}");
        assert!(scaled_below > 9.0, "σ̂₀² below 1, the noise taken as σ̂₀²: mean NEES {scaled_below}");
    }

    /// ξᵀ·C⁻¹·ξ.
    fn nees(xi: &Vector6<f64>, c: &Matrix6<f64>) -> f64 {
        (xi.transpose() * c.try_inverse().expect("invertible") * xi)[(0, 0)]
    }

    /// A strategy whose error shares half the adjustment's, cov(ε, εₐ) =
    /// Σₐ/2 — between the chain's, which shares all of it (the adjustment
    /// the better estimate: ξξᵀ whole is right), and an independent
    /// estimate's, which shares none: its poses exp(εₐ/2 + δ)·truth, εₐ
    /// the adjustment's error and δ another adjustment's of the same six
    /// links measured again. Over 2,000 draws its errors against the
    /// adjustment's covariance plus ξξᵀ whole are 1.3× pessimistic (mean
    /// NEES 3.6: ξξᵀ then holds Σₐ too much); carried as far as the
    /// departures exceed the adjustment's noise
    /// ([`Departures::BeyondNoise`]), 5.1 — as honest as the adjustment's
    /// own errors against its covariance (4.9; a little pessimistic, as in
    /// the chain's test below).
    #[test]
    fn a_strategy_sharing_half_the_adjustments_error_carries_its_departure_beyond_the_noise() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(62);
        let truth = four_scans();
        let draws = 2000;
        let (mut whole, mut beyond, mut own) = (0.0, 0.0, 0.0);
        for _ in 0..draws {
            let (edges, again) = (measured(&mut rng, &truth, &ALL_PAIRS), measured(&mut rng, &truth, &ALL_PAIRS));
            // Each adjustment at exp(−ξ)·truth, ξ truth's departure from it:
            // its error −ξ.
            let (first, other) = (adjusted(&truth, &edges), adjusted(&truth, &again));
            let strategy: Vec<Isometry3<f64>> =
                (0..4).map(|s| crate::se3::exp(&(-0.5 * first.departure[s] - other.departure[s])) * truth[s]).collect();
            let noise: Vec<Matrix6<f64>> =
                edges.iter().map(|e| e.information.try_inverse().expect("positive definite")).collect();
            let pulls = vec![Pull::default(); edges.len()];
            let at = |departures| {
                adjust_matches(&strategy, &edges, &noise, &pulls, &[], &LinkConfig::default(), departures)
                    .expect("adjusted")
            };
            let (w, b) = (at(Departures::Whole), at(Departures::BeyondNoise));
            assert!(b.departure_weight >= 0.0 && b.departure_weight < 1.0, "{}", b.departure_weight);
            for s in 1..4 {
                let e = left_difference(&strategy[s], &truth[s]);
                whole += nees(&e, &w.covariance[s]);
                beyond += nees(&e, &b.covariance[s]);
                // The adjustment's own error against its covariance.
                let d = first.departure[s];
                own += nees(&-d, &(first.covariance[s] - d * d.transpose()));
            }
        }
        let n = f64::from(3 * draws);
        let (whole, beyond, own) = (whole / n, beyond / n, own / n);
        assert!(whole < 4.0, "ξξᵀ whole: mean NEES {whole}");
        assert!((beyond - own).abs() < 0.6, "beyond the noise: {beyond}, the adjustment's own {own}");
    }

    /// A chain (each scan placed on the one before, as pairwise matching
    /// places it) does not close the links' cycles: its poses are the
    /// adjustment of all six links plus their departure from it, and over
    /// 2,000 draws the chain's errors against the adjustment's covariance
    /// plus the departure's ξξᵀ are as honest as the adjustment's own
    /// errors against its covariance (mean NEES 5.0 and 4.8 — both a
    /// little pessimistic, as each draw's σ̂₀² below 1 is read as the
    /// scans' shared noise, which these links do not have); against the
    /// adjustment's covariance alone the chain is 3× optimistic (20).
    #[test]
    fn a_chain_is_the_adjustment_plus_its_departure() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(39);
        let truth = four_scans();
        let draws = 2000;
        let (mut chained, mut own, mut alone) = (0.0, 0.0, 0.0);
        // Each pair of poses relative to each other, against the joint
        // covariance's Cᵢ + Cⱼ − Cᵢⱼ − Cⱼᵢ: the adjustment's own poses and
        // the chain's; and, as if the poses shared nothing, Cᵢ + Cⱼ.
        let (mut own_relative, mut chained_relative, mut unshared) = (0.0, 0.0, 0.0);
        for _ in 0..draws {
            let edges = measured(&mut rng, &truth, &ALL_PAIRS);
            // (0, 1), (1, 2), (2, 3): the chain's links.
            let mut chain = vec![truth[0]];
            for k in [0, 2, 5] {
                chain.push(chain[edges[k].target] * edges[k].target_from_source);
            }
            let a = adjusted(&chain, &edges);
            for s in 1..4 {
                let d = a.departure[s];
                let adjustment = a.covariance[s] - d * d.transpose();
                let at = crate::se3::exp(&-d) * chain[s];
                chained += nees(&left_difference(&chain[s], &truth[s]), &a.covariance[s]);
                own += nees(&left_difference(&at, &truth[s]), &adjustment);
                alone += nees(&left_difference(&chain[s], &truth[s]), &adjustment);
            }
            let own_error: Vec<Vector6<f64>> =
                (0..4).map(|s| left_difference(&(crate::se3::exp(&-a.departure[s]) * chain[s]), &truth[s])).collect();
            let chain_error: Vec<Vector6<f64>> = (0..4).map(|s| left_difference(&chain[s], &truth[s])).collect();
            let c = &a.joint_covariance;
            for (i, j) in [(1, 2), (1, 3), (2, 3)] {
                let (di, dj) = (a.departure[i], a.departure[j]);
                let relative = c.block(i, i) + c.block(j, j) - c.block(i, j) - c.block(j, i);
                let own_relative_covariance = relative - (dj - di) * (dj - di).transpose();
                own_relative += nees(&(own_error[j] - own_error[i]), &own_relative_covariance);
                chained_relative += nees(&(chain_error[j] - chain_error[i]), &relative);
                let alone = c.block(i, i) - di * di.transpose() + c.block(j, j) - dj * dj.transpose();
                unshared += nees(&(own_error[j] - own_error[i]), &alone);
            }
        }
        let n = (3 * draws) as f64;
        let (chained, own, alone) = (chained / n, own / n, alone / n);
        assert!((chained - own).abs() < 0.4, "the chain's mean NEES {chained}, the adjustment's {own}");
        assert!((own - 6.0).abs() < 1.2, "the adjustment's mean NEES {own}");
        assert!(alone > own + 2.0, "against the adjustment's covariance alone: {alone} (its own {own})");
        // Relative poses: as honest as each pose alone (the adjustment's
        // cross-covariances), the chain's departures carried as one
        // stacked error; taken as sharing nothing, about 2× pessimistic.
        let (own_relative, chained_relative, unshared) = (own_relative / n, chained_relative / n, unshared / n);
        assert!((own_relative - own).abs() < 0.5, "relative poses' mean NEES {own_relative}, each pose's {own}");
        assert!(
            (chained_relative - own_relative).abs() < 0.5,
            "the chain's relative {chained_relative}, the adjustment's {own_relative}"
        );
        assert!(
            unshared < 0.6 * own,
            "relative poses without the cross-covariances: {unshared} (with them {own_relative})"
        );
    }
}
