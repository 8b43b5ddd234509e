//! Multi-view matching (seed 000 §4.2): many scans into one consistent
//! world frame.
//!
//! Scans arrive in order, each with a guess of its pose (odometry or CPS).
//! Scan 0 is the master scan: it is fixed and defines the frame. Each new
//! scan starts from the previous scan's registered pose moved by the
//! guesses' increment (`pose[i−1] · guess[i−1]⁻¹ · guess[i]`), and then
//! - [`Strategy::Pairwise`] registers it against the earlier scan with the
//!   most overlap (most correspondences at the start pose);
//! - [`Strategy::Incremental`] registers it against the *metascan*, the
//!   union of all scans registered so far (Chen and Medioni);
//! - [`Strategy::Simultaneous`] registers it pairwise for a start, puts it in
//!   a queue and repeats until the queue is empty: take the first scan off
//!   the queue; unless it is the master, align it (ICP) against the union of
//!   its neighbours — every scan with more than
//!   [`min_pairs`](MultiviewConfig::min_pairs) correspondences with it — and,
//!   if that moved it, append each neighbour not yet in the queue.
//!
//! Pairwise and incremental registration accumulate each match's error;
//! simultaneous matching lets later scans pull earlier ones back, so the
//! whole set stays consistent.
//!
//! Each scan is prepared once: reduced points (the data set D) and a
//! target with normals estimated in the scan's own frame and turned towards
//! its scanner at [`IcpConfig::source_viewpoint`] (so that a match can
//! leave out surfaces the other scanner saw from behind,
//! [`IcpConfig::reject_back_faces`]). A match against one scan runs in
//! that scan's frame, against its prepared target (the link graph's way:
//! no tree to build, the neighbourhoods already there), its result carried
//! into the world by the frame's adjoint; a model set M of several scans is
//! their targets moved into the world with their current poses (normals
//! rotated along), so only its k-d tree is built per match.
//!
//! With [`IcpConfig::degeneracy_ratio`] every match runs in the world, as
//! before: the eigen-analysis of blind directions is not invariant to the
//! frame (rotations about a far origin weigh more against translations),
//! and its threshold was chosen in the world frame — run in the scans' own
//! frames, the sewer's matches kept their roll blind but saw the pipe's
//! axis (ratio above 1e-3) and slid a metre along it. (Models built in the
//! matched scan's frame gave the same matches to micrometres but stopped
//! each a little earlier — the translation tolerance no longer carries the
//! world's lever arm — and the millimetre-threshold queue of the hall test
//! walked off; so the models stay in the world.)

use std::collections::VecDeque;

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use crate::error::{FusionError, Result};
use crate::icp::correspondences::Partners;
use crate::icp::solve::align_from;
use crate::icp::{IcpConfig, IcpResult, Kernel, Method, Target, align};
use crate::se3::adjoint;

/// How each new scan is registered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Strategy {
    /// Against the earlier scan with the most overlap.
    Pairwise,
    /// Against the union of all earlier scans (the metascan).
    Incremental,
    /// Pairwise start, then the seed's queue over the neighbours.
    Simultaneous,
}

/// Multi-view settings (documented defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MultiviewConfig {
    /// The strategy. Default simultaneous.
    pub strategy: Strategy,
    /// Every match's ICP settings. Default point-to-plane, 0.5 m, 50
    /// iterations, Huber 2 cm, back faces rejected (each scan's normals
    /// are turned towards its scanner, `icp.source_viewpoint` — the same
    /// place in every scan's frame; default the origin).
    pub icp: IcpConfig,
    /// Reduced-points cell of the data set D, metres. Default 0.1 (0.2 m
    /// cells straddle the edges of door reveals and pilasters, and their
    /// means, off both faces, bias each match by centimetres along a
    /// corridor).
    pub source_voxel_m: f64,
    /// Reduced-points cell of the model set M, metres. Default 0.1.
    pub target_voxel_m: f64,
    /// Two scans overlap when more than this many correspondences exist
    /// (within the ICP distance). Default 250, as in the seed.
    pub min_pairs: usize,
    /// A match "moved" its scan (and re-queues its neighbours) when it
    /// shifted it by more than this, metres. Default 0.01: about twice a
    /// match's own σ for LMS-class scans. Smaller thresholds keep the queue
    /// chasing the matches' noise, which walks the whole set away from the
    /// master scan (measured on the corridor: see BENCHMARKS.md).
    pub moved_translation_m: f64,
    /// … or turned it by more than this, radians. Default 0.05° (8.7e-4).
    pub moved_rotation_rad: f64,
    /// Simultaneous matching: at most this many matches per new scan before
    /// its queue is abandoned (reported as not settled). Default 100.
    pub max_matches_per_scan: usize,
    /// Correspondences between scans are counted within this distance
    /// (for `min_pairs`). Default `None`: the ICP distance. A fine pass
    /// after a coarse one keeps the coarse distance here, since fewer pairs
    /// lie within a fine distance of scans that still overlap as much.
    pub overlap_m: Option<f64>,
}

impl MultiviewConfig {
    /// The distance correspondences are counted within for overlap:
    /// [`overlap_m`](Self::overlap_m), or the ICP distance without it.
    pub fn overlap_distance(&self) -> f64 {
        self.overlap_m.unwrap_or(self.icp.max_correspondence_m)
    }
}

impl Default for MultiviewConfig {
    fn default() -> Self {
        Self {
            strategy: Strategy::Simultaneous,
            icp: IcpConfig {
                max_correspondence_m: 0.5,
                kernel: Kernel::Huber { width_m: 0.02 },
                reject_back_faces: true,
                ..IcpConfig::default()
            },
            source_voxel_m: 0.1,
            target_voxel_m: 0.1,
            min_pairs: 250,
            moved_translation_m: 0.01,
            moved_rotation_rad: 0.05f64.to_radians(),
            max_matches_per_scan: 100,
            overlap_m: None,
        }
    }
}

/// One ICP run of a multi-view registration, iteration by iteration
/// (recorded when [`IcpConfig::trace`] is set).
#[derive(Debug, Clone, PartialEq)]
pub struct IcpTrace {
    /// The scan that moved (the source).
    pub scan: usize,
    /// The scans it was matched against.
    pub partners: Vec<usize>,
    /// The scan's world pose after each iteration, in order.
    pub world_from_scan: Vec<Isometry3<f64>>,
}

/// What multi-view matching returns.
#[derive(Debug, Clone, PartialEq)]
pub struct MultiviewResult {
    /// The registered pose of every scan; scan 0 is its guess.
    pub world_from_scan: Vec<Isometry3<f64>>,
    /// The ICP result of each scan's last match (`None` for the master), its
    /// `target_from_source` being the scan's pose and its information the
    /// match's (conditional on the partners' poses).
    pub last_match: Vec<Option<IcpResult>>,
    /// The scans each scan was last matched against.
    pub partners: Vec<Vec<usize>>,
    /// ICP runs in total.
    pub matches: usize,
    /// False when a simultaneous queue hit
    /// [`max_matches_per_scan`](MultiviewConfig::max_matches_per_scan).
    pub settled: bool,
    /// Every ICP run in the order run, with [`IcpConfig::trace`] set;
    /// empty otherwise.
    pub traces: Vec<IcpTrace>,
}

/// A scan prepared for matching, in its own frame.
pub(crate) struct Prepared {
    /// Reduced points: the data set D.
    pub(crate) source: Vec<Point3<f32>>,
    /// The finer model points with their normals.
    pub(crate) local: Target,
}

/// Registers `scans` (each in its own frame) given a guess of each one's
/// pose. `progress(done, total)` is called as each scan is registered.
pub fn register_views<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    guesses: &[Isometry3<f64>],
    config: &MultiviewConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<MultiviewResult> {
    check(scans, guesses, config)?;
    let prepared = prepare(scans, config)?;
    let n = scans.len();
    let mut m = Matcher {
        prepared,
        config,
        poses: vec![guesses[0]],
        last_match: vec![None],
        partners: vec![Vec::new()],
        matches: 0,
        settled: true,
        traces: Vec::new(),
        occupancy: crate::candidates::Occupancy::empty(2.0 * config.overlap_distance()),
    };
    progress(1, n);
    for i in 1..n {
        let start = m.poses[i - 1] * guesses[i - 1].inverse() * guesses[i];
        m.poses.push(start);
        m.last_match.push(None);
        m.partners.push(Vec::new());
        match config.strategy {
            Strategy::Pairwise => m.pairwise(i)?,
            Strategy::Incremental => m.incremental(i)?,
            Strategy::Simultaneous => {
                m.pairwise(i)?;
                m.settle(i)?;
            }
        }
        progress(i + 1, n);
    }
    Ok(MultiviewResult {
        world_from_scan: m.poses,
        last_match: m.last_match,
        partners: m.partners,
        matches: m.matches,
        settled: m.settled,
        traces: m.traces,
    })
}

/// Reduced points and the model target of every scan, in parallel.
pub(crate) fn prepare<S: AsRef<[Point3<f32>]> + Sync>(scans: &[S], config: &MultiviewConfig) -> Result<Vec<Prepared>> {
    let k = if config.icp.method == Method::PointToPlane { config.icp.normal_neighbours.max(3) } else { 0 };
    scans
        .par_iter()
        .enumerate()
        .map(|(i, points)| -> Result<Prepared> {
            let points = points.as_ref();
            let source = scanner::reduced_points(points, config.source_voxel_m).map_err(|e| in_scan(i, e.into()))?;
            let model = if config.target_voxel_m == config.source_voxel_m {
                source.clone()
            } else {
                scanner::reduced_points(points, config.target_voxel_m).map_err(|e| in_scan(i, e.into()))?
            };
            let mut local = Target::new(&model, k).map_err(|e| in_scan(i, e))?;
            // Every scan of a rig has its scanner at the same place in its frame.
            local.orient_normals_towards(&config.icp.source_viewpoint);
            Ok(Prepared { source, local })
        })
        .collect()
}

/// Pairwise matching's screened candidates, before the [`crate::candidates::SCREEN`]
/// factor: the exact overlap is counted with this many times that many
/// best-ranked earlier scans.
const PAIRWISE_CANDIDATES: usize = 2;

pub(crate) struct Matcher<'a> {
    pub(crate) prepared: Vec<Prepared>,
    pub(crate) config: &'a MultiviewConfig,
    /// Current poses of the scans registered so far (and the new one).
    pub(crate) poses: Vec<Isometry3<f64>>,
    pub(crate) last_match: Vec<Option<IcpResult>>,
    pub(crate) partners: Vec<Vec<usize>>,
    pub(crate) matches: usize,
    pub(crate) settled: bool,
    pub(crate) traces: Vec<IcpTrace>,
    /// The registered scans' cells, for pairwise matching's candidates
    /// (filled as scans are registered).
    pub(crate) occupancy: crate::candidates::Occupancy,
}

impl Matcher<'_> {
    /// The distance correspondences are counted within for overlap.
    pub(crate) fn overlap_distance(&self) -> f64 {
        self.config.overlap_distance()
    }

    /// Correspondences of scan `c`'s reduced points with scan `j`'s model
    /// at the current poses.
    pub(crate) fn overlap(&self, c: usize, j: usize) -> usize {
        let j_from_c = self.poses[j].inverse() * self.poses[c];
        self.prepared[j].local.correspondences(&self.prepared[c].source, &j_from_c, self.overlap_distance())
    }

    /// The model set M: the `members`' models in the world frame.
    fn model(&self, members: &[usize]) -> Result<Target> {
        let total: usize = members.iter().map(|&j| self.prepared[j].local.len()).sum();
        let (mut points, mut normals, mut shares, mut corners) =
            (Vec::with_capacity(total), Vec::with_capacity(total), Vec::new(), Vec::new());
        for &j in members {
            let pose = self.poses[j];
            let moved: Isometry3<f32> = pose.cast();
            let local = &self.prepared[j].local;
            points.extend(local.points().map(|p| moved * p));
            normals.extend(local.normals().into_iter().map(|v| pose.rotation * v));
            // Only the scan-line test reads them (none: every point planar).
            if self.config.icp.line_ratio.is_some() {
                shares.extend(local.middle_shares());
            }
            // Only the corner test reads these (none: every point planar).
            if self.config.icp.corner_ratio.is_some() {
                corners.extend(local.corner_shares_beyond(self.config.icp.corner_reach_m()));
            }
        }
        Target::with_oriented_normals(&points, normals)?.with_middle_shares(shares)?.with_corner_shares(corners)
    }

    /// Aligns scan `c` to its `partners` and records the match; returns its
    /// pose before. One partner is matched in its own frame, with its
    /// prepared target (the tree and neighbourhoods built once per scan),
    /// unless blind directions are analysed (see the module docs); several
    /// through a model built in the world.
    fn align(&mut self, c: usize, partners: Vec<usize>) -> Result<Isometry3<f64>> {
        self.align_starting(c, partners, None)
    }

    /// [`align`](Self::align), with the nearest neighbours of `c`'s points
    /// in its one partner at the current poses already found (`first`,
    /// used when the match runs in the partner's frame).
    fn align_starting(&mut self, c: usize, partners: Vec<usize>, first: Option<Partners>) -> Result<Isometry3<f64>> {
        let r = if let ([j], None) = (&partners[..], self.config.icp.degeneracy_ratio) {
            let world_from_j = self.poses[*j];
            let init = world_from_j.inverse() * self.poses[c];
            let (source, target) = (&self.prepared[c].source, &self.prepared[*j].local);
            let r = match first {
                Some(first) => align_from(source, target, &init, &self.config.icp, first),
                None => align(source, target, &init, &self.config.icp),
            };
            in_world(r.map_err(|e| in_scan(c, e))?, &world_from_j)
        } else {
            let model = self.model(&partners)?;
            align(&self.prepared[c].source, &model, &self.poses[c], &self.config.icp).map_err(|e| in_scan(c, e))?
        };
        Ok(self.record(c, r, partners))
    }

    /// Records match `r` (in the world) of scan `c` against `partners`;
    /// returns its pose before.
    fn record(&mut self, c: usize, r: IcpResult, partners: Vec<usize>) -> Isometry3<f64> {
        let before = self.poses[c];
        if !r.trace.is_empty() {
            self.traces.push(IcpTrace { scan: c, partners: partners.clone(), world_from_scan: r.trace.clone() });
        }
        self.poses[c] = r.target_from_source;
        self.last_match[c] = Some(r);
        self.partners[c] = partners;
        self.matches += 1;
        before
    }

    fn no_overlap(&self, c: usize, pairs: usize, against: &str, partner: Option<usize>) -> FusionError {
        FusionError::NoOverlap {
            scan: c,
            pairs,
            needed: self.config.min_pairs + 1,
            against: against.into(),
            partner,
            stage: None,
        }
    }

    /// Registers scan `i` against the earlier scan with the most overlap.
    fn pairwise(&mut self, i: usize) -> Result<()> {
        // Each earlier scan's nearest neighbours of scan i's points, counted
        // within the overlap distance; the best one's start the match.
        // The exact overlap only with the earlier scans that share the most
        // cells at their registered poses ([`crate::candidates`]).
        while self.occupancy.len() < i {
            let j = self.occupancy.len();
            self.occupancy.push(&self.prepared[j].source, &self.poses[j]);
        }
        let screened = self.occupancy.ranked_for(
            &self.prepared[i].source,
            &self.poses[i],
            crate::candidates::SCREEN * PAIRWISE_CANDIDATES,
        );
        let source = &self.prepared[i].source;
        let found: Vec<(usize, usize, Partners)> = screened
            .into_par_iter()
            .map(|j| {
                let partners =
                    Partners::at(source, &self.prepared[j].local, &(self.poses[j].inverse() * self.poses[i]));
                (j, partners.within(self.overlap_distance()), partners)
            })
            .collect();
        let Some((best, pairs, first)) = found.into_iter().max_by_key(|&(j, p, _)| (p, j)) else {
            return Err(self.no_overlap(i, 0, "the best earlier scan (0)", Some(0)));
        };
        if pairs <= self.config.min_pairs {
            return Err(self.no_overlap(i, pairs, &format!("the best earlier scan ({best})"), Some(best)));
        }
        self.align_starting(i, vec![best], Some(first))?;
        Ok(())
    }

    /// Registers scan `i` against the metascan of scans `0..i`.
    fn incremental(&mut self, i: usize) -> Result<()> {
        let members: Vec<usize> = (0..i).collect();
        let model = self.model(&members)?;
        let pairs = model.correspondences(&self.prepared[i].source, &self.poses[i], self.overlap_distance());
        if pairs <= self.config.min_pairs {
            return Err(self.no_overlap(i, pairs, "the metascan", None));
        }
        let r = align(&self.prepared[i].source, &model, &self.poses[i], &self.config.icp).map_err(|e| in_scan(i, e))?;
        self.record(i, r, members);
        Ok(())
    }

    /// The seed's queue, started with the new scan `i`; scans `0..=i` take part.
    fn settle(&mut self, i: usize) -> Result<()> {
        let mut queue = VecDeque::from([i]);
        let mut runs = 0;
        while let Some(c) = queue.pop_front() {
            if c == 0 {
                continue;
            }
            if runs == self.config.max_matches_per_scan {
                self.settled = false;
                break;
            }
            let neighbours: Vec<usize> =
                (0..=i).into_par_iter().filter(|&j| j != c && self.overlap(c, j) > self.config.min_pairs).collect();
            if neighbours.is_empty() {
                continue;
            }
            let before = self.align(c, neighbours.clone())?;
            runs += 1;
            let step = self.poses[c] * before.inverse();
            let moved = step.translation.vector.norm() > self.config.moved_translation_m
                || step.rotation.angle() > self.config.moved_rotation_rad;
            if moved {
                for j in neighbours {
                    if j != 0 && !queue.contains(&j) {
                        queue.push_back(j);
                    }
                }
            }
        }
        Ok(())
    }
}

/// A match made in its target scan's frame (`target_from_source` =
/// `j_from_c`), moved into the world by `world_from_j`: the pose and trace
/// composed, the source's centroid moved, the information and blind
/// directions carried by the adjoint
/// (ξ_world = Ad(world_from_j) ξ_j).
pub(crate) fn in_world(mut r: IcpResult, world_from_j: &Isometry3<f64>) -> IcpResult {
    let ad = adjoint(world_from_j);
    let ad_inv = adjoint(&world_from_j.inverse());
    r.target_from_source = world_from_j * r.target_from_source;
    r.trace.iter_mut().for_each(|t| *t = world_from_j * *t);
    r.information = ad_inv.transpose() * r.information * ad_inv;
    r.information = 0.5 * (r.information + r.information.transpose());
    r.unobservable.iter_mut().for_each(|d| *d = (ad * *d).normalize());
    r.edge_bias = ad * r.edge_bias;
    r.edge_lean = ad * r.edge_lean;
    r.asymmetry = ad * r.asymmetry;
    r.source_centroid = world_from_j * r.source_centroid;
    r.range_covariance = r.range_covariance.map(|c| ad * c * ad.transpose());
    r
}

pub(crate) fn in_scan(scan: usize, e: FusionError) -> FusionError {
    FusionError::InScan { scan, source: Box::new(e) }
}

pub(crate) fn check<S>(scans: &[S], guesses: &[Isometry3<f64>], c: &MultiviewConfig) -> Result<()> {
    if scans.len() != guesses.len() {
        return Err(FusionError::OutOfRange {
            what: "number of pose guesses".into(),
            value: guesses.len() as f64,
            expected: format!("one per scan ({})", scans.len()),
        });
    }
    if scans.is_empty() {
        return Err(FusionError::OutOfRange { what: "number of scans".into(), value: 0.0, expected: "≥ 1".into() });
    }
    FusionError::require_positive("source voxel (m)", c.source_voxel_m)?;
    FusionError::require_positive("target voxel (m)", c.target_voxel_m)?;
    FusionError::require_positive("max correspondence distance (m)", c.icp.max_correspondence_m)?;
    if let Some(d) = c.overlap_m {
        FusionError::require_positive("overlap distance (m)", d)?;
    }
    FusionError::require_non_negative("moved translation (m)", c.moved_translation_m)?;
    FusionError::require_non_negative("moved rotation (rad)", c.moved_rotation_rad)?;
    if c.max_matches_per_scan == 0 {
        return Err(FusionError::OutOfRange { what: "matches per scan".into(), value: 0.0, expected: "≥ 1".into() });
    }
    if let Some((i, g)) = guesses.iter().enumerate().find(|(_, g)| !g.to_homogeneous().iter().all(|v| v.is_finite())) {
        return Err(FusionError::OutOfRange {
            what: format!("pose guess of scan {i}"),
            value: g.translation.vector.norm(),
            expected: "finite".into(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion, Vector3, Vector6};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// Random points on a plane patch (corner, two edges), with ±0.5 mm noise.
    fn patch(rng: &mut ChaCha8Rng, c: [f32; 3], u: [f32; 3], v: [f32; 3], n: usize) -> Vec<Point3<f32>> {
        let (c, u, v) = (Vector3::from(c), Vector3::from(u), Vector3::from(v));
        let normal = u.cross(&v).normalize();
        (0..n)
            .map(|_| {
                let (a, b): (f32, f32) = (rng.random_range(0.0..1.0), rng.random_range(0.0..1.0));
                Point3::from(c + u * a + v * b + normal * rng.random_range(-0.0005..0.0005))
            })
            .collect()
    }

    /// A room (floor, four walls, a pillar) or, with `corridor`, only a
    /// floor and two long walls — blind along x; x within ±`half_length`.
    fn scene(rng: &mut ChaCha8Rng, corridor: bool, half_length: f32) -> Vec<Point3<f32>> {
        let (x0, l) = (-half_length, 2.0 * half_length);
        let dense = (1000.0 * half_length) as usize;
        let mut p = patch(rng, [x0, -3.0, -1.0], [l, 0.0, 0.0], [0.0, 6.0, 0.0], 2 * dense);
        p.extend(patch(rng, [x0, -3.0, -1.0], [l, 0.0, 0.0], [0.0, 0.0, 3.0], dense));
        p.extend(patch(rng, [x0, 3.0, -1.0], [l, 0.0, 0.0], [0.0, 0.0, 3.0], dense));
        if !corridor {
            p.extend(patch(rng, [x0, -3.0, -1.0], [0.0, 6.0, 0.0], [0.0, 0.0, 3.0], 2000));
            p.extend(patch(rng, [-x0, -3.0, -1.0], [0.0, 6.0, 0.0], [0.0, 0.0, 3.0], 2000));
            p.extend(patch(rng, [1.0, 1.0, -1.0], [0.4, 0.0, 0.0], [0.0, 0.0, 3.0], 300));
            p.extend(patch(rng, [1.0, 1.0, -1.0], [0.0, 0.4, 0.0], [0.0, 0.0, 3.0], 300));
        }
        p
    }

    /// A match made in the target scan's frame and carried into the world
    /// ([`in_world`]) — the target's frame 14 m and 40° from the world's:
    /// - in a room, it is the match against the target moved into the world
    ///   (what a one-scan model was): the same pose and information;
    /// - in a corridor (the source inside the target's length), the axis is
    ///   its one blind direction, carried into the world by the adjoint, and
    ///   the pose stays at the start along it while the rest is recovered
    ///   (the link graph's matches, and `register`'s, run this way).
    #[test]
    fn a_match_in_its_target_frame_is_the_world_match() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let world_from_j = Isometry3::from_parts(
            Translation3::new(12.0, -7.0, 1.5),
            UnitQuaternion::from_euler_angles(0.05, -0.03, 40f64.to_radians()),
        );
        let j_from_c = Isometry3::from_parts(
            Translation3::new(0.6, -0.2, 0.05),
            UnitQuaternion::from_euler_angles(0.01, 0.02, 0.2),
        );
        let config = IcpConfig {
            max_correspondence_m: 0.5,
            max_iterations: 100,
            translation_tolerance_m: 1e-9,
            rotation_tolerance_rad: 1e-9,
            reject_back_faces: true,
            ..IcpConfig::default()
        };
        let start = Isometry3::translation(0.05, 0.03, -0.02) * j_from_c;
        let c_from_j: Isometry3<f32> = j_from_c.inverse().cast();
        let mut prepared = |corridor: bool, source_half_length: f32| {
            let mut target = Target::new(&scene(&mut rng, corridor, 4.0), 10).expect("target");
            target.orient_normals_towards(&Point3::origin());
            let source: Vec<Point3<f32>> =
                scene(&mut rng, corridor, source_half_length).iter().map(|p| c_from_j * p).collect();
            (target, source)
        };

        let (local, source) = prepared(false, 4.0);
        let moved: Isometry3<f32> = world_from_j.cast();
        let world = Target::with_oriented_normals(
            &local.points().map(|p| moved * p).collect::<Vec<_>>(),
            local.normals().into_iter().map(|n| world_from_j.rotation * n).collect(),
        )
        .and_then(|t| t.with_middle_shares(local.middle_shares()))
        .expect("world target");
        let b = in_world(align(&source, &local, &start, &config).expect("in j's frame"), &world_from_j);
        let a = align(&source, &world, &(world_from_j * start), &config).expect("in the world");
        let d = a.target_from_source.inverse() * b.target_from_source;
        assert!(d.translation.vector.norm() < 2e-5 && d.rotation.angle() < 2e-6, "{d}");
        let truth = world_from_j * j_from_c;
        let e = truth.inverse() * b.target_from_source;
        assert!(e.translation.vector.norm() < 1e-3 && e.rotation.angle() < 2e-4, "{e}");
        assert!((a.information - b.information).amax() < 1e-3 * a.information.amax(), "{}", b.information);

        let (local, source) = prepared(true, 2.0);
        // Random points' PCA normals tilt enough to leave the axis 1.7e-3
        // of the largest eigenvalue here.
        let blind = IcpConfig { degeneracy_ratio: Some(1e-2), ..config };
        let in_j = align(&source, &local, &start, &blind).expect("in j's frame");
        // The error in j's frame: the start's was (0.05, 0.03, −0.02) m.
        let e = in_j.target_from_source * j_from_c.inverse();
        assert!((e.translation.vector.x - 0.05).abs() < 1e-3, "held along the axis: {e}");
        assert!(e.translation.vector.yz().norm() < 1e-3 && e.rotation.angle() < 2e-4, "{e}");
        let b = in_world(in_j, &world_from_j);
        let axis = adjoint(&world_from_j) * Vector6::new(0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
        assert_eq!(b.unobservable.len(), 1, "{:?}", b.unobservable);
        assert!(b.unobservable[0].dot(&axis).abs() > 1.0 - 1e-4, "the corridor's axis: {}", b.unobservable[0]);
        let along = b.information * b.unobservable[0];
        assert!(along.norm() < 1e-9 * b.information.amax(), "information along the blind direction: {along}");
    }
}
