//! A user's scan set registered into one frame: multi-view matching
//! ([`crate::multiview`]) stage by stage of a coarse-to-fine schedule,
//! each stage starting from the last one's poses; for [`Mode::Graph`] the
//! finest stage is the link graph over every overlapping pair
//! ([`crate::links`]), and the coarser stages match pairwise — the graph
//! makes the set consistent, so they need only bring each scan within the
//! finer stage's reach. On the three 3DTK scans that lands where
//! simultaneous stages before the graph land (to 0.002° and 0.1 mm) in a
//! third of the time.
//!
//! The first scan stays where its start puts it and defines the frame.
//! Everything runs in that frame — the starts moved into it, the poses
//! moved back, covariances and blind directions turned into the world's
//! axes about the first scan's origin — so georeferenced starts (an E57's
//! project coordinates, UTM) cost neither the models' f32 coordinates their
//! millimetres, nor the blind-direction analysis its balance, nor the
//! covariances their meaning.

use nalgebra::{Isometry3, Matrix6, Point3, Vector6};
use rayon::prelude::*;

use crate::error::{FusionError, Result};
use crate::icp::degeneracy::orthonormal;
use crate::icp::{IcpResult, Stage};
use crate::links::{LinkConfig, LinkGraph};
use crate::multiview::{MultiviewConfig, Strategy, in_world, register_views};
use crate::se3::adjoint;
use crate::verify::{PairCheck, PairChecks};

/// How the set is registered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Each scan against the earlier scan with the most overlap.
    Pairwise,
    /// Each scan against the metascan of all earlier ones.
    Incremental,
    /// The seed's simultaneous matching.
    Simultaneous,
    /// Simultaneous matching, then the link graph over every pair.
    Graph,
}

/// The settings of [`register_set`].
#[derive(Debug, Clone, PartialEq)]
pub struct SetConfig {
    /// The mode. Default graph.
    pub mode: Mode,
    /// The coarse-to-fine stages (voxel of both sets, correspondence
    /// distance). Default 0.5/2, 0.25/1, 0.1/0.5, 0.05/0.2 m.
    pub stages: Vec<Stage>,
    /// Everything else: the ICP settings (point-to-plane, Huber 2 cm, 100
    /// iterations — the 3DTK set, its schedule scaled by 0.99, slid on
    /// past 50 at 2 cm an iteration before it converged —, converged below
    /// 0.1 mm and 1e-4 rad, back faces
    /// rejected, blind directions held: ratio 1e-3), `min_pairs` (250 at
    /// the finest stage, scaled by the cell's area at coarser ones), the
    /// step σ of the start and the link gate. The voxels and distances are
    /// the stages'.
    pub link: LinkConfig,
    /// Each scan's scanner position in its own frame, where the input
    /// states it (`None`, or a missing entry: not known); the verification
    /// tests the free space those scanners saw ([`crate::free_space`]).
    /// Default: none known.
    pub viewpoints: Vec<Option<Point3<f64>>>,
    /// At the finest stage, leave out pairs whose source point lies beyond
    /// what the target sampled around its partner
    /// ([`crate::icp::IcpConfig::only_covered`]). Default false: on the
    /// room's 150° wedges it brings the error from 1.2 mm to 0.4 mm, but
    /// it left the simulated corridor's 77 scans 11.6 mm RMS from the
    /// truth along the axis, against 6.6 mm without it (BENCHMARKS,
    /// "Matching both ways, and where the overlap ends").
    pub only_covered: bool,
}

impl Default for SetConfig {
    fn default() -> Self {
        Self {
            mode: Mode::Graph,
            stages: [(0.5, 2.0), (0.25, 1.0), (0.1, 0.5), (0.05, 0.2)]
                .map(|(voxel_m, max_correspondence_m)| Stage { voxel_m, max_correspondence_m })
                .to_vec(),
            link: {
                let link = LinkConfig::default();
                LinkConfig {
                    multiview: MultiviewConfig {
                        icp: crate::icp::IcpConfig {
                            kernel: crate::icp::Kernel::Huber { width_m: 0.02 },
                            translation_tolerance_m: 1e-4,
                            rotation_tolerance_rad: 1e-4,
                            max_iterations: 100,
                            ..link.multiview.icp
                        },
                        ..link.multiview
                    },
                    ..link
                }
            },
            viewpoints: Vec::new(),
            only_covered: false,
        }
    }
}

/// What [`register_set`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct SetResult {
    /// Every scan's registered `world_from_scan`.
    pub world_from_scan: Vec<Isometry3<f64>>,
    /// Each pose's 6×6 covariance (ξ = (ω, v), left perturbation, world
    /// frame): the link graph's, or for the other modes that of the
    /// verification's matches adjusted together from the final poses (the
    /// link graph's model) plus the poses' departure from that adjustment
    /// — whole in pairwise mode, in the others as far as it exceeds the
    /// adjustment's noise ([`crate::links::adjust_matches`],
    /// [`crate::links::Departures`]) — before the verification, or
    /// without a pair to verify, the last match's with its partners'
    /// (their mean for a metascan); zero for the first scan.
    pub covariance: Vec<Matrix6<f64>>,
    /// The poses' joint covariance (the same ξ, frame and model),
    /// [`covariance`](Self::covariance) its diagonal: what two poses'
    /// errors share — the relative pose of two scans placed by the same
    /// links is known better than either alone. `None` where the
    /// covariances are not an adjustment's (the last matches', before the
    /// verification or without a pair to verify).
    pub joint_covariance: Option<crate::graph::JointCovariance>,
    /// Each pose's share of [`covariance`](Self::covariance) that is the
    /// scans' own sampling ([`crate::links::Adjusted::sampling`]; empty
    /// where the covariances are not an adjustment's): left out where a
    /// pose is judged (its moves along what only its start holds).
    pub sampling: Vec<Matrix6<f64>>,
    /// The share of [`joint_covariance`](Self::joint_covariance) that is
    /// the pairs' rest ([`crate::links::Adjusted::pairs_rest`]; `None`
    /// where there is none): left out where a pose or a pair is judged.
    pub pairs_rest: Option<crate::graph::JointCovariance>,
    /// In the modes without a link graph, each pose's departure from the
    /// adjustment of the verification's matches (ξ = (ω, v), world frame,
    /// pose ≈ exp(ξ)·adjusted; zero for the first scan): how far the
    /// strategy stopped from where all its pairs agree, and part of
    /// [`covariance`](Self::covariance) (w·ξξᵀ,
    /// [`departure_weight`](Self::departure_weight)). Empty in graph mode, whose
    /// poses are the adjustment, and without a pair verified.
    pub departure: Vec<Vector6<f64>>,
    /// Each departure in the σ of the adjustment it departs from, ξᵀ·C⁺·ξ
    /// ([`crate::links::Adjusted::departure_chi2`]): above
    /// [`MAX_DEPARTURE_CHI2`](crate::verify::MAX_DEPARTURE_CHI2) the scan
    /// is not trusted ([`untrusted`](Self::untrusted)). Empty where
    /// [`departure`](Self::departure) is.
    pub departure_chi2: Vec<f64>,
    /// The share of the departures' ξξᵀ in
    /// [`covariance`](Self::covariance)
    /// (1 in pairwise mode; in the others
    /// [`crate::links::departure_weight`], as far as they exceed the
    /// adjustment's noise). `None` where [`departure`](Self::departure) is
    /// empty.
    pub departure_weight: Option<f64>,
    /// How far each departure moves the scan's points, metres: its
    /// centroid's displacement plus the turn times their RMS radius (as
    /// [`crate::verify::PairCheck::moved_m`] measures a pair). Empty where
    /// [`departure`](Self::departure) is.
    pub departure_m: Vec<f64>,
    /// The scans whose departure is beyond
    /// [`MAX_DEPARTURE_CHI2`](crate::verify::MAX_DEPARTURE_CHI2) in its σ
    /// *and* moves their points by more than the finest voxel (the
    /// verification's tolerance for a pair): the
    /// strategy settled in a compromise of its matches that no pair,
    /// matched again alone, moves far enough to name. Empty in graph mode.
    pub departed: Vec<usize>,
    /// How far each scan moved from its start along the directions only
    /// the start holds — in graph mode those it reports blind
    /// ([`unobservable`](Self::unobservable): held by the start's steps,
    /// not by its links), in the other modes those its matches hold less
    /// than the start does ([`held_by_start`]) — in χ² of its own
    /// covariance along them (with as many degrees of freedom as there are
    /// directions), and how far that moves its points, metres (0 and 0
    /// without such a direction; empty before the verification).
    pub held: Vec<Held>,
    /// Each scan's directions the matches do not see (unit ξ, world frame).
    pub unobservable: Vec<Vec<Vector6<f64>>>,
    /// The final stage's matches: the link graph's pairs, or each scan's
    /// last match against its partners.
    pub links: Vec<SetLink>,
    /// ICP runs in all.
    pub matches: usize,
    /// False when a simultaneous queue was abandoned at its cap.
    pub settled: bool,
    /// The set's variance factor σ̂₀²: the link graph's, or in the other
    /// modes that of the verification's matches adjusted together from the
    /// final poses ([`crate::links::adjust_matches`]); it scales the
    /// covariances (below 1 as the scans' shared noise; above 1 within the
    /// links' global test pooled with the calibration's,
    /// [`noise_factor`](Self::noise_factor)). `None` before
    /// the verification (other modes) or without a pair to verify.
    pub variance_factor: Option<f64>,
    /// σ̂₀² of the same links each corrected by its edge's lean
    /// ([`crate::links::LinkGraph::lean_variance_factor`]); below
    /// `variance_factor`, where the links fail their global test without
    /// it, the covariances take it ([`crate::links::Pull`]).
    /// `None` without redundancy or a lean, or where `variance_factor` is.
    pub lean_variance_factor: Option<f64>,
    /// The redundancy `variance_factor` rests on
    /// ([`crate::links::LinkGraph::redundancy`]); `None` where it is.
    pub redundancy: Option<usize>,
    /// The factor the covariances take on the links' noise
    /// ([`crate::links::LinkGraph::noise_factor`]: σ̂₀² or the lean's,
    /// above 1 and within the links' global test pooled with the
    /// calibration's); `None` where `variance_factor` is.
    pub noise_factor: Option<f64>,
    /// Each stage of the schedule: its matches and time.
    pub stages: Vec<StageRun>,
    /// Every pair overlapping at the final poses, matched once more from
    /// them at the finest stage ([`crate::verify`]).
    pub checks: Vec<PairCheck>,
    /// The verification's wall-clock time, seconds.
    pub check_seconds: f64,
    /// The covariance model calibrated on these scans' halves and
    /// quarters ([`crate::noise::calibrate`]); its factors scale the
    /// finest matches' covariances. `None` without a stage.
    pub noise: Option<crate::noise::Calibration>,
    /// The calibration's wall-clock time, seconds.
    pub noise_seconds: f64,
    /// The registration from the starts again without the schedule's
    /// first stage, when a scan moved beyond the second stage's reach of
    /// its start, the schedule failed, put points in another scanner's
    /// free space or left links that disagree ([`Restart`]).
    pub restart: Option<Restart>,
}

impl SetResult {
    /// The scans not to trust, in order: those the verification names at
    /// the final poses ([`crate::verify::untrusted`]), those the
    /// schedule's and the restart's registrations place apart with nothing
    /// in the data to choose between them ([`Restart::undecided`]), and
    /// those the strategy left apart from where their verified pairs agree
    /// ([`departed`](Self::departed)).
    pub fn untrusted(&self) -> Vec<usize> {
        let mut named = self.named();
        named.extend(self.restart.iter().filter(|x| !x.corroborated).flat_map(|x| x.undecided.iter().map(|u| u.0)));
        named.extend(self.restart.iter().flat_map(|x| x.unsupported.iter().map(|u| u.0)));
        named.sort_unstable();
        named.dedup();
        named
    }

    /// Whether the verification names scans only by their moves along
    /// what only their starts hold ([`held`](Self::held)): each of them
    /// tied to another by a pair matched again that agrees, no pair
    /// disagreeing and nothing departing from where they agree — what
    /// the data do not hold moved, not what they contradict. (A scan that
    /// no pair reaches is held by its start in every direction: its move
    /// is all the stages' doing, and nothing verifies it.)
    pub fn named_only_held(&self) -> bool {
        let held: Vec<usize> = self.held.iter().enumerate().filter(|(_, h)| h.named).map(|(i, _)| i).collect();
        !held.is_empty()
            && held.iter().all(|&i| self.tied(i))
            && self.departed.is_empty()
            && crate::verify::untrusted(self.world_from_scan.len(), &self.checks).is_empty()
    }

    /// Whether the verification ties every scan to another by a pair
    /// matched again that agrees: none is placed by the stages alone (a
    /// scan no pair reaches is held by its start in every direction, and
    /// nothing verifies it).
    pub fn all_tied(&self) -> bool {
        (1..self.world_from_scan.len()).all(|i| self.tied(i))
    }

    /// Whether a pair matched again that agrees ties scan `i` to another.
    fn tied(&self, i: usize) -> bool {
        self.checks.iter().any(|c| c.consistent && (c.source == i || c.target == i))
    }

    /// The scans the verification names at these poses: by their pairs
    /// ([`crate::verify::untrusted`]), by their departure from where
    /// those pairs agree ([`departed`](Self::departed)) or by their move
    /// along what only their start holds ([`held`](Self::held)), in
    /// order. What
    /// the restarts judge a registration by ([`Restart`]).
    pub fn named(&self) -> Vec<usize> {
        let mut named = crate::verify::untrusted(self.world_from_scan.len(), &self.checks);
        named.extend(&self.departed);
        named.extend(self.held.iter().enumerate().filter(|(_, h)| h.named).map(|(i, _)| i));
        named.sort_unstable();
        named.dedup();
        named
    }
}

/// A scan's move from its start along the directions only the start
/// holds ([`SetResult::held`]): in graph mode those it reports blind, in
/// the other modes those its matches hold less than the start does
/// ([`held_by_start`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Held {
    /// The move in χ² of the scan's covariance along those directions.
    pub chi2: f64,
    /// How many directions (the χ²'s degrees of freedom).
    pub directions: usize,
    /// The directions (unit ξ = (ω, v), left, in the frame of the
    /// scan's covariance).
    pub along: Vec<Vector6<f64>>,
    /// How far the move takes the scan's points: its centroid's
    /// displacement plus the turn times their RMS radius, metres.
    pub moved_m: f64,
    /// Beyond [`held_limit`] and the finest voxel: what only the start
    /// holds moved further than the start's steps allow — the scan is
    /// named.
    /// (A pipe's scans, matched at the default blind-direction threshold,
    /// slid 74–184 mm along its axis with both the axis and the roll
    /// reported blind on every scan: 15.7–22.6 in χ² with two directions;
    /// right results 0.0–0.1.)
    pub named: bool,
}

/// The χ² a [`Held`] move with `directions` degrees of freedom may reach:
/// the distribution's 99.9 % point ([`crate::chi2::chi2_999`]).
pub fn held_limit(directions: usize) -> f64 {
    crate::chi2::chi2_999(directions)
}

/// Whether a move of `chi2` along `directions` blind directions, moving
/// the scan's points by `moved_m`, names the scan ([`Held::named`]):
/// beyond [`held_limit`] and beyond `tolerance_m` (the finest voxel).
pub fn held_beyond(chi2: f64, directions: usize, moved_m: f64, tolerance_m: f64) -> bool {
    chi2 > held_limit(directions) && moved_m > tolerance_m
}

/// How scan `pose` moved from `start` along `blind` (unit ξ, left, about
/// the frame's origin, as `covariance`), judged about the scan's points'
/// `centroid` (in its own frame) with rotations scaled by their RMS
/// `radius` — the metric the blind directions were found in — so that
/// its move along what its links see does not leak into them.
pub fn held_move(
    pose: &Isometry3<f64>,
    start: &Isometry3<f64>,
    blind: &[Vector6<f64>],
    covariance: &Matrix6<f64>,
    centroid: &Point3<f64>,
    radius: f64,
    tolerance_m: f64,
) -> Held {
    if blind.is_empty() {
        return Held::default();
    }
    // (ω, v) about the origin → (ω·radius, v + ω × c) about the centroid.
    let c = (pose * centroid).coords;
    let mut m = Matrix6::<f64>::identity();
    m.fixed_view_mut::<3, 3>(0, 0).fill_diagonal(radius.max(f64::EPSILON));
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-crate::se3::skew(&c)));
    let moved: Vec<Vector6<f64>> = blind.iter().map(|d| m * d).collect();
    let basis = orthonormal(&moved);
    // The move itself, exactly: its turn and the centroid's displacement
    // (a turn about a centroid far from the origin is no shift of it).
    let step = pose * start.inverse();
    let from = start * centroid;
    let turn = step.rotation.scaled_axis() * radius.max(f64::EPSILON);
    let shift = step * from - from;
    let delta = Vector6::new(turn.x, turn.y, turn.z, shift.x, shift.y, shift.z);
    let a = nalgebra::DVector::from_iterator(basis.len(), basis.iter().map(|q| q.dot(&delta)));
    let cm = m * covariance * m.transpose();
    let s = nalgebra::DMatrix::from_fn(basis.len(), basis.len(), |i, j| basis[i].dot(&(cm * basis[j])));
    let chi2 = s.clone().pseudo_inverse(1e-12 * s.amax()).map_or(f64::INFINITY, |p| (a.transpose() * p * &a)[0]);
    let along: Vector6<f64> = basis.iter().zip(a.iter()).map(|(q, x)| q * *x).sum();
    let moved_m = along.fixed_rows::<3>(3).norm() + along.fixed_rows::<3>(0).norm();
    let named = held_beyond(chi2, basis.len(), moved_m, tolerance_m);
    Held { chi2, directions: basis.len(), along: orthonormal(blind), moved_m, named }
}

/// The least share of a direction's variance from the start alone that a
/// scan's covariance keeps where the start holds it at least as much as
/// the scan's matches do ([`held_by_start`]): information adds, so there
/// the matches add at most as much as the start's steps give.
pub const HELD_SHARE: f64 = 0.5;

/// In the modes without a link graph, how scan `pose` moved from `start`
/// along the directions its `covariance` (the verification's adjustment,
/// [`crate::links::adjust_matches`]) keeps at least [`HELD_SHARE`] of the
/// start's steps' alone (`steps`, [`crate::links::steps_covariance`]):
/// those its matches hold no better than the start — a pipe's axis and
/// roll, whatever a match's blind-direction threshold judged. The
/// directions are the generalised eigenvectors of the two covariances
/// (the same in every frame and unit), the move judged in the steps'
/// whitened metric. (On a pipe's 180-slice scans at the default
/// threshold, the matches reported nothing blind and slid the scans
/// 74–289 mm along the axis: two such directions on every scan, their
/// shares 0.72–1.13, the others' ≤ 0.17; the moves 17–51 in χ².) The
/// points (`centroid` in the scan's frame, RMS `radius`) measure the
/// move as [`held_move`] does, taken exactly as the turn and the
/// centroid's displacement.
pub fn held_by_start(
    pose: &Isometry3<f64>,
    start: &Isometry3<f64>,
    covariance: &Matrix6<f64>,
    steps: &Matrix6<f64>,
    centroid: &Point3<f64>,
    radius: f64,
    tolerance_m: f64,
) -> Held {
    let Some(l) = steps.cholesky().map(|c| c.l()) else { return Held::default() };
    let Some(li) = l.try_inverse() else { return Held::default() };
    let w = li * covariance * li.transpose();
    let eigen = nalgebra::SymmetricEigen::new((w + w.transpose()) * 0.5);
    // The move exactly as its turn and its centroid's displacement (a
    // turn about a centroid far from the origin is no shift of it), in
    // ξ about the origin: (ω, v − ω × c).
    let from = (start * centroid).coords;
    let step = pose * start.inverse();
    let turn = step.rotation.scaled_axis();
    let shift = step * Point3::from(from) - Point3::from(from);
    let xi = Vector6::from_iterator(turn.iter().copied().chain((shift - turn.cross(&from)).iter().copied()));
    let y = li * xi;
    let (mut chi2, mut along, mut directions) = (0.0, Vector6::<f64>::zeros(), Vec::new());
    for (k, share) in eigen.eigenvalues.iter().enumerate().filter(|(_, s)| **s >= HELD_SHARE) {
        let v = eigen.eigenvectors.column(k).into_owned();
        let a = v.dot(&y);
        chi2 += a * a / share;
        let d = l * v;
        along += d * a;
        directions.push(d.normalize());
    }
    if directions.is_empty() {
        return Held::default();
    }
    // Back about the centroid: its displacement plus the turn times the
    // points' RMS radius.
    let (w, v) = (along.fixed_rows::<3>(0).into_owned(), along.fixed_rows::<3>(3).into_owned());
    let moved_m = (v + w.cross(&from)).norm() + w.norm() * radius;
    let named = held_beyond(chi2, directions.len(), moved_m, tolerance_m);
    Held { chi2, directions: directions.len(), along: directions, moved_m, named }
}

/// A second registration from the starts: the schedule without its first
/// (coarsest) stage, run when the first registration moved a scan further
/// from its start than the second stage's correspondence distance (out of
/// the restart's reach: the first stage decided where it went), and kept
/// when the scans agree clearly better there (`agreement::disagreement`) — or
/// better at all when the verification names scans of the first and none
/// of the restart's; or
/// run when the schedule failed (a stage moved two scans apart that
/// overlapped at their starts, a match lost every correspondence), and
/// kept when it succeeds; or run when the first registration's links
/// disagree more than their covariances allow ([`Trigger::Disagreeing`]),
/// or when a pair the verification matched again still creeps at its cap
/// and the scans agree no better than at their starts
/// ([`Trigger::Creeping`]), and kept as after a move. On narrow overlaps a
/// coarse stage can drag good starts away: small_gicp's outdoor frame cut
/// into 150° wedges, from starts 0.1 m / 2° off, ended 1–77° and 1.1–10 m
/// off in 5 of 10 trials with the auto schedule (first cell 0.7 m, a
/// street's 60° overlaps a few cells wide), and right in all 10 without
/// its first stage.
#[derive(Debug, Clone, PartialEq)]
pub struct Restart {
    /// The scan that moved furthest from its start in the first
    /// registration, or that its failure names.
    pub scan: Option<usize>,
    /// How far it moved, metres (the centroid's displacement plus the turn
    /// times the points' RMS radius about it); `None` when the first
    /// registration failed.
    pub moved_m: Option<f64>,
    /// Why the first registration failed (a stage moved two scans apart,
    /// a match lost every correspondence).
    pub schedule_error: Option<String>,
    /// The restart's stages.
    pub stages: Vec<StageRun>,
    /// The scans' disagreement at the first registration's poses and at
    /// the restart's, m² a point (`agreement::disagreement`); `None` for one
    /// that failed.
    pub disagreement_m2: (Option<f64>, Option<f64>),
    /// The scans' disagreement at their starts, m² a point: a result the
    /// scans agree with no better sets off the [`further`](Self::further)
    /// restarts, or names its long moves ([`unsupported`](Self::unsupported)).
    /// `None` only without a stage to measure it at (since session 57 also
    /// after a schedule that failed).
    pub starts_disagreement_m2: Option<f64>,
    /// Why the restart failed.
    pub error: Option<String>,
    /// True when the restart's registration is the result.
    pub kept: bool,
    /// What set it off.
    pub trigger: Trigger,
    /// The scans the verification names at the first registration's poses
    /// ([`SetResult::named`]; `None` when it failed) and at the
    /// restart's (`None` when the restart failed, or was neither kept nor
    /// needed verifying: the first registration was possible, and no scan
    /// was [`undecided`](Self::undecided) between them).
    pub untrusted: (Option<Vec<usize>>, Option<Vec<usize>>),
    /// The scans the schedule's and the restart's registrations place
    /// apart — by more than the verification lets a pair move
    /// ([`MAX_RELATIVE_MOTION`](crate::verify::MAX_RELATIVE_MOTION) of
    /// the scan's radius) — when the scans' disagreement prefers neither by
    /// [`RESTART_RATIO`]: (scan, how far apart in metres — the centroid's
    /// displacement plus the turn times the radius —, the turn in
    /// radians). The data cannot tell which registration is right, so
    /// these scans are not trusted (the one the scans agree with better is
    /// kept). Also the scans a [`repeated`](Self::repeated) schedule's
    /// result and a shorter schedule's the scans agree with better place
    /// apart, where that one is kept. Empty otherwise.
    pub undecided: Vec<(usize, f64, f64)>,
    /// True when the [`undecided`](Self::undecided) scans are not named
    /// after all: every further restart (at least one ran; after a
    /// [`repeated`](Self::repeated) schedule, every other from the first
    /// that left the schedule's place) landed where
    /// the registration kept — the one the scans agree with better —
    /// places them (no scan apart from it, as `undecided` measures). Of
    /// the two registrations, that one is reached again from the starts by
    /// every shorter schedule; the other only by the schedule (or the
    /// restart) whose coarse stage dragged it. Measured in every
    /// undecided case met (the street's wedges of the e2e test and of the
    /// NEES bench's seeds 7 and 17, the room's wedges of its seed 13):
    /// the registration reached again was the right one (each
    /// part within 0.1° and 5 mm; seed 7's all-source parts 0.03° and
    /// 1.6 mm RMS), and was named before with exit 1.
    pub corroborated: bool,
    /// True when the restart only repeated the schedule: a scan moved
    /// beyond the second stage's reach ([`Trigger::Moved`]), and the
    /// restart, not kept, landed where the schedule did (no scan
    /// [`MAX_RELATIVE_MOTION`](crate::verify::MAX_RELATIVE_MOTION) of its
    /// radius apart). The second stage may drag as the first did, so
    /// every [`further`](Self::further) restart runs until one is kept.
    /// Found on the NEES bench's seed 31 (the street's wedges,
    /// simultaneous mode, trial 5): the schedule and the restart both left
    /// three wedges 1.3° and 2.6 m off together, nothing named, exit 0;
    /// the schedule without its first two stages landed them within 0.02°,
    /// the scans agreeing 1.58× better. A shorter schedule that lands
    /// where the schedule did is no corroboration — its own coarse stage
    /// may drag as far (seed 71, graph mode, trial 0: the schedule without
    /// its first two stages left three wedges 2.4° and 1.8 m off with the
    /// schedule, nothing named; the last two stages and the finest alone
    /// landed them within 0.03° and 4 mm, the scans agreeing 1.45× better,
    /// under the 1.5×). Where none is kept and one lands apart from the
    /// schedule's result with a better agreement, however slight, the two
    /// are judged as [`undecided`](Self::undecided) scans are: the better
    /// (the best of those apart), verified, is kept — then the scans the
    /// two place apart are undecided, corroborated only when every other
    /// shorter schedule from the first that left the schedule's place
    /// (at least one) lands where it does (seed 71's: kept, corroborated,
    /// exit 0).
    pub repeated: bool,
    /// True when the result before the [`further`](Self::further)
    /// restarts — the schedule's, or the restart's where it was kept — has
    /// links that disagree beyond [`GROSS_VARIANCE_FACTOR`]: the further
    /// restarts then run, and one the scans agree with better, however
    /// slightly, whose links do not disagree so and that the verification
    /// names nothing of is kept, as in place of a named result.
    pub disagreeing_links: bool,
    /// The scans the result moved from their starts beyond the finest
    /// stage's reach (its correspondence distance), where the scans agree
    /// with the result not clearly better than with their starts
    /// ([`starts_disagreement_m2`](Self::starts_disagreement_m2) times
    /// [`SUPPORT_RATIO`]): (scan,
    /// how far in metres — the centroid's displacement plus the turn times
    /// its points' RMS radius). The finest stage alone finds a fit within
    /// its reach of the starts; a move beyond it a coarser stage decided,
    /// and a result the scans agree with no better than with their starts
    /// is no evidence for it — these scans are not trusted. Measured: the
    /// building example in simultaneous mode (façades seen at grazing
    /// angles from starts within 4 mm of the truth): every registration
    /// slid scans 0.3–4.6 m along the walls, the kept one agreeing 1.010×
    /// worse than the starts, exit 0; in incremental mode one scan 0.56 m
    /// (1.002×); with the corner test off, in incremental mode, scan009
    /// 1.22 m at 0.9963× ([`SUPPORT_RATIO`]). Right results agreed better
    /// than their starts wherever a restart ran (0.44–0.82× on the
    /// street's and the room's wedges from rough starts; 0.96–0.9971× on
    /// the simulated hall and the 3DTK set,
    /// 0.80× on the corridor); the 3DTK set's graph mode, 0.9999×, moves
    /// no scan beyond its reach (0.08 m of 0.20). Empty otherwise.
    pub unsupported: Vec<(usize, f64)>,
    /// Further restarts from the starts, each without one more of the
    /// schedule's stages (the first without its first two — without its
    /// first after the pipe's restart, [`degeneracy_ratio`](Self::degeneracy_ratio)
    /// —, …, the last with the finest stage alone), run in turn while the result is not
    /// to be trusted — the verification names some of its scans, the
    /// restart left some [`undecided`](Self::undecided), the scans
    /// agree no better there than at their starts
    /// ([`starts_disagreement_m2`](Self::starts_disagreement_m2); not
    /// clearly better, [`SUPPORT_RATIO`], where it moved a scan beyond
    /// the finest stage's reach), or its links disagree beyond
    /// [`GROSS_VARIANCE_FACTOR`] ([`disagreeing_links`](Self::disagreeing_links)) — and
    /// the schedule has more than two stages: a restart's second stage can
    /// drag scans as the schedule's first did. One is kept, in place of all before
    /// it, when the scans agree [`RESTART_RATIO`] times better there than
    /// at the best registration so far (or the schedule's result was
    /// impossible and the verification names nothing of it); then
    /// [`kept`](Self::kept) is false and nothing is undecided, and they go
    /// on only while it is not to be trusted. A trusted result runs none
    /// (the 3DTK set — its scans disagree 0.9993× as much as at its
    /// odometry's poses —: no cost; the simulated corridor, 0.80×, runs
    /// them because its restart repeats the schedule,
    /// [`repeated`](Self::repeated)). On the
    /// bench's 30 street and room wedge trials (below) whose restart ran,
    /// the schedule's right results agreed 0.44–0.82× as much as at the
    /// starts, its wrong ones 0.85–1.66×. Measured
    /// on small_gicp's street cut into 150° wedges from starts 0.1 m / 2°
    /// off (16 trials, `NEES_PARTS=2` of `fusion/benches/covariance_nees.py`,
    /// graph mode): in one the schedule and the restart both left three
    /// wedges 2.6 m off together (one named undecided, exit 1) and the
    /// schedule's finest two stages alone landed them within 2 mm, the
    /// scans agreeing 1.6× better; in another both slid a wedge 1.2 m along
    /// the street, the scans agreeing 1.11× worse than at the starts (and,
    /// where the parts' scanner positions are known, named by free space),
    /// and the schedule without its first two stages landed it within
    /// 1 mm, the scans agreeing 2.0× better. Last, when the result is
    /// still named only by moves along what only the starts hold
    /// ([`SetResult::named_only_held`]), the whole schedule with a pipe's
    /// threshold ([`Further::degeneracy_ratio`]). Empty when none ran,
    /// and after a schedule that failed ([`Trigger::Failed`]: the restart
    /// alone).
    pub further: Vec<Further>,
    /// The blind-direction threshold the restart ran with where it is not
    /// the set's: the whole schedule from the starts with a pipe's
    /// ([`crate::links::PIPE_DEGENERACY_RATIO`], the line test on), in
    /// place of the schedule without its first stage, when the schedule's
    /// result is named only by moves along what only the starts hold
    /// ([`SetResult::named_only_held`]) and a simultaneous queue of it was
    /// abandoned at its cap: the queue chased a slide the data do not
    /// hold, and each shorter schedule would chase it again from the same
    /// starts (the sewer example's, simultaneous mode: the restart and
    /// both shorter schedules abandoned at the cap and named, 150 s of
    /// 190; the pipe's threshold settled in 2.4 s, within 3 mm of the
    /// truth). Kept where the verification names nothing of it and the
    /// scans agree with it within [`RESTART_RATIO`] of the schedule's
    /// result; else the [`further`](Self::further) restarts begin with
    /// the schedule without its first stage. `None` for the usual
    /// restart.
    pub degeneracy_ratio: Option<f64>,
}

/// A further restart from the starts ([`Restart::further`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Further {
    /// Its stages as they ran (empty when it failed).
    pub stages: Vec<StageRun>,
    /// The scans' disagreement at its poses, m² a point
    /// (`agreement::disagreement`); `None` when it failed.
    pub disagreement_m2: Option<f64>,
    /// Why it failed.
    pub error: Option<String>,
    /// True when its registration is the result.
    pub kept: bool,
    /// The scans the verification names at its poses; `None` when it
    /// failed or was not verified (verified only where it may be kept).
    pub untrusted: Option<Vec<usize>>,
    /// The blind-direction threshold it ran with where it is not the
    /// set's: the whole schedule from the starts with a pipe's
    /// ([`crate::links::PIPE_DEGENERACY_RATIO`], the line test on), run
    /// last when the result is still named only by moves along what only
    /// the starts hold ([`SetResult::named_only_held`]). `None` for the
    /// shorter schedules.
    pub degeneracy_ratio: Option<f64>,
    /// The largest move of a scan from its start at its poses, metres (as
    /// [`Restart::moved_m`] measures the schedule's); `None` when it
    /// failed.
    pub moved_m: Option<f64>,
    /// Kept as nearer the starts: the result before it the scans agreed
    /// with no better than with their starts, and this one — named nothing
    /// of by the verification, every scan tied by an agreeing pair
    /// ([`SetResult::all_tied`]), the scans agreeing with it within
    /// [`RESTART_RATIO`] of the best — moves them less.
    pub nearer_starts: bool,
}

/// What sets a [`Restart`] off.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trigger {
    /// The schedule moved a scan beyond the second stage's reach of its
    /// start.
    Moved,
    /// The schedule failed.
    Failed,
    /// The schedule's result put points in another scanner's free space
    /// (and moved no scan beyond the second stage's reach).
    Untrusted,
    /// The schedule's links disagree with one another more than their own
    /// covariances allow (the set's variance factor — the link graph's, or
    /// the verification's matches' in the other modes — above
    /// [`RESTART_VARIANCE_FACTOR`]), and nothing above set it off.
    Disagreeing,
    /// The verification names scans of the schedule's result
    /// ([`crate::verify::untrusted`]), and nothing above set it off: two
    /// street wedges 3.5° off together, the verification's variance factor
    /// below 1 (matched again, a pair's residual fell 3.1×:
    /// [`crate::verify::MAX_RESIDUAL_GAIN`]); the restart landed them.
    Named,
    /// A pair the verification matched again stopped at its iteration cap
    /// still moving beyond the finest voxel, and the scans agree with the
    /// schedule's result no better than with their starts (not clearly
    /// better, where it moved a scan beyond the finest stage's reach:
    /// [`SUPPORT_RATIO`]); nothing above set it off. The street's wedges
    /// (the NEES bench's, starts 0.1 m / 2° off) at the corner test's
    /// default: the schedule slid a wedge
    /// 1.2 m along the street, its link to a partner was rejected at the
    /// cap — the links left were a tree, σ̂₀² 1 — and the verification's
    /// match of that pair crept 0.83 m and 3.7°, within every tier of a
    /// weak slide: exit 0, nothing named; a further restart lands it.
    /// (Right pairs creep too — the simulated corridor's along its axis,
    /// a pipe's about and along it —, but there the scans agree better
    /// than at their starts.)
    Creeping,
    /// A simultaneous queue of the schedule was abandoned at its cap
    /// ([`StageRun::settled`] false), and nothing above set it off: the
    /// queue stopped while its scans were still moving, wherever they
    /// had got to. The NEES bench's seed 41 (the street's wedges,
    /// simultaneous mode, trial 7): the first stage, abandoned after 174
    /// runs, left three wedges 1.43 m along the street together, within
    /// the second stage's reach, nothing named, the variance factor below
    /// 1 — exit 0; the schedule without that stage landed them.
    Abandoned,
    /// The schedule moved a scan beyond the finest stage's reach of its
    /// start (its correspondence distance), and the scans agree with its
    /// result not clearly better than with their starts ([`SUPPORT_RATIO`]);
    /// nothing above set it off.
    /// The check [`Restart::unsupported`] makes of every restart's result,
    /// made of a schedule's that set off nothing else: a move the data
    /// give no evidence for is tried again, and named when no restart
    /// does better. (The NEES bench's seed 41 trial above: the abandoned
    /// stage's result agreed 1.42× worse than the starts.)
    Unsupported,
}

/// A set whose variance factor σ̂₀² is above this sets off a restart
/// ([`Trigger::Disagreeing`]): its links disagree more than they should,
/// as when the first stage dragged scans into a wrong fit within the
/// second stage's reach (small_gicp's street cut into wedges: three wedges
/// 3.1–3.2° off together, 0.45–0.71 m of motion, in graph and in pairwise
/// mode; without the first stage 0.001–0.04° off). Right registrations of
/// parts of one scan give 0.03–0.8 on shares and up to 5.7 on wedges;
/// real sets of different viewpoints more (the 3DTK set about 370), where
/// the restart costs its finer stages once more and is kept only by the
/// disagreement rule ([`RESTART_RATIO`]).
pub const RESTART_VARIANCE_FACTOR: f64 = 1.0;

/// A result whose links disagree beyond this variance factor σ̂₀² is in
/// doubt as a named one is ([`Restart::disagreeing_links`]): the further
/// restarts run, and one the scans agree with better, however slightly,
/// whose links do not disagree so and that the verification names
/// nothing of takes its place. Measured (session 74): right registrations
/// give 0.03–0.8 on parts of one scan's shares, 1–17 on a room's wedges
/// (the NEES bench's seed 103, graph mode, eight trials), 273 on the
/// 3DTK set's three viewpoints in every mode (370–470 as first
/// measured); the room's wedges of seed 103's trial 3, which the
/// schedule's second stage dragged 29–89 mm and 0.1–0.5° off (the
/// restart without the first stage landing there too): 37,116, their σ
/// 0.47–0.68 m carrying it, exit 0 — the schedule without its first two
/// stages landed them within 8 mm, σ̂₀² 14, the scans agreeing 1.12×
/// better (under the restart's 1.5×).
pub const GROSS_VARIANCE_FACTOR: f64 = 1000.0;

/// The restart is kept when the first registration's poses put points in
/// another scanner's free space and the verification names none of the
/// restart's; otherwise when the first registration's disagreement is
/// more than this many times the restart's. Measured: registrations a coarse
/// stage dragged into a wrong fit disagree 2.2–3.1× as much as the right
/// ones (the street wedges; the room's wedges from 1 m / 10°: 2.9×); two
/// wrong fits differ by up to 1.12× (the room's wedges in simultaneous
/// mode: the restart lands in another wrong fit, which the schedule's
/// verification had named) and two right ones in the sixth digit; on the
/// 3DTK set from `--init global` (its starts up to 4 m off) the restart
/// lands 0.2° from the schedule's fit, both within the reference's
/// uncertainty, disagreeing 1.02× less — a nearby minimum, not a rescue.
pub const RESTART_RATIO: f64 = 1.5;

/// A rescue — a registration kept in place of one the verification named,
/// itself named nothing of — gives way to a further restart the
/// verification names nothing of either when the scans agree this many
/// times better there: a rescue is not trusted as a schedule's own
/// unnamed result is (the 1.5× of [`RESTART_RATIO`]), but the same fit
/// reached again agrees alike to the sixth digit and a nearby minimum
/// 1.02× ([`RESTART_RATIO`]'s measurements). Measured: the street's
/// wedges in pairwise mode, a rescue with two wedges 3.1° off, the right
/// registration 1.19× better (since the verification names that fit
/// itself, [`crate::verify::MAX_RESIDUAL_GAIN`], a guard no measured case
/// needs).
pub const RESCUE_RATIO: f64 = 1.05;

/// Whether a restart set off by the schedule's result ([`Trigger`]:
/// moved, impossible — points in free space —, or disagreeing) is the
/// result: when the schedule's result was impossible and the
/// verification names nothing of the restart's (`named_after`, verified
/// only then), or when the schedule's disagreement (`before`, m² a point)
/// is more than [`RESTART_RATIO`] times the restart's (`after`; `None`
/// when the restart failed).
fn keeps_restart(impossible: bool, named_after: Option<&[usize]>, before: f64, after: Option<f64>) -> bool {
    match after {
        None => false,
        Some(_) if impossible && named_after.is_some_and(<[usize]>::is_empty) => true,
        Some(a) => before > RESTART_RATIO * a,
    }
}

/// Whether the whole schedule with a pipe's threshold — the restart
/// ([`Restart::degeneracy_ratio`]) or the last further restart — is the
/// result: the verification names nothing of it (`named`; `None` when it
/// failed) and the scans agree with it (`a`) within [`RESTART_RATIO`] of
/// the best so far, better or not (along what the data do not hold, their
/// agreement is no evidence).
fn keeps_pipe(named: Option<&[usize]>, a: Option<f64>, best: f64) -> bool {
    named.is_some_and(<[usize]>::is_empty) && a.is_some_and(|a| a <= RESTART_RATIO * best)
}

/// Whether a further restart may take the place of the result so far as
/// nearer the starts: the result so far is `doubtful` — the scans agree
/// with it no better than with their starts, or it moved scans beyond
/// the finest stage's reach and they agree with it not clearly better
/// ([`unsupported`]): its moves are no evidence of the data's —, they
/// agree with this one (`a`) within
/// [`RESTART_RATIO`] of the best so far, and it moves no scan as far from
/// its start (`moved` against `current_moved`, metres). Whether the
/// verification names nothing of it and ties every scan by an agreeing
/// pair ([`SetResult::all_tied`]) is asked after (it is verified where
/// this holds): a scan no pair reaches would give way to its start (the
/// room pair with a 1 mm last stage, whose coarse stages landed it from
/// an odometry guess 0.69 m off). Measured: the building example's own
/// scans, a façade 20 m a station seen at grazing angles from 7.5 m — its
/// sparse columns'
/// normals (a line's, PCA's plane across the wall) rough the
/// point-to-plane cost along the wall with a minimum every 0.25 m —:
/// the coarse stages slid the scans 0.1–0.5 m along the walls from starts
/// within 4 mm of the truth (the CPS's), the scans agreeing no better
/// there (4.69e-2 m² a point against 4.67e-2 at the starts), exit 0 with
/// σ 43–121 mm (BENCHMARKS.md, "Agreeing no better than the starts").
fn keeps_nearer_starts(doubtful: bool, a: f64, best: f64, moved: f64, current_moved: f64) -> bool {
    doubtful && a <= RESTART_RATIO * best && moved < current_moved
}

/// How far `poses` move each scan but the first from its start
/// (`starts`), metres: its centroid's displacement plus the turn times
/// its points' RMS radius (`shapes`, each scan's centroid and radius).
fn moves_from_starts(
    shapes: &[(Point3<f64>, f64)],
    starts: &[Isometry3<f64>],
    poses: &[Isometry3<f64>],
) -> Vec<(usize, f64)> {
    (1..shapes.len().min(starts.len()).min(poses.len()))
        .map(|i| (i, crate::se3::motion(&(starts[i].inverse() * poses[i]), &shapes[i].0, shapes[i].1)))
        .collect()
}

/// A move beyond the finest stage's reach of a scan's start is
/// supported by the data only where the scans agree with the result
/// better than this times with their starts (m² a point): a coarser
/// stage decided it, and a fit a hair better than the starts is what a
/// slide along a wall gives as well. Measured: the building example in
/// incremental mode with the corner test off, a restart that slid
/// scan009 1.22 m along its façade, the scans agreeing 0.9963× as much
/// as with their starts (4.6521e-2 against 4.6695e-2), named nothing —
/// exit 0; right results with such moves agreed 0.44–0.82× (the street's
/// and the room's wedges from rough starts) and 0.80× (the corridor's
/// long moves from odometry), and the 3DTK set's 0.9999× and the hall's
/// 0.96–0.9971× move no scan beyond the finest reach.
pub const SUPPORT_RATIO: f64 = 0.99;

/// The scans a result moved (`moves`: scan, metres from its start)
/// beyond `reach` (the finest stage's correspondence distance), when the
/// scans agree with it (`agreement`, m² a point) not clearly better than
/// with their starts (`at_starts`, by [`SUPPORT_RATIO`]): a move the data
/// give no evidence for ([`Restart::unsupported`]).
fn unsupported(moves: Vec<(usize, f64)>, reach: f64, agreement: f64, at_starts: f64) -> Vec<(usize, f64)> {
    if agreement < SUPPORT_RATIO * at_starts {
        return Vec::new();
    }
    moves.into_iter().filter(|&(_, m)| m > reach).collect()
}

/// What one stage of the schedule did.
#[derive(Debug, Clone, PartialEq)]
pub struct StageRun {
    /// Its voxel, metres.
    pub voxel_m: f64,
    /// Its correspondence distance, metres.
    pub max_correspondence_m: f64,
    /// ICP runs in it (in graph mode's last stage: the links matched).
    pub matches: usize,
    /// Its wall-clock time, seconds.
    pub seconds: f64,
    /// False when a simultaneous queue was abandoned at its cap.
    pub settled: bool,
}

/// One match of the final stage.
#[derive(Debug, Clone, PartialEq)]
pub struct SetLink {
    /// The scan that was matched.
    pub source: usize,
    /// The scans it was matched against.
    pub targets: Vec<usize>,
    /// Correspondences at the start of the match (graph mode).
    pub overlap: Option<usize>,
    /// The match, when ICP ran to the end.
    pub result: Option<IcpResult>,
    /// Why it is not used; `None` when it is.
    pub rejected: Option<String>,
    /// The cycle of used links a link disagreeing with the others closes
    /// (graph mode; [`crate::links::Link::cycle`]): rejected, or kept when
    /// the set cannot tell which of the cycle's links is wrong.
    pub cycle: Option<crate::links::Cycle>,
}

/// Registers `scans` (each in its own frame) from `starts`, their guessed
/// `world_from_scan`. `progress(stage, stages, done, total)` is called as
/// scans (and, in graph mode, pairs: stage = stages) are matched.
pub fn register_set<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    starts: &[Isometry3<f64>],
    config: &SetConfig,
    progress: &mut dyn FnMut(usize, usize, usize, usize),
) -> Result<SetResult> {
    // The finest matches reported with the covariance model calibrated
    // on these scans (the coarser stages' matches only steer) — in every
    // mode since the covariance by pair and the edges' pull carry them
    // (with the information alone the modes without a link graph were
    // 1.3–2.7× optimistic calibrated, against 0.55–2.8× without:
    // BENCHMARKS.md, "Covariances the data calibrate"). Matched both ways
    // (as `link.both_ways` says), as the matches that carry the
    // covariances are: graph mode's links, the other modes' verification
    // ([`verified`]). The calibration multiplies the caller's own scale.
    let started = std::time::Instant::now();
    let noise = finest_link(config).map(|(_, link)| crate::noise::calibrate(scans, &link.multiview, link.both_ways));
    let noise_seconds = started.elapsed().as_secs_f64();
    let mut calibrated = config.clone();
    calibrated.link.multiview.icp.noise_scale *= noise.map_or(1.0, |n| n.variance_scale);
    calibrated.link.range_scale *= noise.map_or(1.0, |n| n.range_scale);
    if let Some(n) = noise {
        calibrated.link.range_blocks = (n.rotation_scale / n.range_scale, n.translation_scale / n.range_scale);
    }
    calibrated.link.asymmetry = noise.map(|n| n.asymmetry).filter(|a| *a > 0.0).or(config.link.asymmetry);
    calibrated.link.calibration_dof = noise.map_or(config.link.calibration_dof, |n| n.dof);
    let config = &calibrated;
    let r = registered(scans, starts, config, progress)?;
    Ok(SetResult { noise, noise_seconds, ..r })
}

fn registered<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    starts: &[Isometry3<f64>],
    config: &SetConfig,
    progress: &mut dyn FnMut(usize, usize, usize, usize),
) -> Result<SetResult> {
    let Some(world_from_first) = starts.first().copied() else {
        return register_in_first_frame(scans, starts, config, progress);
    };
    // The first start exactly the identity, so the first scan comes back
    // exactly where its start puts it.
    let local: Vec<Isometry3<f64>> = std::iter::once(Isometry3::identity())
        .chain(starts[1..].iter().map(|s| world_from_first.inverse() * s))
        .collect();
    let r = match register_in_first_frame(scans, &local, config, progress) {
        Ok(r) => restart_if_dragged(scans, &local, config, verified(scans, &local, r, config)?, progress)?,
        // A stage moved two scans apart, or a match lost its partner: the
        // restart without the first stage may not. (Where the starts
        // themselves do not overlap, or the input is at fault, the restart
        // fails too and the schedule's error stands.)
        Err(e) if config.stages.len() > 1 => restart_after_failure(scans, &local, config, e, progress)?,
        Err(e) => return Err(e),
    };
    Ok(into_world(r, &world_from_first, config.mode == Mode::Graph))
}

/// `r` with its verification ([`verify_set`]) and the time it took; with
/// each scan's move from its start (`starts`) along what only the start
/// holds — in graph mode what it reports blind ([`held_move`]), in the
/// others what its matches hold less than the start does
/// ([`held_by_start`]); in
/// the modes without a link graph also with the variance factor and the
/// covariances of the verification's matches adjusted together, plus the
/// poses' departure from them ([`crate::links::adjust_matches`]): a
/// strategy places each scan against partners held and stops short of
/// where all its pairs agree, and its matches lean one way. With each
/// scan's last match and its partners' covariances (averaged) instead,
/// the mean NEES of these modes on real scans' parts was up to 10.7 on
/// shares and 12.6 on wedges (6 when honest; 252 for a simultaneous
/// compromise 0.68° off); so, 2.6–8.3 over five draws, as graph mode's
/// 2.8–8.7 (BENCHMARKS).
fn verified<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    starts: &[Isometry3<f64>],
    mut r: SetResult,
    config: &SetConfig,
) -> Result<SetResult> {
    let started = std::time::Instant::now();
    let PairChecks { pairs, shared } = verify_set(scans, &r.world_from_scan, config)?;
    r.checks = pairs;
    let graph = config.mode == Mode::Graph;
    let adjusted = !graph && !r.checks.is_empty();
    let tolerance = finest_link(config).map_or(0.0, |(finest, _)| finest.voxel_m);
    // Each scan's points' centroid and RMS radius, where a move of it is
    // measured: the departures' and the held moves' metric.
    let lever: Vec<(Point3<f64>, f64)> = if adjusted || (graph && r.unobservable.iter().any(|u| !u.is_empty())) {
        scans.par_iter().map(|s| crate::icp::degeneracy::centroid_and_lever_arm(s.as_ref())).collect()
    } else {
        Vec::new()
    };
    let mut steps = None;
    if adjusted {
        let (mut edges, mut noise, mut pulls) = (Vec::new(), Vec::new(), Vec::new());
        for c in &r.checks {
            if let (Some(e), Some(n)) = (c.edge, c.edge_covariance) {
                edges.push(e);
                noise.push(n);
                pulls.push(c.pull);
            }
        }
        // A pairwise pose is placed on one partner's match, the others on
        // several partners' ([`crate::links::Departures`]).
        let departures = if config.mode == Mode::Pairwise {
            crate::links::Departures::Whole
        } else {
            crate::links::Departures::BeyondNoise
        };
        let a = crate::links::adjust_matches(
            &r.world_from_scan,
            &edges,
            &noise,
            &pulls,
            &shared,
            &config.link,
            departures,
        )?;
        r.variance_factor = Some(a.variance_factor);
        r.lean_variance_factor = a.lean_variance_factor;
        r.redundancy = Some(a.redundancy);
        r.noise_factor = Some(a.noise_factor);
        r.covariance = a.covariance;
        r.joint_covariance = Some(a.joint_covariance);
        r.sampling = a.sampling;
        r.pairs_rest = a.pairs_rest;
        r.departure = a.departure;
        r.departure_chi2 = a.departure_chi2;
        r.departure_weight = Some(a.departure_weight);
        r.departure_m = lever
            .par_iter()
            .zip(&r.world_from_scan)
            .zip(&r.departure)
            .map(|((&(c, radius), pose), d)| {
                // pose = exp(ξ)·adjusted: exp(ξ) moves the points from the
                // adjustment's place to the pose's, in the world's frame.
                let step = crate::se3::exp(d);
                crate::se3::motion(&step, &(step.inverse() * (pose * c)), radius)
            })
            .collect();
        r.departed = departed_scans(&r.departure_chi2, &r.departure_m, tolerance);
        steps = Some(crate::links::steps_covariance(&r.world_from_scan, &config.link));
    }
    // A pair named by its residual's gain alone, within the σ of its
    // poses' relative pose (without the pairs' rest), agrees after all.
    if let Some(joint) = &r.joint_covariance {
        let narrow = r.pairs_rest.as_ref().map(|rest| joint.less(rest));
        crate::verify::weigh_residual_gains(&mut r.checks, &r.world_from_scan, narrow.as_ref().unwrap_or(joint));
    }
    // Each scan's move along what only its start holds: in graph mode
    // what its links report blind, in the others what its matches hold
    // no better than the start (after the adjustment).
    if !lever.is_empty() {
        r.held = (0..scans.len())
            .into_par_iter()
            .map(|i| {
                let (Some(pose), Some(start), Some(c)) = (r.world_from_scan.get(i), starts.get(i), r.covariance.get(i))
                else {
                    return Held::default();
                };
                if i == 0 {
                    return Held::default();
                }
                // Judged without the scans' sampling and the pairs' rest,
                // as the departures are.
                let c = &crate::links::judged_covariance(c, &r.sampling, r.pairs_rest.as_ref(), i);
                let (centroid, radius) = &lever[i];
                match &steps {
                    Some(steps) => held_by_start(pose, start, c, &steps[i], centroid, *radius, tolerance),
                    None => {
                        let blind = r.unobservable.get(i).map_or(&[][..], Vec::as_slice);
                        held_move(pose, start, blind, c, centroid, *radius, tolerance)
                    }
                }
            })
            .collect();
    }
    r.check_seconds = started.elapsed().as_secs_f64();
    Ok(r)
}

/// The scans (after the first, which holds the frame) whose departure
/// from where their verified pairs agree is beyond
/// [`MAX_DEPARTURE_CHI2`](crate::verify::MAX_DEPARTURE_CHI2) in that
/// agreement's σ (`chi2`) and moves their points (`moved_m`) by more than
/// `tolerance_m` ([`SetResult::departed`]).
fn departed_scans(chi2: &[f64], moved_m: &[f64], tolerance_m: f64) -> Vec<usize> {
    (1..chi2.len().min(moved_m.len())).filter(|&i| departs(chi2[i], moved_m[i], tolerance_m)).collect()
}

/// Whether a departure of `chi2` in its adjustment's σ, moving the scan's
/// points by `moved_m`, names the scan: beyond
/// [`MAX_DEPARTURE_CHI2`](crate::verify::MAX_DEPARTURE_CHI2) and beyond
/// `tolerance_m` (the finest voxel).
pub fn departs(chi2: f64, moved_m: f64, tolerance_m: f64) -> bool {
    chi2 > crate::verify::MAX_DEPARTURE_CHI2 && moved_m > tolerance_m
}

/// The set's final poses checked against its data at the finest stage,
/// the tolerance its voxel ([`crate::verify::check_pairs`]).
fn verify_set<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    poses: &[Isometry3<f64>],
    config: &SetConfig,
) -> Result<PairChecks> {
    let Some((finest, link)) = finest_link(config) else { return Ok(PairChecks::default()) };
    // Both ways where the covariances rest on these matches, one way
    // where the link graph's carry them ([`crate::verify::check_pairs`]).
    let link = LinkConfig { both_ways: link.both_ways && config.mode != Mode::Graph, ..link };
    crate::verify::check_pairs(scans, poses, &config.viewpoints, &link, finest.voxel_m)
}

/// The registration from the starts without the schedule's first stage,
/// after the schedule failed with `failure` (a stage moved two scans
/// apart, a match found no correspondence); that failure when the restart
/// fails too.
fn restart_after_failure<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    starts: &[Isometry3<f64>],
    config: &SetConfig,
    failure: FusionError,
    progress: &mut dyn FnMut(usize, usize, usize, usize),
) -> Result<SetResult> {
    let scan = match &failure {
        FusionError::NoOverlap { scan, .. } | FusionError::InScan { scan, .. } => Some(*scan),
        _ => None,
    };
    let Ok(r) = without_first(scans, starts, config, 1, progress) else { return Err(failure) };
    let mut r = verified(scans, starts, r, config)?;
    // The scans' agreement with the restart and with their starts, and
    // the moves the one no better than the other does not support.
    let agreement = finest_link(config).and_then(|(finest, link)| {
        let prepared = crate::multiview::prepare(scans, &link.multiview).ok()?;
        let tau = finest.max_correspondence_m;
        let (after, at_starts) = (
            crate::agreement::disagreement(&prepared, &r.world_from_scan, tau),
            crate::agreement::disagreement(&prepared, starts, tau),
        );
        let shapes: Vec<(Point3<f64>, f64)> =
            scans.iter().map(|s| crate::icp::degeneracy::centroid_and_lever_arm(s.as_ref())).collect();
        let unsupported = unsupported(moves_from_starts(&shapes, starts, &r.world_from_scan), tau, after, at_starts);
        Some((after, at_starts, unsupported))
    });
    let (after, at_starts, unsupported) = agreement.map_or((None, None, Vec::new()), |(a, s, u)| (Some(a), Some(s), u));
    r.restart = Some(Restart {
        scan,
        moved_m: None,
        schedule_error: Some(failure.to_string()),
        stages: std::mem::take(&mut r.stages),
        disagreement_m2: (None, after),
        starts_disagreement_m2: at_starts,
        error: None,
        kept: true,
        trigger: Trigger::Failed,
        untrusted: (None, Some(r.named())),
        undecided: Vec::new(),
        corroborated: false,
        repeated: false,
        disagreeing_links: false,
        unsupported,
        further: Vec::new(),
        degeneracy_ratio: None,
    });
    Ok(r)
}

/// The registration from `starts` with the schedule of `config` less its
/// first `skip` stages: the restart's (1, [`Restart`]) and the further
/// restarts' ([`Restart::further`]).
fn without_first<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    starts: &[Isometry3<f64>],
    config: &SetConfig,
    skip: usize,
    progress: &mut dyn FnMut(usize, usize, usize, usize),
) -> Result<SetResult> {
    let shorter = SetConfig { stages: config.stages[skip..].to_vec(), ..config.clone() };
    register_in_first_frame(scans, starts, &shorter, progress)
}

/// `config` with a pipe's blind-direction threshold
/// ([`crate::links::PIPE_DEGENERACY_RATIO`]) and, point-to-plane, the
/// line test ([`crate::links::DEFAULT_LINE_RATIO`] unless one is set);
/// `None` where its threshold is that already or above, or off (the
/// user's choice).
fn pipe_config(config: &SetConfig) -> Option<SetConfig> {
    let icp = &config.link.multiview.icp;
    icp.degeneracy_ratio.filter(|&r| r < crate::links::PIPE_DEGENERACY_RATIO)?;
    let mut pipe = config.clone();
    let held = &mut pipe.link.multiview.icp;
    held.degeneracy_ratio = Some(crate::links::PIPE_DEGENERACY_RATIO);
    if held.method == crate::icp::Method::PointToPlane {
        held.line_ratio = held.line_ratio.or(Some(crate::links::DEFAULT_LINE_RATIO));
    }
    Some(pipe)
}

/// The finest stage and the link settings at it.
fn finest_link(config: &SetConfig) -> Option<(Stage, LinkConfig)> {
    let finest = *config.stages.last()?;
    let multiview = &config.link.multiview;
    let link = LinkConfig {
        multiview: MultiviewConfig {
            source_voxel_m: finest.voxel_m,
            target_voxel_m: finest.voxel_m,
            icp: crate::icp::IcpConfig {
                max_correspondence_m: finest.max_correspondence_m,
                only_covered: config.only_covered,
                ..multiview.icp
            },
            ..*multiview
        },
        ..config.link
    };
    Some((finest, link))
}

/// `first` (verified), or — when it moved a scan from its start
/// (`starts`, the first scan's frame) beyond the second stage's
/// correspondence distance, put points in another scanner's free space,
/// or its links disagree more than their covariances allow, or a pair
/// of its verification creeps at its cap and the scans agree no better
/// with it than with their starts — the
/// registration from the starts without the schedule's first
/// stage, if `first` is impossible and the verification names nothing of
/// it, or the scans agree clearly better there — or at all, where the
/// verification names scans of `first` and none of it ([`Restart`]).
fn restart_if_dragged<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    starts: &[Isometry3<f64>],
    config: &SetConfig,
    first: SetResult,
    progress: &mut dyn FnMut(usize, usize, usize, usize),
) -> Result<SetResult> {
    let Some((finest, link)) = finest_link(config).filter(|_| config.stages.len() > 1) else { return Ok(first) };
    // Each scan's centroid and RMS radius, and how far poses move it from
    // its start (its centroid displaced plus the turn times the radius).
    let shapes: Vec<(Point3<f64>, f64)> =
        scans.iter().map(|s| crate::icp::degeneracy::centroid_and_lever_arm(s.as_ref())).collect();
    let moves = |poses: &[Isometry3<f64>]| moves_from_starts(&shapes, starts, poses);
    let largest_move = |poses: &[Isometry3<f64>]| moves(poses).into_iter().map(|(_, m)| m).fold(0.0, f64::max);
    let Some((scan, moved_m)) = moves(&first.world_from_scan).into_iter().max_by(|a, b| a.1.total_cmp(&b.1)) else {
        return Ok(first);
    };
    let named = first.named();
    // Points in another scanner's free space: the schedule's poses are
    // physically impossible, not merely in doubt.
    let impossible = first.checks.iter().any(crate::verify::PairCheck::violates_free_space);
    let Some(trigger) = trigger_of(&first, moved_m, impossible, &named, &config.stages[1], &finest) else {
        return Ok(first);
    };
    let prepared = crate::multiview::prepare(scans, &link.multiview)?;
    let tau = finest.max_correspondence_m;
    let before = crate::agreement::disagreement(&prepared, &first.world_from_scan, tau);
    let at_starts = crate::agreement::disagreement(&prepared, starts, tau);
    // (Whether the scans agree with a result no better than with their
    // starts, or it moved scans beyond the finest stage's reach and they
    // agree with it not clearly better: [`unsupported`].)
    let doubtful =
        |poses: &[Isometry3<f64>], a: f64| a >= at_starts || !unsupported(moves(poses), tau, a, at_starts).is_empty();
    if matches!(trigger, Trigger::Creeping | Trigger::Unsupported) && !doubtful(&first.world_from_scan, before) {
        return Ok(first);
    }
    // A registration verified, with the scans its verification names.
    let verify = |r: SetResult| -> Result<(SetResult, Vec<usize>)> {
        let r = verified(scans, starts, r, config)?;
        let named = r.named();
        Ok((r, named))
    };
    // Named only by moves along what only the starts hold, with a
    // simultaneous queue abandoned at its cap on the way: the queue chased
    // a slide the data do not hold (a pipe's scans along its axis), and
    // every shorter schedule runs the same queue from the same starts
    // along the same slide (the sewer example's: the restart and both
    // shorter schedules abandoned at the cap and named, 150 s of its 190;
    // the pipe's threshold settled in 2.4 s within 3 mm of the truth). The
    // restart is then the whole schedule with a pipe's threshold — what
    // the pipe's fallback runs last otherwise ([`Restart::degeneracy_ratio`]).
    let pipe_first = pipe_config(config).filter(|_| first.named_only_held() && first.stages.iter().any(|s| !s.settled));
    let restart_config = pipe_first.as_ref().unwrap_or(config);
    // The restart is verified where its verdict decides (an impossible
    // first result, a named one, the pipe's) or where it is kept: a
    // verification of a large set costs as much as its last stage.
    let (mut second, error) =
        match without_first(scans, starts, restart_config, usize::from(pipe_first.is_none()), progress) {
            Ok(r) => (Some(r), None),
            Err(e) => (None, Some(e.to_string())),
        };
    let mut named_after = None;
    if impossible && pipe_first.is_none() {
        (second, named_after) = second.take().map(verify).transpose()?.unzip();
    }
    let after = second.as_ref().map(|r| crate::agreement::disagreement(&prepared, &r.world_from_scan, tau));
    // (The pipe's restart verified with its own threshold, as the
    // pipe's last further restart is.)
    if let Some(pipe) = &pipe_first {
        let r = second.take().map(|r| verified(scans, starts, r, pipe)).transpose()?;
        named_after = r.as_ref().map(SetResult::named);
        second = r;
    }
    // An impossible result gives way to one the verification names
    // nothing of (the disagreement may prefer the impossible: a slide
    // lays floors and walls on each other); else the disagreement decides.
    // (Only free space, not a doubt: the room's wedges trapped 90° off
    // were named by their motion, and a restart that landed them in
    // another wrong fit, 41° off, was named by nothing.)
    let mut kept = match &pipe_first {
        Some(_) => keeps_pipe(named_after.as_deref(), after, before),
        None => keeps_restart(impossible, named_after.as_deref(), before, after),
    };
    // Two registrations that place a scan apart, the verification naming
    // nothing of either and neither clearly the one the scans agree with:
    // the data cannot tell which is right (small_gicp's street cut into
    // wedges of disjoint points: the schedule left three wedges 5.9° off
    // together, the restart landed them within 0.05°, and the scans agreed
    // only 1.42× better there; the verification's matches, along what they
    // see weakly, named nothing — exit 0). Those scans are named, and the
    // better agreement kept. Where the verification names the restart's
    // scans the data do tell (the 3DTK set from `--init global`: a restart
    // 1.02× better put scan002 in the others' free space), and where it
    // names the schedule's the exit is 1 already.
    let mut restart_verified = impossible || pipe_first.is_some();
    let mut undecided = Vec::new();
    if let (Some(r), Some(a)) = (&second, after)
        && !impossible
        && pipe_first.is_none()
        && !kept
        && named.is_empty()
        && before <= RESTART_RATIO * a
        && a <= RESTART_RATIO * before
    {
        let far = apart(&shapes, &first.world_from_scan, &r.world_from_scan);
        if !far.is_empty() {
            (second, named_after) = second.take().map(verify).transpose()?.unzip();
            restart_verified = true;
            if named_after.as_ref().is_some_and(Vec::is_empty) {
                undecided = far;
                kept = a < before;
            }
        }
    }
    // A result the verification names gives way to one the scans agree
    // with better, however slightly, that it names nothing of: the 1.5×
    // guards a trusted result against a nearby fit, and this one is not
    // trusted (the room's wedges, 8 trials of the NEES bench, trial 5:
    // two wedges 1.8 m off, one named, and three stages from the starts
    // landed all four, the scans agreeing 1.33× better). Such a rescue
    // is itself in doubt — the verification misses a slide along what
    // its pairs see weakly (the room's wedges from 1 m / 10° in
    // simultaneous mode: a restart 1.12× better, one wedge 1.4 m off,
    // nothing named) — so the further restarts still run after it.
    let mut rescued = false;
    if let (Some(a), false, false) = (after, kept, named.is_empty())
        && a < before
        && pipe_first.is_none()
    {
        if !restart_verified {
            (second, named_after) = second.take().map(verify).transpose()?.unzip();
            restart_verified = true;
        }
        kept = named_after.as_ref().is_some_and(Vec::is_empty);
        rescued = kept;
    }
    if kept && !restart_verified {
        (second, named_after) = second.take().map(verify).transpose()?.unzip();
    }
    // While the result is not to be trusted — the verification names some
    // of its scans, the restart left some undecided, or the scans agree no
    // better there than at the starts — the schedule without one more
    // stage at a time ([`Restart::further`]), each held to the best
    // registration so far and verified where it may be kept. A trusted
    // result costs nothing more.
    let (mut further, mut spent, mut alone) = (Vec::new(), (0, 0.0), None);
    let mut best = after.map_or(before, |a| a.min(before));
    // (A kept restart has its disagreement and its verification.)
    let in_doubt = |named: &[usize], doubtful: bool| !named.is_empty() || doubtful;
    // The scans the verification names of the result so far, and whether
    // only by their moves along what only their starts hold.
    let mut current_named = if kept { named_after.clone().unwrap_or_default() } else { named.clone() };
    let mut only_held =
        if kept { second.as_ref().is_some_and(SetResult::named_only_held) } else { first.named_only_held() };
    // The result so far: the scans' disagreement there, its largest move
    // from the starts, and whether it is doubtful.
    let (mut current_a, mut current_moved, mut current_doubtful) = match (&second, after) {
        (Some(r), Some(a)) if kept => (a, largest_move(&r.world_from_scan), doubtful(&r.world_from_scan, a)),
        _ => (before, moved_m, doubtful(&first.world_from_scan, before)),
    };
    // Whether a result's links disagree grossly ([`GROSS_VARIANCE_FACTOR`]),
    // and the result so far's: in doubt as a named one is.
    let gross = |r: &SetResult| r.variance_factor.is_some_and(|f| f > GROSS_VARIANCE_FACTOR);
    let mut current_gross = if kept { second.as_ref().is_some_and(gross) } else { gross(&first) };
    // (Reported where it sets the further restarts off: not after the
    // pipe's restart, kept.)
    let disagreeing_links = current_gross && !(kept && pipe_first.is_some());
    // (The pipe's restart kept: held by the starts along what its matches
    // find blind, the scans' agreement no evidence there.)
    let mut doubted = !(kept && pipe_first.is_some())
        && (in_doubt(&current_named, current_doubtful) || !undecided.is_empty() || rescued || current_gross);
    // The restart only repeated the schedule's long move ([`Restart::repeated`]):
    // the further restarts run until one lands there too or is kept.
    let repeated = trigger == Trigger::Moved
        && !kept
        && pipe_first.is_none()
        && undecided.is_empty()
        && second.as_ref().is_some_and(|r| apart(&shapes, &first.world_from_scan, &r.world_from_scan).is_empty());
    // A repeated schedule is not corroborated by a shorter one landing
    // there too — that one's own coarse stage may drag as far (the NEES
    // bench's seed 71, the street's wedges in graph mode, trial 0: the
    // schedule, the restart and the schedule without its first two stages
    // all left three wedges 2.4° and 1.8 m off together, nothing named;
    // the last two stages, and the finest alone, landed them within 0.03°
    // and 4 mm, the scans agreeing 1.45× better). Every shorter schedule
    // runs (until one is kept), and each one's poses are kept: where one
    // lands apart from the schedule's result and the scans agree with it
    // better, the two are judged as undecided scans are (below).
    let mut checking = repeated;
    // (Each further restart's poses while `checking`, and whether they
    // lie apart from the schedule's; `None` for one that failed.)
    let mut landed: Vec<Option<(Vec<Isometry3<f64>>, bool)>> = Vec::new();
    // (The one the scans agree with best of those apart and better than
    // the schedule's: its place in `further`, its disagreement, and it
    // with the scans its verification names, if it ran.)
    let mut candidate: Option<(usize, f64, SetResult, Option<Vec<usize>>)> = None;
    // Where scans are undecided: how many further restarts landed where
    // the registration kept places them, and whether any did not.
    let (mut reached_again, mut strayed) = (0usize, false);
    // (After the pipe's restart, the schedule without its first stage is
    // the first of them.)
    for skip in usize::from(pipe_first.is_none()) + 1..config.stages.len() {
        if !doubted && !checking {
            break;
        }
        let report = match without_first(scans, starts, config, skip, progress) {
            Ok(f) => {
                let a = crate::agreement::disagreement(&prepared, &f.world_from_scan, tau);
                // Whether it lands where the registration kept places
                // undecided scans: that counts for (or against) them.
                if !undecided.is_empty() {
                    let current = alone.as_ref().or(second.as_ref().filter(|_| kept)).unwrap_or(&first);
                    if apart(&shapes, &current.world_from_scan, &f.world_from_scan).is_empty() {
                        reached_again += 1;
                    } else {
                        strayed = true;
                    }
                }
                let away = checking && !apart(&shapes, &first.world_from_scan, &f.world_from_scan).is_empty();
                // Named, the result so far gives way to a better agreement
                // the verification names nothing of (as the restart's);
                // itself a rescue, to one [`RESCUE_RATIO`] better (the
                // street's wedges in pairwise mode, seed 7: the restart
                // rescued a named schedule with two wedges 3.1° off along
                // what their link cannot see, nothing named, and a further
                // restart the scans agreed with 1.19× better was passed
                // over by the 1.5×).
                // Named only by such moves, it gives way to one the
                // verification names nothing of within [`RESTART_RATIO`]
                // of the best agreement, better or not: along what the
                // data hold no better than the starts their agreement is
                // no evidence (a pipe's scans, slid 74–184 mm along its
                // axis in graph mode, agreed 1.05× better than where the
                // finest stage alone left them, within 29 mm of the truth
                // and of their σ there).
                // Its links disagreeing grossly, it gives way alike to a
                // better agreement whose links do not.
                let f_gross = gross(&f);
                let rescue = (!current_named.is_empty() && a < best)
                    || (rescued && RESCUE_RATIO * a < best)
                    || (only_held && a <= RESTART_RATIO * best)
                    || (current_gross && !f_gross && a < best);
                let f_moved = largest_move(&f.world_from_scan);
                let nearer = keeps_nearer_starts(current_doubtful, a, best, f_moved, current_moved);
                let (f, named) = if impossible || rescue || nearer || best > RESTART_RATIO * a {
                    let (f, named) = verify(f)?;
                    (f, Some(named))
                } else {
                    (f, None)
                };
                let f_only_held = f.named_only_held();
                let f_tied = f.all_tied();
                spent = (spent.0 + f.matches, spent.1 + f.check_seconds);
                let by_ratio = keeps_restart(impossible, named.as_deref(), best, Some(a));
                let by_rescue = !by_ratio && rescue && named.as_ref().is_some_and(Vec::is_empty);
                let by_nearer =
                    !by_ratio && !by_rescue && nearer && f_tied && named.as_ref().is_some_and(Vec::is_empty);
                let report = Further {
                    stages: f.stages.clone(),
                    disagreement_m2: Some(a),
                    error: None,
                    kept: by_ratio || by_rescue || by_nearer,
                    untrusted: named,
                    degeneracy_ratio: None,
                    moved_m: Some(f_moved),
                    nearer_starts: by_nearer,
                };
                best = best.min(a);
                if report.kept {
                    checking = false;
                    (current_a, current_moved) = (a, f_moved);
                    current_doubtful = doubtful(&f.world_from_scan, a);
                    current_named = report.untrusted.clone().unwrap_or_default();
                    only_held = f_only_held;
                    rescued = by_rescue;
                    current_gross = f_gross;
                    doubted = by_rescue || in_doubt(&current_named, current_doubtful) || current_gross;
                    (kept, undecided, alone) = (false, Vec::new(), Some(f));
                } else if checking {
                    landed.push(Some((f.world_from_scan.clone(), away)));
                    if away && a < before && candidate.as_ref().is_none_or(|c| a < c.1) {
                        candidate = Some((further.len(), a, f, report.untrusted.clone()));
                    }
                }
                report
            }
            Err(e) => {
                // (No registration reached again: no corroboration.)
                strayed |= !undecided.is_empty();
                if checking {
                    landed.push(None);
                }
                Further {
                    stages: Vec::new(),
                    disagreement_m2: None,
                    error: Some(e.to_string()),
                    kept: false,
                    untrusted: None,
                    degeneracy_ratio: None,
                    moved_m: None,
                    nearer_starts: false,
                }
            }
        };
        further.push(report);
    }
    // A repeated schedule no further restart was kept over, where one
    // landed apart from it and the scans agree with that one better
    // (however slightly): two registrations the data cannot choose
    // between by the 1.5×, as undecided scans are. The better agreement
    // is kept if its verification names nothing, and the scans the two
    // place apart are undecided — corroborated only when every other
    // shorter schedule from the first that landed apart (at least one)
    // lands where it does. (One the verification names is wrong: the
    // schedule's result stands.)
    if let Some((k, a, f, named)) = candidate.filter(|_| checking) {
        let (f, named) = match named {
            Some(named) => (f, named),
            None => verify(f)?,
        };
        if named.is_empty() {
            let from = landed.iter().position(|l| l.as_ref().is_some_and(|l| l.1)).unwrap_or(k);
            for (_, l) in landed.iter().enumerate().skip(from).filter(|(j, _)| *j != k) {
                match l {
                    Some((poses, _)) if apart(&shapes, &f.world_from_scan, poses).is_empty() => reached_again += 1,
                    _ => strayed = true,
                }
            }
            undecided = apart(&shapes, &first.world_from_scan, &f.world_from_scan);
            further[k].kept = true;
            current_a = a;
            only_held = false;
            alone = Some(f);
        }
        further[k].untrusted = Some(named);
    }
    // Still named only by moves along what only the starts hold — a
    // pipe at the default threshold, whose finest stage alone still slides
    // some scans in the modes without a link graph —: the whole schedule
    // once more from the starts with a pipe's threshold, where the matches
    // find those directions blind and the starts hold them (what the
    // message names as the remedy). Kept where the verification names
    // nothing of it and the scans agree with it within [`RESTART_RATIO`]
    // of the best (along what the data do not hold, their agreement is no
    // evidence).
    if let Some(pipe) = pipe_config(config).filter(|_| only_held && pipe_first.is_none()) {
        let ratio = pipe.link.multiview.icp.degeneracy_ratio;
        let report = match without_first(scans, starts, &pipe, 0, progress).and_then(|f| {
            let a = crate::agreement::disagreement(&prepared, &f.world_from_scan, tau);
            Ok((verified(scans, starts, f, &pipe)?, a))
        }) {
            Ok((f, a)) => {
                let named = f.named();
                spent = (spent.0 + f.matches, spent.1 + f.check_seconds);
                let report = Further {
                    stages: f.stages.clone(),
                    disagreement_m2: Some(a),
                    error: None,
                    kept: keeps_pipe(Some(&named), Some(a), best),
                    untrusted: Some(named),
                    degeneracy_ratio: ratio,
                    moved_m: Some(largest_move(&f.world_from_scan)),
                    nearer_starts: false,
                };
                if report.kept {
                    current_a = a;
                    (kept, undecided, alone) = (false, Vec::new(), Some(f));
                }
                report
            }
            Err(e) => Further {
                stages: Vec::new(),
                disagreement_m2: None,
                error: Some(e.to_string()),
                kept: false,
                untrusted: None,
                degeneracy_ratio: ratio,
                moved_m: None,
                nearer_starts: false,
            },
        };
        further.push(report);
    }
    let stages = second.as_ref().map_or_else(Vec::new, |r| r.stages.clone());
    let ran = || [Some(&first), second.as_ref()].into_iter().flatten();
    let matches = ran().map(|r| r.matches).sum::<usize>() + spent.0;
    let check_seconds = ran().map(|r| r.check_seconds).sum::<f64>() + spent.1;
    let mut restart = Restart {
        scan: Some(scan),
        moved_m: Some(moved_m),
        schedule_error: None,
        stages,
        disagreement_m2: (Some(before), after),
        starts_disagreement_m2: Some(at_starts),
        error,
        kept,
        trigger,
        untrusted: (Some(named), named_after),
        corroborated: !undecided.is_empty() && reached_again > 0 && !strayed,
        repeated,
        disagreeing_links,
        undecided,
        unsupported: Vec::new(),
        further,
        degeneracy_ratio: pipe_first.and_then(|p| p.link.multiview.icp.degeneracy_ratio),
    };
    let mut r = match (second.take(), alone.take()) {
        (_, Some(a)) => SetResult { stages: first.stages, ..a },
        (Some(s), _) if kept => SetResult { stages: first.stages, ..s },
        _ => first,
    };
    restart.unsupported = unsupported(moves(&r.world_from_scan), tau, current_a, at_starts);
    r.matches = matches;
    r.check_seconds = check_seconds;
    r.restart = Some(restart);
    Ok(r)
}

/// What the schedule's result `first` sets off, the first that applies
/// of [`Trigger`]'s (`moved_m`: its largest move of a scan from its
/// start; `impossible`: it puts points in another scanner's free space;
/// `named`: the scans its verification names; `second` and `finest`: the
/// schedule's second and finest stages); `None` for a result that sets
/// off nothing. (Creeping and
/// unsupported moves restart only where the scans agree with the result
/// no better than with their starts, which the caller measures.) Within
/// the second stage's reach of its start the restart would begin where
/// the schedule's first stage had no say — unless the result is
/// impossible: then the restart may land where the first stage would not
/// let it.
fn trigger_of(
    first: &SetResult,
    moved_m: f64,
    impossible: bool,
    named: &[usize],
    second: &Stage,
    finest: &Stage,
) -> Option<Trigger> {
    Some(if moved_m > second.max_correspondence_m {
        Trigger::Moved
    } else if impossible {
        Trigger::Untrusted
    } else if first.variance_factor.is_some_and(|f| f > RESTART_VARIANCE_FACTOR) {
        Trigger::Disagreeing
    } else if !named.is_empty() {
        Trigger::Named
    } else if first.checks.iter().any(|c| c.converged == Some(false) && c.moved_m.is_some_and(|m| m > finest.voxel_m)) {
        Trigger::Creeping
    } else if first.stages.iter().any(|s| !s.settled) {
        Trigger::Abandoned
    } else if moved_m > finest.max_correspondence_m {
        Trigger::Unsupported
    } else {
        return None;
    })
}

/// The scans that `a` and `b` (two registrations' `world_from_scan`)
/// place apart by more than the verification lets a pair move: the
/// points' centroid displaced plus the turn times their RMS radius beyond
/// [`MAX_RELATIVE_MOTION`](crate::verify::MAX_RELATIVE_MOTION) of the
/// radius (a turn alone beyond 0.05 rad, within the verification's
/// [`MAX_TURN_RAD`](crate::verify::MAX_TURN_RAD)); each with that motion
/// (metres) and turn (radians). `shapes`: each scan's centroid and RMS
/// radius, as [`moves_from_starts`] takes them.
fn apart(shapes: &[(Point3<f64>, f64)], a: &[Isometry3<f64>], b: &[Isometry3<f64>]) -> Vec<(usize, f64, f64)> {
    (1..shapes.len())
        .filter_map(|i| {
            let (c, radius) = shapes[i];
            let delta = a[i].inverse() * b[i];
            let angle = delta.rotation.angle();
            let moved = crate::se3::motion(&delta, &c, radius);
            (moved > crate::verify::MAX_RELATIVE_MOTION * radius).then_some((i, moved, angle))
        })
        .collect()
}

/// A set's result moved from the first scan's frame into the world by
/// `world_from_first`: poses composed; covariances and blind directions
/// turned into the world's axes but left about the first scan's origin
/// (the adjoint of the rotation alone: carried to the world's origin, a
/// set at national-grid coordinates would report the rotations' lever arm
/// over 5,500 km as metres of position σ); and — outside graph mode, whose
/// links are relative — each last match's result in the world.
fn into_world(mut r: SetResult, world_from_first: &Isometry3<f64>, graph: bool) -> SetResult {
    let ad = adjoint(&Isometry3::from_parts(nalgebra::Translation3::identity(), world_from_first.rotation));
    r.world_from_scan.iter_mut().for_each(|p| *p = world_from_first * *p);
    r.covariance.iter_mut().for_each(|c| *c = ad * *c * ad.transpose());
    r.joint_covariance = r.joint_covariance.map(|j| j.turned(&ad));
    r.sampling.iter_mut().for_each(|c| *c = ad * *c * ad.transpose());
    r.pairs_rest = r.pairs_rest.map(|j| j.turned(&ad));
    r.departure.iter_mut().for_each(|d| *d = ad * *d);
    r.unobservable.iter_mut().flatten().for_each(|d| *d = (ad * *d).normalize());
    r.held.iter_mut().flat_map(|h| &mut h.along).for_each(|d| *d = (ad * *d).normalize());
    if !graph {
        for l in &mut r.links {
            l.result = l.result.take().map(|m| in_world(m, world_from_first));
        }
    }
    r
}

fn register_in_first_frame<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    starts: &[Isometry3<f64>],
    config: &SetConfig,
    progress: &mut dyn FnMut(usize, usize, usize, usize),
) -> Result<SetResult> {
    if config.stages.is_empty() {
        return Err(FusionError::OutOfRange {
            what: "stages of the schedule".into(),
            value: 0.0,
            expected: "at least one VOXEL/DISTANCE".into(),
        });
    }
    let strategy = match config.mode {
        Mode::Pairwise => Strategy::Pairwise,
        Mode::Incremental => Strategy::Incremental,
        Mode::Simultaneous => Strategy::Simultaneous,
        // The link graph at the finest stage makes the set consistent: its
        // coarser stages only need to bring each scan into the finer
        // stage's reach (see the module docs).
        Mode::Graph => Strategy::Pairwise,
    };
    let finest = config.stages.last().map_or(1.0, |s| s.voxel_m);
    let finest_stage = config.stages.len() - 1;
    let stage_config = |k: usize, s: &Stage| MultiviewConfig {
        strategy,
        source_voxel_m: s.voxel_m,
        target_voxel_m: s.voxel_m,
        icp: crate::icp::IcpConfig {
            max_correspondence_m: s.max_correspondence_m,
            only_covered: config.only_covered && k == finest_stage,
            // The finest matches carry their pull by the pairs past the
            // other scan's edge and their covariance by pair into the
            // covariances (`links`, `placed_covariances`).
            edge_bias: k == finest_stage,
            range_noise: k == finest_stage,
            noise_scale: if k == finest_stage { config.link.multiview.icp.noise_scale } else { 1.0 },
            ..config.link.multiview.icp
        },
        // Fewer reduced points at a coarse stage give fewer pairs: the
        // overlap threshold scales with the cell's area.
        min_pairs: scaled_min_pairs(config.link.multiview.min_pairs, s.voxel_m, finest),
        ..config.link.multiview
    };
    let stages = config.stages.len();
    // Graph mode matches its finest stage in the link graph.
    let multiview_stages = &config.stages[..stages - usize::from(config.mode == Mode::Graph)];
    let mut poses = starts.to_vec();
    let mut matches = 0;
    let mut settled = true;
    let mut last = None;
    let mut runs = Vec::with_capacity(stages);
    for (k, stage) in multiview_stages.iter().enumerate() {
        let started = std::time::Instant::now();
        let r = register_views(scans, &poses, &stage_config(k, stage), &mut |done, total| {
            progress(k + 1, stages, done, total)
        })
        .map_err(|e| match e {
            FusionError::NoOverlap { scan, pairs, needed, against, partner, .. } => {
                FusionError::NoOverlap { scan, pairs, needed, against, partner, stage: Some(k + 1) }
            }
            e => e,
        })?;
        runs.push(StageRun {
            voxel_m: stage.voxel_m,
            max_correspondence_m: stage.max_correspondence_m,
            matches: r.matches,
            seconds: started.elapsed().as_secs_f64(),
            settled: r.settled,
        });
        poses.clone_from(&r.world_from_scan);
        matches += r.matches;
        settled &= r.settled;
        last = Some(r);
    }
    if config.mode == Mode::Graph {
        let link = LinkConfig { multiview: stage_config(finest_stage, &config.stages[finest_stage]), ..config.link };
        // The coarse stages' poses hold what no link sees: along a blind
        // direction the (degeneracy-aware) coarse matches left each scan
        // where the start put it, and a scan no fine link reaches keeps
        // the coarse registration.
        let started = std::time::Instant::now();
        let g = crate::links::adjust(scans, &poses, &poses, &link, &mut |done, total| {
            progress(stages, stages, done, total)
        })?;
        let finest = config.stages.last().expect("a stage");
        runs.push(StageRun {
            voxel_m: finest.voxel_m,
            max_correspondence_m: finest.max_correspondence_m,
            matches: g.links.iter().filter(|l| l.result.is_some()).count(),
            seconds: started.elapsed().as_secs_f64(),
            settled: true,
        });
        return Ok(from_graph(g, matches, settled, runs));
    }
    let last = last.expect("at least one stage");
    let n = scans.len();
    let links: Vec<SetLink> = (0..n)
        .filter_map(|i| {
            last.last_match[i].as_ref().map(|m| SetLink {
                source: i,
                targets: last.partners[i].clone(),
                overlap: None,
                result: Some(m.clone()),
                rejected: None,
                cycle: None,
            })
        })
        .collect();
    let covariance = placed_covariances(n, &links, &config.link.step_information(), &config.link);
    Ok(SetResult {
        world_from_scan: poses,
        covariance,
        joint_covariance: None,
        sampling: Vec::new(),
        pairs_rest: None,
        departure: Vec::new(),
        departure_chi2: Vec::new(),
        departure_weight: None,
        departure_m: Vec::new(),
        departed: Vec::new(),
        held: Vec::new(),
        unobservable: last
            .last_match
            .iter()
            .map(|m| m.as_ref().map_or_else(Vec::new, |m| m.unobservable.clone()))
            .collect(),
        links,
        matches,
        settled,
        variance_factor: None,
        lean_variance_factor: None,
        redundancy: None,
        noise_factor: None,
        stages: runs,
        checks: Vec::new(),
        check_seconds: 0.0,
        noise: None,
        noise_seconds: 0.0,
        restart: None,
    })
}

/// The covariances of `n` scans each placed by its last match (`links`:
/// the modes without a link graph), plus its partners' — until the
/// verification gives the pairs' own ([`verified`]). A match's own is
/// graph mode's link model ([`crate::links`]): its covariance by pair
/// (`range_scale` and `range_blocks`, the calibration's factors on it)
/// plus its edges' pull δδᵀ (beyond its noise:
/// [`crate::links::beyond_noise`]), and along what it cannot see the
/// start's step (`step`, an information); without the covariance by
/// pair (point-to-point), its information held by `step` where it sees
/// nothing. (No variance factor: the verification's, which judges these
/// matches, replaces these covariances whole.) A scan is placed on its
/// partners, which are uncertain themselves: to first order
/// (independent errors, world-frame left perturbations) a partner's
/// error moves the scan with it, so its covariance adds to the match's —
/// the mean over several partners (a metascan's), in scan order (a later
/// partner, in simultaneous mode, with its own match's alone).
/// The match's alone made the single-strategy modes' covariances 10–100×
/// optimistic on chains of partial overlaps (mean NEES 86–1,100 on
/// wedges); with the link model, calibrated, their mean NEES on real
/// scans' parts came within 1.6× of 6 (BENCHMARKS).
fn placed_covariances(n: usize, links: &[SetLink], step: &Matrix6<f64>, link: &LinkConfig) -> Vec<Matrix6<f64>> {
    let mut covariance = vec![Matrix6::zeros(); n];
    for l in links {
        if let Some(m) = &l.result {
            covariance[l.source] = match m.range_covariance {
                // Nothing of it along the blind directions (projected
                // out): there the start's step's variance.
                Some(c) => {
                    let bias = crate::links::Pull::of(m, link).bias;
                    crate::links::range_noise(&c, m, link)
                        + step_within(&m.unobservable, step)
                        + bias * bias.transpose()
                }
                // The information's inverse along what it sees, the start's
                // step σ along what it cannot.
                None => m.covariance_held(step),
            };
        }
    }
    // Scan 0 holds the frame: it inherits nothing.
    for l in links.iter().filter(|l| l.source > 0 && l.result.is_some() && !l.targets.is_empty()) {
        let inherited = l.targets.iter().map(|&p| covariance[p]).sum::<Matrix6<f64>>() / l.targets.len() as f64;
        covariance[l.source] += inherited;
    }
    covariance
}

/// The start's step variance within the span of the blind `directions`:
/// Q·(Qᵀ·step·Q)⁻¹·Qᵀ, Q an orthonormal basis of the span (d·dᵀ / dᵀ·step·d
/// for one direction d) — no inversion of the whole.
fn step_within(directions: &[Vector6<f64>], step: &Matrix6<f64>) -> Matrix6<f64> {
    let q = orthonormal(directions);
    if q.is_empty() {
        return Matrix6::zeros();
    }
    let q = nalgebra::Matrix6xX::from_columns(&q);
    (q.transpose() * step * &q).try_inverse().map_or_else(Matrix6::zeros, |a| &q * a * q.transpose())
}

fn from_graph(g: LinkGraph, matches: usize, settled: bool, stages: Vec<StageRun>) -> SetResult {
    let matches = matches + g.links.iter().filter(|l| l.result.is_some()).count();
    SetResult {
        world_from_scan: g.world_from_scan,
        covariance: g.covariance,
        joint_covariance: Some(g.joint_covariance),
        sampling: g.sampling,
        pairs_rest: g.pairs_rest,
        departure: Vec::new(),
        departure_chi2: Vec::new(),
        departure_weight: None,
        departure_m: Vec::new(),
        departed: Vec::new(),
        held: Vec::new(),
        unobservable: g.unobservable,
        links: g
            .links
            .into_iter()
            .map(|l| SetLink {
                source: l.source,
                targets: vec![l.target],
                overlap: Some(l.overlap),
                result: l.result,
                rejected: l.rejected,
                cycle: l.cycle,
            })
            .collect(),
        matches,
        settled,
        variance_factor: Some(g.variance_factor),
        lean_variance_factor: g.lean_variance_factor,
        redundancy: Some(g.redundancy),
        noise_factor: Some(g.noise_factor),
        stages,
        checks: Vec::new(),
        check_seconds: 0.0,
        noise: None,
        noise_seconds: 0.0,
        restart: None,
    }
}

/// `min_pairs` at a stage of cell `voxel_m` when it holds at the finest
/// cell `finest_m` (at least 6, the unknowns of a pose).
fn scaled_min_pairs(min_pairs: usize, voxel_m: f64, finest_m: f64) -> usize {
    let ratio = (finest_m / voxel_m).min(1.0);
    ((min_pairs as f64 * ratio * ratio).round() as usize).max(6)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A schedule's result that is possible gives way when the scans agree
    /// clearly better at the restart (street wedges dragged 1.45 m along
    /// the street: 1.03e-2 against 3.8e-3 m² — kept by nothing in a first
    /// version of this rule, exit 0), an impossible one when the
    /// verification names nothing of the restart even if the disagreement
    /// prefers the impossible (the 3DTK slide: 2.2e-2 against 2.9e-2), and a
    /// failed restart never.
    #[test]
    fn a_restart_is_kept_by_clearly_better_agreement_or_by_free_space() {
        assert!(keeps_restart(false, None, 1.03e-2, Some(3.8e-3)));
        assert!(!keeps_restart(false, None, 1.03e-2, Some(0.9e-2)));
        assert!(keeps_restart(true, Some(&[]), 2.2e-2, Some(2.9e-2)));
        assert!(!keeps_restart(true, Some(&[2]), 2.2e-2, Some(2.9e-2)));
        assert!(keeps_restart(true, Some(&[2]), 2.2e-2, Some(1.0e-2)));
        assert!(!keeps_restart(false, None, 1.0, None));
        assert!(!keeps_restart(true, Some(&[]), 1.0, None));
    }

    /// A further restart takes the result's place as nearer the starts
    /// only where the result is doubtful (its moves unsupported), the
    /// scans agree with it within 1.5× of the best and it moves the scans
    /// less (the building's scans: 4.720e-2 against the best 4.691e-2 and
    /// the starts' 4.670e-2, 0.13 m against 0.72 m).
    #[test]
    fn a_result_no_better_than_the_starts_gives_way_to_one_nearer_them() {
        let best = 4.691e-2;
        assert!(keeps_nearer_starts(true, 4.720e-2, best, 0.13, 0.72));
        // The result agreed clearly better than the starts: its moves are
        // evidence.
        assert!(!keeps_nearer_starts(false, 4.720e-2, 4.60e-2, 0.13, 0.72));
        // Beyond 1.5× of the best, or moving a scan as far.
        assert!(!keeps_nearer_starts(true, 7.1e-2, best, 0.13, 0.72));
        assert!(!keeps_nearer_starts(true, 4.720e-2, best, 0.72, 0.72));
    }

    /// Two registrations place a scan apart when they move its points (the
    /// centroid's displacement plus the turn times their RMS radius) by
    /// more than 5 % of that radius — a turn alone beyond 0.05 rad; scan
    /// 0, the frame, never.
    #[test]
    fn registrations_are_apart_beyond_what_a_reverified_pair_may_move() {
        // A ring of radius 2 m about (10, 0, 0): RMS radius 2 m, 5 % = 0.1 m.
        let ring: Vec<Point3<f32>> = (0..360)
            .map(|k| {
                let a = (k as f32).to_radians();
                Point3::new(10.0 + 2.0 * a.cos(), 2.0 * a.sin(), 0.0)
            })
            .collect();
        let scans = [ring.clone(), ring.clone(), ring.clone(), ring];
        let a = vec![Isometry3::identity(); 4];
        let shift = |m: f64| Isometry3::translation(m, 0.0, 0.0);
        // A turn about the scan's origin, 10 m from its points: 1° moves
        // the centroid 0.175 m.
        let turn = |deg: f64| Isometry3::rotation(nalgebra::Vector3::z() * deg.to_radians());
        let b = vec![shift(5.0), shift(0.09), shift(0.11), turn(1.0)];
        let shapes: Vec<(Point3<f64>, f64)> =
            scans.iter().map(|s| crate::icp::degeneracy::centroid_and_lever_arm(s)).collect();
        let far = apart(&shapes, &a, &b);
        let named: Vec<usize> = far.iter().map(|f| f.0).collect();
        assert_eq!(named, [2, 3]);
        assert!((far[0].1 - 0.11).abs() < 1e-6, "{far:?}");
        let one = 1f64.to_radians();
        assert!((far[1].1 - (10.0 * 2.0 * (one / 2.0).sin() + 2.0 * one)).abs() < 1e-5, "{far:?}");
        assert!((far[1].2 - one).abs() < 1e-9, "{far:?}");
        // A turn about the centroid itself: apart beyond 0.05 rad (2.9°).
        let about =
            |deg: f64| Isometry3::translation(10.0, 0.0, 0.0) * turn(deg) * Isometry3::translation(-10.0, 0.0, 0.0);
        let c = apart(&shapes, &a, &[Isometry3::identity(), about(2.8), about(-3.0), about(2.0)]);
        assert_eq!(c.iter().map(|f| f.0).collect::<Vec<_>>(), [2]);
    }

    /// A result the scans agree with not clearly better than with their
    /// starts (within 1 %) names the scans it moved beyond the finest
    /// stage's reach; one they agree with clearly better, none.
    #[test]
    fn moves_the_scans_agree_with_no_better_than_their_starts_are_unsupported() {
        let moves = vec![(1, 0.2), (2, 4.6), (3, 0.43)];
        assert_eq!(unsupported(moves.clone(), 0.428, 4.718e-2, 4.670e-2), [(2, 4.6), (3, 0.43)]);
        assert_eq!(unsupported(moves.clone(), 0.428, 4.670e-2, 4.670e-2), [(2, 4.6), (3, 0.43)]);
        // The building's scan009 slid 1.22 m, the scans agreeing 0.9963×.
        assert_eq!(unsupported(moves.clone(), 0.428, 4.6521e-2, 4.6695e-2), [(2, 4.6), (3, 0.43)]);
        assert!(unsupported(moves.clone(), 0.428, 4.622e-2, 4.670e-2).is_empty());
        assert!(unsupported(moves, 5.0, 4.718e-2, 4.670e-2).is_empty());
    }

    /// A result of `n` scans at the identity, nothing verified, nothing
    /// restarted.
    fn bare(n: usize) -> SetResult {
        SetResult {
            world_from_scan: vec![Isometry3::identity(); n],
            covariance: vec![Matrix6::identity(); n],
            joint_covariance: None,
            sampling: Vec::new(),
            pairs_rest: None,
            departure: Vec::new(),
            departure_chi2: Vec::new(),
            departure_weight: None,
            departure_m: Vec::new(),
            departed: Vec::new(),
            held: Vec::new(),
            unobservable: vec![Vec::new(); n],
            links: Vec::new(),
            matches: 0,
            settled: true,
            variance_factor: None,
            lean_variance_factor: None,
            redundancy: None,
            noise_factor: None,
            stages: Vec::new(),
            checks: Vec::new(),
            check_seconds: 0.0,
            noise: None,
            noise_seconds: 0.0,
            restart: None,
        }
    }

    /// What sets the restart off, in order, with the NEES bench's seed 41
    /// trial (the street's wedges, simultaneous mode: the largest move
    /// 1.76 m, the second stage's reach 1.80 m, the finest's 0.18 m): a
    /// queue abandoned at its cap; with every queue settled, the move
    /// beyond the finest stage's reach (the caller then asks the scans'
    /// agreement); within it, nothing. A move beyond the second stage's
    /// reach, points in free space, links that disagree and named scans
    /// come first.
    #[test]
    fn a_queue_abandoned_at_its_cap_or_a_long_move_sets_the_restart_off() {
        let stage = |voxel_m: f64, max_correspondence_m: f64| Stage { voxel_m, max_correspondence_m };
        let (second, finest) = (stage(0.449, 1.798), stage(0.045, 0.180));
        let run =
            |settled: bool| StageRun { voxel_m: 0.9, max_correspondence_m: 3.6, matches: 174, seconds: 0.4, settled };
        let abandoned = SetResult { stages: vec![run(false), run(true)], ..bare(4) };
        assert_eq!(trigger_of(&abandoned, 1.759, false, &[], &second, &finest), Some(Trigger::Abandoned));
        assert_eq!(trigger_of(&abandoned, 1.9, false, &[], &second, &finest), Some(Trigger::Moved));
        let disagreeing = SetResult { variance_factor: Some(RESTART_VARIANCE_FACTOR * 1.01), ..abandoned.clone() };
        assert_eq!(trigger_of(&disagreeing, 1.759, false, &[], &second, &finest), Some(Trigger::Disagreeing));
        let settled = SetResult { stages: vec![run(true), run(true)], variance_factor: Some(0.3), ..bare(4) };
        assert_eq!(trigger_of(&settled, 1.759, false, &[], &second, &finest), Some(Trigger::Unsupported));
        assert_eq!(trigger_of(&settled, 0.181, false, &[], &second, &finest), Some(Trigger::Unsupported));
        assert_eq!(trigger_of(&settled, 0.179, false, &[], &second, &finest), None);
        assert_eq!(trigger_of(&abandoned, 0.01, false, &[], &second, &finest), Some(Trigger::Abandoned));
        // Points in free space, then named scans, come before the queue.
        assert_eq!(trigger_of(&abandoned, 1.759, true, &[2], &second, &finest), Some(Trigger::Untrusted));
        assert_eq!(trigger_of(&abandoned, 1.759, false, &[2], &second, &finest), Some(Trigger::Named));
    }

    /// Undecided scans are named unless every further restart landed
    /// where the registration kept places them.
    #[test]
    fn undecided_scans_are_named_unless_the_further_restarts_corroborate() {
        let restart = |corroborated: bool| Restart {
            scan: Some(2),
            moved_m: Some(1.9),
            schedule_error: None,
            stages: Vec::new(),
            disagreement_m2: (Some(4.2e-3), Some(3.4e-3)),
            starts_disagreement_m2: Some(6.0e-3),
            error: None,
            kept: true,
            trigger: Trigger::Moved,
            untrusted: (Some(Vec::new()), Some(Vec::new())),
            undecided: vec![(2, 1.94, 0.03), (3, 1.93, 0.03)],
            corroborated,
            repeated: false,
            disagreeing_links: false,
            unsupported: Vec::new(),
            further: Vec::new(),
            degeneracy_ratio: None,
        };
        let result = |corroborated: bool| SetResult { restart: Some(restart(corroborated)), ..bare(4) };
        assert_eq!(result(false).untrusted(), [2, 3]);
        assert!(result(true).untrusted().is_empty());
        // A move the scans' agreement gives no evidence for is named
        // whatever the further restarts say.
        let mut moved = result(true);
        moved.restart.as_mut().expect("restart").unsupported = vec![(1, 4.6)];
        assert_eq!(moved.untrusted(), [1]);
        assert!(moved.named().is_empty());
        // A scan that departs from where its verified pairs agree beyond
        // the limit is named — by the verification, as the restarts judge
        // — whatever the restart says; at the limit it is not, nor is the
        // first scan (which holds the frame).
        let (chi2, moved) = ([5e3, 3.0, crate::verify::MAX_DEPARTURE_CHI2, 4744.0], [1.0; 4]);
        assert_eq!(departed_scans(&chi2, &moved, 0.05), [3]);
        let mut departed = result(true);
        departed.departed = departed_scans(&chi2, &moved, 0.05);
        assert_eq!(departed.named(), [3]);
        assert_eq!(departed.untrusted(), [3]);
        let mut both = result(false);
        both.departed = departed.departed.clone();
        assert_eq!(both.untrusted(), [2, 3]);
        // Beyond the limit in σ but moving the points less than the finest
        // voxel (a right pose whose pairs agree far more tightly, as
        // overlaps that share their samples do): not named.
        assert!(departed_scans(&chi2, &[1.0, 1.0, 1.0, 0.004], 0.05).is_empty());
    }

    /// A graph-mode scan's move along what it reports blind, in χ² of its
    /// covariance there, judged about its points' centroid — far from the
    /// frame's origin here (1.1 km), where a turn about the centroid is a
    /// turn about the origin plus a long translation: a move along what
    /// its links see leaks nothing into the blind directions. The limits
    /// are the χ² distributions' 99.9 % points (two degrees of freedom:
    /// −2 ln 0.001, exactly).
    #[test]
    fn a_move_along_what_only_the_start_holds_is_judged_in_its_own_sigma() {
        let (start, n) = far_from_the_origin();
        let moved = |turn, shift| turned(&start, turn, shift);
        // Blind: the roll about the centroid and the shift along x; σ 0.01
        // rad and 0.02 m there, 1e-4 in every seen direction.
        let blind = [n * Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0), Vector6::new(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)]
            .map(|d| d.normalize());
        let about_centroid = Matrix6::from_diagonal(&Vector6::new(1e-4, 1e-8, 1e-8, 4e-4, 1e-8, 1e-8));
        let covariance = n * about_centroid * n.transpose();
        let judged = |roll: f64, along: f64, yaw: f64, across: f64| {
            let pose = moved(nalgebra::Vector3::new(roll, 0.0, yaw), nalgebra::Vector3::new(along, across, 0.0));
            held_move(&pose, &start, &blind, &covariance, &Point3::origin(), 2.0, 0.01)
        };
        // 0.03 rad and 0.04 m: 3² + 2² = 13, within 13.82.
        let within = judged(0.03, 0.04, 0.0, 0.0);
        assert!((within.chi2 - 13.0).abs() < 0.05, "{within:?}");
        assert_eq!(within.directions, 2);
        assert!(!within.named, "{within:?}");
        // 0.04 rad and 0.05 m: 16 + 6.25; its points 0.05 + 0.04 × 2 m.
        let beyond = judged(0.04, 0.05, 0.0, 0.0);
        assert!((beyond.chi2 - 22.25).abs() < 0.1, "{beyond:?}");
        assert!((beyond.moved_m - 0.13).abs() < 1e-3, "{beyond:?}");
        assert!(beyond.named, "{beyond:?}");
        // A turn of 0.2 rad about z and 0.5 m across: seen, and none of it
        // is blind (about the origin the turn is also a 100 m shift along x).
        let seen = judged(0.0, 0.0, 0.2, 0.5);
        assert!(seen.chi2 < 1e-6 && seen.moved_m < 1e-6, "{seen:?}");
        // Below the finest voxel the move names nothing, however tight σ.
        let pose = moved(nalgebra::Vector3::zeros(), nalgebra::Vector3::new(0.005, 0.0, 0.0));
        let small = held_move(&pose, &start, &blind, &(covariance * 1e-6), &Point3::origin(), 2.0, 0.01);
        assert!(small.chi2 > 1e3 && !small.named, "{small:?}");
        // Nothing blind, nothing judged.
        assert_eq!(held_move(&start, &start, &[], &covariance, &Point3::origin(), 2.0, 0.01), Held::default());
        assert!((held_limit(2) + 2.0 * 0.001f64.ln()).abs() < 1e-3);
        assert!((1..6).all(|k| held_limit(k) < held_limit(k + 1)));
    }

    /// A scan at its start 1.1 km from the frame's origin, its points'
    /// centroid c there, and `n`, which takes ξ about the centroid (ω, the
    /// centroid's v) to ξ about the origin (v − ω × c).
    fn far_from_the_origin() -> (Isometry3<f64>, Matrix6<f64>) {
        let start = Isometry3::translation(1000.0, 500.0, 0.0);
        let mut n = Matrix6::<f64>::identity();
        n.fixed_view_mut::<3, 3>(3, 0).copy_from(&crate::se3::skew(&start.translation.vector));
        (start, n)
    }

    /// `start` turned about its centroid (its origin here), then shifted.
    fn turned(start: &Isometry3<f64>, turn: nalgebra::Vector3<f64>, shift: nalgebra::Vector3<f64>) -> Isometry3<f64> {
        let c = start.translation.vector;
        Isometry3::new(c + shift, turn) * Isometry3::translation(-c.x, -c.y, -c.z) * start
    }

    /// The pipe's threshold for the last further restart: 0.01 with the
    /// line test (point-to-plane), a line ratio of the user's own kept;
    /// none where the user's threshold is that or above, or off.
    #[test]
    fn the_pipes_threshold_is_tried_only_below_it() {
        let with = |ratio: Option<f64>, line: Option<f64>, method: crate::icp::Method| {
            let mut c = SetConfig::default();
            c.link.multiview.icp.degeneracy_ratio = ratio;
            c.link.multiview.icp.line_ratio = line;
            c.link.multiview.icp.method = method;
            pipe_config(&c).map(|p| (p.link.multiview.icp.degeneracy_ratio, p.link.multiview.icp.line_ratio))
        };
        let plane = crate::icp::Method::PointToPlane;
        assert_eq!(with(Some(2e-3), None, plane), Some((Some(0.01), Some(0.1))));
        assert_eq!(with(Some(2e-3), Some(0.05), plane), Some((Some(0.01), Some(0.05))));
        assert_eq!(with(Some(2e-3), None, crate::icp::Method::PointToPoint), Some((Some(0.01), None)));
        assert_eq!(with(Some(0.01), None, plane), None);
        assert_eq!(with(Some(0.05), Some(0.1), plane), None);
        assert_eq!(with(None, None, plane), None);
    }

    /// The modes without a link graph: the directions where the scan's
    /// covariance keeps at least half the start's steps' variance — here
    /// the roll about the scan's centroid (0.8 of it) and the shift along
    /// x (0.8), every other direction 1e-4 of it — found by the two
    /// covariances alone, 1.1 km from the frame's origin; the move judged
    /// along them in the covariance: 0.03 rad and 0.04 m are
    /// 0.03²/0.8e-4 + 0.04²/3.2e-4 = 16.25 in χ², beyond two directions'
    /// 13.8. A turn of 0.2 rad about the centroid and 0.5 m across are
    /// seen: nothing of them is judged.
    #[test]
    fn what_the_matches_hold_no_better_than_the_start_is_judged_in_its_own_sigma() {
        let (start, n) = far_from_the_origin();
        let moved = |turn, shift| turned(&start, turn, shift);
        let about_centroid = Vector6::new(1e-4, 1e-4, 1e-4, 4e-4, 4e-4, 4e-4);
        let steps = n * Matrix6::from_diagonal(&about_centroid) * n.transpose();
        let share = Vector6::new(0.8, 1e-4, 1e-4, 0.8, 1e-4, 1e-4);
        let covariance = n * Matrix6::from_diagonal(&about_centroid.component_mul(&share)) * n.transpose();
        let judged = |roll: f64, along: f64, yaw: f64, across: f64| {
            let pose = moved(nalgebra::Vector3::new(roll, 0.0, yaw), nalgebra::Vector3::new(along, across, 0.0));
            held_by_start(&pose, &start, &covariance, &steps, &Point3::origin(), 2.0, 0.01)
        };
        let beyond = judged(0.03, 0.04, 0.0, 0.0);
        assert!((beyond.chi2 - 16.25).abs() < 0.05, "{beyond:?}");
        assert_eq!(beyond.directions, 2);
        // Its points: 0.04 m + 0.03 rad × 2 m.
        assert!((beyond.moved_m - 0.1).abs() < 1e-3, "{beyond:?}");
        assert!(beyond.named, "{beyond:?}");
        // The directions: the roll about the centroid and x.
        let basis = orthonormal(&beyond.along);
        let roll = (n * Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0)).normalize();
        for d in [roll, Vector6::new(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)] {
            let within: f64 = basis.iter().map(|q| q.dot(&d).powi(2)).sum();
            assert!((within - 1.0).abs() < 1e-9, "{d:?} not in {:?}", beyond.along);
        }
        // 0.02 rad and 0.03 m: 5 + 2.8 = 7.8, within 13.8.
        let within = judged(0.02, 0.03, 0.0, 0.0);
        assert!((within.chi2 - 7.8125).abs() < 0.05 && !within.named, "{within:?}");
        let seen = judged(0.0, 0.0, 0.2, 0.5);
        assert!(seen.chi2 < 1e-6 && seen.moved_m < 1e-6, "{seen:?}");
        // Below the finest voxel nothing is named, however far in χ².
        let small = held_by_start(
            &moved(nalgebra::Vector3::zeros(), nalgebra::Vector3::new(0.005, 0.0, 0.0)),
            &start,
            &(covariance * 1e-4),
            &(steps * 1e-4),
            &Point3::origin(),
            2.0,
            0.01,
        );
        assert!(small.chi2 > 1e2 && !small.named, "{small:?}");
        // Where the matches hold every direction better than the start,
        // nothing is judged.
        let held = held_by_start(
            &moved(nalgebra::Vector3::zeros(), nalgebra::Vector3::new(1.0, 0.0, 0.0)),
            &start,
            &(steps * 0.4),
            &steps,
            &Point3::origin(),
            2.0,
            0.01,
        );
        assert_eq!(held, Held::default());
    }
}
