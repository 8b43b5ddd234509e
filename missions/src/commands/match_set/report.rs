//! `poses.json` (`match --json`): the document and how a registration
//! becomes it.

use fusion::scanset::SetResult;
use nalgebra::Matrix6;
use serde::Serialize;

use super::args::ModeArg;
use crate::run::report::directions;
use crate::scans::inputs::InputScan;

/// `match --json` and `poses.json`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub(crate) struct MatchReport {
    /// The mode.
    pub(super) mode: String,
    /// The coordinate reference system of the poses and clouds.
    pub(super) crs: crate::run::report::CrsReport,
    /// Every scan in input order.
    pub(super) scans: Vec<ScanReport>,
    /// The final stage's matches, used or not.
    pub(super) links: Vec<LinkReport>,
    /// ICP runs in all.
    pub(super) matches: usize,
    /// The link graph's variance factor σ̂₀² (graph mode).
    pub(super) variance_factor: Option<f64>,
    /// Registration time, seconds (reading the scans and writing excluded).
    pub(super) seconds: f64,
    /// The length scales measured on the scans and the schedule used.
    pub(super) settings: SettingsReport,
    /// Each stage of the schedule as it ran.
    pub(super) stages: Vec<StageReport>,
    /// The registration from the starts again without the schedule's
    /// first stage, run when the schedule moved a scan further from its
    /// start than the second stage's correspondence distance (a coarse
    /// stage can drag good starts away on narrow overlaps), or when the
    /// schedule failed; null when it did not run.
    pub(super) restart: Option<RestartReport>,
    /// The verification: every pair of scans that overlaps at the final
    /// poses, matched once more from them at the finest stage.
    pub(super) checks: Vec<CheckReport>,
    /// The verification's wall-clock time, seconds (within `seconds`).
    pub(super) check_seconds: f64,
    /// With `--init global`: scans blind in some direction (indices into
    /// `scans`) — their start, found from the shape, says nothing along it,
    /// so the exit is 1.
    pub(super) blind_without_start: Vec<usize>,
    /// Scans an inconsistent pair names (indices into `scans`; never the
    /// first, which holds the frame, when its partner is named): their
    /// poses are not where the data agree, and the exit is 1.
    pub(super) untrusted: Vec<usize>,
}

/// One pair of the verification.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub(super) struct CheckReport {
    /// The scan matched (index into `scans`).
    pub(super) source: usize,
    /// The scan it was matched against.
    pub(super) target: usize,
    /// Correspondences at the final poses.
    pub(super) overlap: usize,
    /// How far the match moved the source's points from the final poses,
    /// metres (its centroid's displacement plus the turn times their RMS
    /// radius); null when the match failed.
    pub(super) moved_m: Option<f64>,
    /// The match's turn from the final poses, degrees.
    pub(super) angle_deg: Option<f64>,
    /// The motion against the match's own information (δᵀ·I·δ; the matches'
    /// information is optimistic on real scans: informative only).
    pub(super) chi2: Option<f64>,
    /// `moved_m` as a fraction of the source points' RMS radius.
    pub(super) relative_motion: Option<f64>,
    /// The motion along the directions the match sees well (eigenvalue at
    /// least 5 % of the largest, about the source's centroid, rotation
    /// scaled by the radius), metres: what judges the pair (a corridor
    /// pair matched alone slides along the axis the set's other links hold).
    pub(super) seen_motion_m: Option<f64>,
    /// The match's point-to-plane RMS residual, metres; null when it failed.
    pub(super) rmse_m: Option<f64>,
    /// What a right registration of the two scans leaves: the RMS of their
    /// noise floors (each scan's two random halves matched at the
    /// identity), metres.
    pub(super) noise_m: f64,
    /// The match moved the points by at most the finest stage's voxel, or
    /// along what it sees well by at most 5 % of their RMS radius and
    /// turned them by at most 5°.
    pub(super) consistent: bool,
}

/// One stage of the schedule as it ran.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub(super) struct StageReport {
    /// Its voxel, metres.
    pub(super) voxel_m: f64,
    /// Its correspondence distance, metres.
    pub(super) max_correspondence_m: f64,
    /// ICP runs in it (graph mode's last stage: the links matched).
    pub(super) matches: usize,
    /// Its wall-clock time, seconds.
    pub(super) seconds: f64,
    /// False when a simultaneous queue was abandoned at its cap.
    pub(super) settled: bool,
}

/// The second registration from the starts, without the schedule's first
/// stage.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub(super) struct RestartReport {
    /// The scan the schedule moved furthest from its start, or that its
    /// failure names (index into `scans`; null when it names none).
    pub(super) scan: Option<usize>,
    /// How far, metres (its centroid's displacement plus the turn times
    /// its points' RMS radius); null when the schedule failed.
    pub(super) moved_m: Option<f64>,
    /// Why the schedule failed — a stage moved two scans apart that
    /// overlapped at their starts, a match lost every correspondence (the
    /// restart is then the result when it succeeds; when it fails too, the
    /// schedule's error is the command's).
    pub(super) schedule_error: Option<String>,
    /// The restart's stages as they ran.
    pub(super) stages: Vec<StageReport>,
    /// How badly the scans agree at the schedule's poses: the mean over
    /// every reduced point of the squared point-to-plane distance to the
    /// other scans, truncated at the finest correspondence distance (a
    /// point with no partner pays its square), m²; null when the schedule
    /// failed.
    pub(super) schedule_disagreement_m2: Option<f64>,
    /// The same at the restart's poses; null when the restart failed.
    pub(super) restart_disagreement_m2: Option<f64>,
    /// Why the restart failed.
    pub(super) error: Option<String>,
    /// True when the restart's poses are the result: the schedule's
    /// disagreement is more than 1.5 times the restart's.
    pub(super) kept: bool,
}

/// What the scans measured and the settings they were matched with.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub(super) struct SettingsReport {
    /// The median distance from a point to its nearest neighbour over the
    /// scans' surfaces (one point per cell of a fiftieth of the radius),
    /// metres: the median over the scans.
    pub(super) spacing_m: f64,
    /// The 90th percentile of a scan's points' distances from their
    /// centroid, metres: the median over the scans.
    pub(super) radius_m: f64,
    /// Whether the schedule was derived from the scans (`--schedule auto`).
    pub(super) auto_schedule: bool,
    /// The stages, [voxel, correspondence distance] in metres.
    pub(super) schedule: Vec<[f64; 2]>,
    /// The Huber width, metres (0: least squares).
    pub(super) huber_m: f64,
    /// σ of the start's step between scans, metres (0.2 × the first
    /// voxel).
    pub(super) step_sigma_m: f64,
    /// ICP's convergence tolerance in translation, metres (0.002 × the
    /// last voxel).
    pub(super) translation_tolerance_m: f64,
    /// `simultaneous`: a match that moves its scan by more than this
    /// (metres, 0.2 × the last voxel) or 0.05° re-queues its neighbours.
    pub(super) moved_translation_m: f64,
    /// With `--init global`: how the starts were found.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) global: Option<GlobalReport>,
}

/// `--init global`'s starts.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub(super) struct GlobalReport {
    /// The descriptors' cell, metres (a fortieth of the radius).
    pub(super) voxel_m: f64,
    /// Its wall-clock time, seconds (outside `seconds`).
    pub(super) seconds: f64,
    /// Each later scan's match: against which earlier scan, with how many
    /// feature correspondences and inliers.
    pub(super) matches: Vec<GlobalMatchReport>,
}

/// One scan's global match.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub(super) struct GlobalMatchReport {
    /// The scan placed (index into `scans`).
    pub(super) source: usize,
    /// The earlier scan it was placed against.
    pub(super) target: usize,
    /// Mutual nearest neighbours in feature space.
    pub(super) correspondences: usize,
    /// Of them, within 1.5 cells after the transform.
    pub(super) inliers: usize,
}

/// One scan in a [`MatchReport`].
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub(super) struct ScanReport {
    /// The scan as given (`FILE.e57#NAME` for an E57's scans).
    pub(super) file: String,
    /// Its name (the file's stem, or the E57 `data3D`'s name): its frames
    /// file, E57 `data3D` and recording entity.
    pub(super) name: String,
    /// Its number: the input's own (3DTK `scanNNN`, the trailing digits of
    /// the name) when they tell the scans apart, else its input order; each
    /// of its points carries it (LAS `point_source_id`).
    pub(super) number: u16,
    /// Its registered pose, 4×4 row-major, metres.
    pub(super) world_from_scan: [[f64; 4]; 4],
    /// 6×6, order (ωx, ωy, ωz, x, y, z), radians and metres, left
    /// perturbation (as `register`'s) in the world's axes about the first
    /// scan's origin; zero for the first scan, which holds the frame.
    pub(super) covariance: [[f64; 6]; 6],
    /// Directions the matches cannot see (unit vectors in the order and
    /// frame of the covariance): held where the start put them, their σ
    /// the start's.
    pub(super) degenerate_directions: Vec<[f64; 6]>,
}

/// One match in a [`MatchReport`].
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub(super) struct LinkReport {
    /// The matched scan (index into `scans`).
    pub(super) source: usize,
    /// The scans it was matched against.
    pub(super) targets: Vec<usize>,
    /// Correspondences at the start of the match (graph mode).
    pub(super) overlap: Option<usize>,
    /// Correspondences at the end, when ICP ran.
    pub(super) correspondences: Option<usize>,
    /// RMS residual, metres, when ICP ran.
    pub(super) rmse_m: Option<f64>,
    /// Whether ICP converged.
    pub(super) converged: bool,
    /// ICP iterations of the match (0 when it did not run).
    pub(super) iterations: usize,
    /// Whether the match is used.
    pub(super) accepted: bool,
    /// Why not, when rejected.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) reason: Option<String>,
    /// Directions this match cannot see (order of the covariance, the
    /// first target's frame).
    pub(super) degenerate_directions: Vec<[f64; 6]>,
    /// For a link rejected as disagreeing with the others (graph mode):
    /// the shortest cycle of used links it contradicts.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) cycle: Option<CycleReport>,
}

/// A cycle of used links a rejected link contradicts.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub(super) struct CycleReport {
    /// The scans from the link's target round to its source along used
    /// links (indices into `scans`); the link closes the cycle.
    pub(super) scans: Vec<usize>,
    /// How far the path and the link disagree: the turn, degrees.
    pub(super) angle_deg: f64,
    /// … and the translation, metres.
    pub(super) translation_m: f64,
}

impl crate::view::document::Document for MatchReport {
    const NAME: &'static str = "match";
    const VERSION: u32 = 1;
}

pub(super) fn matrix<const R: usize, const C: usize>(f: impl Fn(usize, usize) -> f64) -> [[f64; C]; R] {
    std::array::from_fn(|r| std::array::from_fn(|c| f(r, c)))
}

pub(super) fn report(
    mode: ModeArg,
    crs: &scanner::io::Crs,
    scans: &[InputScan],
    r: &SetResult,
    seconds: f64,
    settings: SettingsReport,
) -> MatchReport {
    use clap::ValueEnum;
    let numbers = crate::scans::inputs::scan_numbers(scans);
    MatchReport {
        // The name the command line takes.
        mode: mode.to_possible_value().map_or_else(String::new, |v| v.get_name().to_owned()),
        crs: crate::run::report::CrsReport::new(crs),
        scans: scans
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let m = r.world_from_scan[i].to_homogeneous();
                let c: Matrix6<f64> = r.covariance[i];
                ScanReport {
                    file: s.file.clone(),
                    name: s.name.clone(),
                    number: numbers[i],
                    world_from_scan: matrix(|a, b| m[(a, b)]),
                    covariance: matrix(|a, b| c[(a, b)]),
                    degenerate_directions: directions(&r.unobservable[i]),
                }
            })
            .collect(),
        links: r
            .links
            .iter()
            .map(|l| LinkReport {
                source: l.source,
                targets: l.targets.clone(),
                overlap: l.overlap,
                correspondences: l.result.as_ref().map(|m| m.inliers),
                rmse_m: l.result.as_ref().map(|m| m.rmse_m),
                converged: l.result.as_ref().is_some_and(|m| m.converged),
                iterations: l.result.as_ref().map_or(0, |m| m.iterations),
                accepted: l.rejected.is_none(),
                reason: l.rejected.clone(),
                degenerate_directions: l.result.as_ref().map_or_else(Vec::new, |m| directions(&m.unobservable)),
                cycle: l.cycle.as_ref().map(|c| CycleReport {
                    scans: c.scans.clone(),
                    angle_deg: c.angle_rad.to_degrees(),
                    translation_m: c.translation_m,
                }),
            })
            .collect(),
        matches: r.matches,
        variance_factor: r.variance_factor,
        seconds,
        settings,
        stages: stage_reports(&r.stages),
        restart: r.restart.as_ref().map(|x| RestartReport {
            scan: x.scan,
            moved_m: x.moved_m,
            schedule_error: x.schedule_error.clone(),
            stages: stage_reports(&x.stages),
            schedule_disagreement_m2: x.disagreement_m2.0,
            restart_disagreement_m2: x.disagreement_m2.1,
            error: x.error.clone(),
            kept: x.kept,
        }),
        checks: r
            .checks
            .iter()
            .map(|c| CheckReport {
                source: c.source,
                target: c.target,
                overlap: c.overlap,
                moved_m: c.moved_m,
                angle_deg: c.angle_rad.map(f64::to_degrees),
                chi2: c.chi2,
                relative_motion: c.relative_motion,
                seen_motion_m: c.seen_motion_m,
                rmse_m: c.rmse_m,
                noise_m: c.noise_m,
                consistent: c.consistent,
            })
            .collect(),
        check_seconds: r.check_seconds,
        untrusted: fusion::verify::untrusted(scans.len(), &r.checks),
        blind_without_start: Vec::new(),
    }
}

pub(super) fn stage_reports(stages: &[fusion::scanset::StageRun]) -> Vec<StageReport> {
    stages
        .iter()
        .map(|s| StageReport {
            voxel_m: s.voxel_m,
            max_correspondence_m: s.max_correspondence_m,
            matches: s.matches,
            seconds: s.seconds,
            settled: s.settled,
        })
        .collect()
}
