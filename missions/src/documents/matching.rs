//! `poses.json` (`match --json`): every scan's pose, the links, the
//! schedule as it ran, the verification.

use serde::Serialize;

use super::Document;
use super::records::Link;
use super::run::CrsReport;

/// `match --json` and `poses.json`.
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct MatchReport {
    /// The mode.
    pub mode: String,
    /// The coordinate reference system of the poses and clouds.
    pub crs: CrsReport,
    /// Every scan in input order.
    pub scans: Vec<ScanReport>,
    /// The final stage's matches, used or not.
    pub links: Vec<Link>,
    /// ICP runs in all.
    pub matches: usize,
    /// The variance factor σ̂₀² = χ²/redundancy of the final links: the
    /// link graph's in graph mode; in the other modes that of the
    /// verification's matches (`checks`) adjusted together from the final
    /// poses. The redundancy is the links' own: 6 per link less 6 per scan
    /// they place. It scales the matches' noise in every covariance
    /// (`noise_factor`; not the start's steps, which hold what no match
    /// sees); below 1 the rest
    /// of it is taken as each scan's own, shared by its links. In the other
    /// modes null when no pair was verified (a single scan).
    pub variance_factor: Option<f64>,
    /// σ̂₀² of the same links each corrected by its edge's lean: its
    /// measurement moved by 1.25× the step its match would take without
    /// the pairs beyond the other scan's sampled edge and the covered
    /// pairs within three spacings of them, and the links adjusted again.
    /// Where it is below `variance_factor` and the links as measured fail
    /// their global test (redundancy × `variance_factor` beyond the 97.5 %
    /// point of χ² with the redundancy's degrees of freedom: their noise
    /// does not explain their misfit) the lean explains it: the
    /// covariances take it as each link's bias, and this
    /// factor (not below the smaller of 1 and `variance_factor`) in place
    /// of `variance_factor`; otherwise each link's pull by the pairs
    /// beyond the edge alone, and `variance_factor`. Null without
    /// redundancy (nothing to judge: the pull alone) or without a lean (no
    /// pair beyond an edge), or where `variance_factor` is.
    pub lean_variance_factor: Option<f64>,
    /// The degrees of freedom `variance_factor` rests on: the links'
    /// redundancy, 6 per link less 6 per scan they place (one ring of
    /// four scans: 6). Null where `variance_factor` is.
    pub redundancy: Option<usize>,
    /// The factor the covariances take on the matches' noise: the
    /// variance factor they use (`variance_factor`, or
    /// `lean_variance_factor` where the lean explains the misfit) — above
    /// 1, where the links pass their global test (redundancy × factor
    /// within the 97.5 % point of χ² with the redundancy's degrees of
    /// freedom), pooled with the calibration's, which said 1 on
    /// `noise.dof` degrees of freedom: (dof + redundancy × factor) /
    /// (dof + redundancy), so one ring's chance misfit does not widen
    /// every direction (docs/match.md); beyond the test as it is —, never
    /// below 0.05, and 1 without redundancy. Null where `variance_factor`
    /// is.
    pub noise_factor: Option<f64>,
    /// The modes without a link graph: the share w of the departures'
    /// ξξᵀ (`scans[].departure`, stacked) in the covariances. 1 in
    /// pairwise mode (each scan placed on one partner's match); in
    /// incremental and simultaneous mode the stacked departures' χ² in
    /// the adjustment's joint σ less 6 per scan but the first, over that
    /// χ² (0 where it is below): a departure within the adjustment's own
    /// noise adds nothing to it; a compromise nearly all of itself. Each
    /// covariance less w·ξξᵀ is the adjustment's. Null in graph mode or
    /// when no pair was verified.
    pub departure_weight: Option<f64>,
    /// With `--joint-covariance`: the poses' joint covariance, 6N×6N for
    /// the N `scans` in their order, row by row — block (i, j) is
    /// cov(ξᵢ, ξⱼ) in the order and frame of `scans[].covariance`, which
    /// is its diagonal (the first scan's rows and columns zero). What two
    /// poses' errors share: the covariance of scan j relative to scan i
    /// is Cᵢ + Cⱼ − Cᵢⱼ − Cⱼᵢ (to first order, in the world's axes),
    /// which Cᵢ + Cⱼ overstates where the same links place both. Null
    /// without the flag, and where the covariances are not an
    /// adjustment's (the modes without a link graph when no pair was
    /// verified).
    pub joint_covariance: Option<Vec<Vec<f64>>>,
    /// The covariance model calibrated on the scans themselves — each
    /// scan's random halves, and two quarters, matched under a known turn,
    /// their errors against their own covariances, carried on to the
    /// scans' own density. Its `variance_scale` multiplies every finest
    /// match's covariance from one variance (graph mode: as the adjustment
    /// weighs the links), its `range_scale` every finest match's
    /// covariance by pair (each pair's variance its own squared residual;
    /// the name is its first model's, by range from the scanner), which
    /// the scans' covariances carry (both
    /// before `variance_factor`). Null when the schedule is empty.
    pub noise: Option<NoiseReport>,
    /// Registration time, seconds (reading the scans and writing excluded).
    pub seconds: f64,
    /// The length scales measured on the scans and the schedule used.
    pub settings: SettingsReport,
    /// Each stage of the schedule as it ran.
    pub stages: Vec<StageReport>,
    /// The registration from the starts again without the schedule's
    /// first stage, run when the schedule moved a scan further from its
    /// start than the second stage's correspondence distance (a coarse
    /// stage can drag good starts away on narrow overlaps), or when the
    /// schedule failed; null when it did not run.
    pub restart: Option<RestartReport>,
    /// The verification: every pair of scans that overlaps at the final
    /// poses, matched once more from them at the finest stage.
    pub checks: Vec<CheckReport>,
    /// The verification's wall-clock time, seconds (within `seconds`).
    pub check_seconds: f64,
    /// With `--init global`: scans blind in some direction (indices into
    /// `scans`) — their start, found from the shape, says nothing along it,
    /// so the exit is 1.
    pub blind_without_start: Vec<usize>,
    /// Scans an inconsistent pair names (indices into `scans`; never the
    /// first, which holds the frame, when its partner is named): their
    /// poses are not where the data agree, and the exit is 1.
    pub untrusted: Vec<usize>,
}

/// The noise calibration (`fusion::noise`).
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct NoiseReport {
    /// The factor on the covariances from one variance: the halves'
    /// Σχ²/Σdof (above 1 the match's own covariance was optimistic on
    /// these data, below 1 pessimistic) times its step from the quarters'
    /// (`halves.variance_scale / quarters.variance_scale`, taken between 1
    /// and 2: denser shares misjudge more, so the scans themselves more
    /// than their halves); 1 when nothing could be measured (`dof` 0).
    pub variance_scale: f64,
    /// The degrees of freedom it rests on (6 per halving, less its blind
    /// directions).
    pub dof: usize,
    /// Halvings matched: of each scan that has enough points as many as
    /// bring the halves to 96 degrees of freedom — two for eight scans
    /// or more, four for five or fewer (`fusion::noise::halvings`).
    pub halvings: usize,
    /// Halvings left out as mismatches (χ²/dof beyond 25× the median).
    pub left_out: usize,
    /// The same against the covariance with each pair's variance its own
    /// squared residual (named for its first model, the variance by range
    /// from the scanner): the factor on the finest matches' covariance by
    /// pair, which the reported covariances carry
    /// (`variance_scale` calibrates graph mode's link weights).
    pub range_scale: f64,
    /// The same for the covariance by pair's rotation alone, about each
    /// match's source centroid (where the split is the same in every
    /// frame): the halves' mean χ² of the rotation against its own 3×3
    /// block, over 3, carried on to the scans' density as `range_scale`
    /// is, from the halvings without blind directions (`range_scale`
    /// where none is). Every covariance by pair of a match without blind
    /// directions takes it on its rotation about its source's centroid,
    /// `translation_scale` on its translation there.
    pub rotation_scale: f64,
    /// The same for the translation about the source's centroid
    /// (`rotation_scale`).
    pub translation_scale: f64,
    /// How far a halving's two ways disagree by the scans' noise alone:
    /// the halves' mean ΔᵀC⁻¹Δ, Δ half the difference of the steps each
    /// way alone would take (one the first half's points on the second's
    /// surfaces, the other the reverse), C the calibrated covariance by
    /// pair. A link's Δ beyond it is its scans' sampling — each way leans
    /// on one scan's sampled surfaces — and each scan's share of it in
    /// every one of its links enters the covariances whole (graph mode,
    /// and the adjustment of the verified pairs in the other modes).
    /// 0 when nothing could be measured.
    pub asymmetry: f64,
    /// What the halves measured.
    pub halves: SharesReport,
    /// What two quarters of each scan (halves of a half) measured.
    pub quarters: SharesReport,
    /// Its wall-clock time, seconds (within `seconds`).
    pub seconds: f64,
}

/// What one density of shares measured in the noise calibration.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct SharesReport {
    /// Σχ²/Σdof against the covariance from one variance for all pairs.
    pub variance_scale: f64,
    /// Σχ²/Σdof against the covariance by pair.
    pub range_scale: f64,
    /// The mean χ² of the rotation about the source's centroid against its
    /// own block of the covariance by pair, over 3, from the shares without
    /// blind directions; null when none is.
    pub rotation_scale: Option<f64>,
    /// The same for the translation about the source's centroid.
    pub translation_scale: Option<f64>,
    /// The mean ΔᵀC⁻¹Δ of their two ways against their covariance by pair
    /// (not calibrated).
    pub asymmetry: f64,
    /// The degrees of freedom they rest on.
    pub dof: usize,
    /// Shares matched.
    pub matched: usize,
    /// Shares left out as mismatches (χ²/dof beyond 25× the median).
    pub left_out: usize,
}

/// One pair of the verification.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct CheckReport {
    /// The scan matched (index into `scans`).
    pub source: usize,
    /// The scan it was matched against.
    pub target: usize,
    /// Correspondences at the final poses.
    pub overlap: usize,
    /// How far the match moved the source's points from the final poses,
    /// metres (its centroid's displacement plus the turn times their RMS
    /// radius); null when the match failed.
    pub moved_m: Option<f64>,
    /// The match's turn from the final poses, degrees.
    pub angle_deg: Option<f64>,
    /// The motion against the match's own information (δᵀ·I·δ; the matches'
    /// information is optimistic on real scans: informative only).
    pub chi2: Option<f64>,
    /// `moved_m` as a fraction of the source points' RMS radius.
    pub relative_motion: Option<f64>,
    /// The motion along the directions the match sees well (eigenvalue at
    /// least 5 % of the largest, about the source's centroid, rotation
    /// scaled by the radius), metres: what judges the pair (a corridor
    /// pair matched alone slides along the axis the set's other links hold).
    pub seen_motion_m: Option<f64>,
    /// The match's point-to-plane RMS residual, metres; null when it failed.
    pub rmse_m: Option<f64>,
    /// The same residual at the final poses (the match's first pass),
    /// metres; null when the match failed.
    pub start_rmse_m: Option<f64>,
    /// Whether the match settled: false when it stopped at its iteration
    /// cap still moving (such a match beyond the finest voxel puts the
    /// result in doubt: `restart.trigger` "creeping"); null when it failed.
    pub converged: Option<bool>,
    /// What a right registration of the two scans leaves: the RMS of their
    /// noise floors (each scan's two random halves matched at the
    /// identity), metres.
    pub noise_m: f64,
    /// The registered relative pose of the two scans, its σ: of their
    /// relative error ξₛ − ξₜ (covariance Cₛ + Cₜ − Cₛₜ − Cₜₛ, from the
    /// poses' joint covariance, `--joint-covariance`), √ of the trace of
    /// the displacement it gives the source scan's origin, metres — where
    /// the source stands relative to the target, which the two scans' own
    /// σ overstate where the same links place both. Null where the
    /// covariances are not an adjustment's.
    pub relative_sigma_xyz_m: Option<f64>,
    /// … and √ of the trace of its rotation block, degrees.
    pub relative_sigma_rot_deg: Option<f64>,
    /// The match's departure from the final relative pose in χ² of the
    /// two poses' relative covariance (first order, its pseudo-inverse),
    /// and `relative_dof` its degrees of freedom (the covariance's rank);
    /// null where the match failed, and where the departure lies along a
    /// direction the relative covariance does not span (beyond 1e-9 of
    /// it: a χ² without bound, JSON having no infinity; `relative_dof`
    /// is still given).
    pub relative_chi2: Option<f64>,
    /// See `relative_chi2`.
    pub relative_dof: Option<usize>,
    /// The match moved the points by at most the finest stage's voxel, or
    /// along what it sees well by at most 5 % of their RMS radius, turned
    /// them by at most 5° and lowered its residual (`start_rmse_m` →
    /// `rmse_m`) at most 1.5-fold — or more, where `relative_chi2` is
    /// within the 99.9 % point of χ² with `relative_dof` (the poses are
    /// not known well enough to say the closer fit is elsewhere); and no
    /// scanner's free space holds more than 12 % of the other scan's
    /// points (`free_space`).
    pub consistent: bool,
    /// The free-space test from the pair's scanner whose view the other
    /// scan violates most; null when neither scanner's position is known
    /// (PLY, XYZ, LAS inputs).
    pub free_space: Option<FreeSpaceReport>,
}

/// One scan's points against the free space another scan's scanner saw.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct FreeSpaceReport {
    /// The scan whose scanner's view judges (index into `scans`).
    pub seen_from: usize,
    /// The other scan's points in that scanner's free space: in front of
    /// every surface it saw their way by more than the finest
    /// correspondence distance.
    pub violations: usize,
    /// The other scan's points on a surface it saw their way.
    pub agreements: usize,
    /// violations / (violations + agreements); above 0.12 the pair is
    /// inconsistent.
    pub share: f64,
}

impl FreeSpaceReport {
    /// Whether the share makes the pair inconsistent (as
    /// `fusion::verify::PairCheck::violates_free_space` judged it).
    pub fn violated(&self) -> bool {
        self.share > fusion::free_space::MAX_VIOLATION_SHARE
    }
}

/// One stage of the schedule as it ran.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct StageReport {
    /// Its voxel, metres.
    pub voxel_m: f64,
    /// Its correspondence distance, metres.
    pub max_correspondence_m: f64,
    /// ICP runs in it (graph mode's last stage: the links matched).
    pub matches: usize,
    /// Its wall-clock time, seconds.
    pub seconds: f64,
    /// False when a simultaneous queue was abandoned at its cap.
    pub settled: bool,
}

/// The second registration from the starts, without the schedule's first
/// stage (or, after a slide along what only the starts hold, the whole
/// schedule with a pipe's threshold: `degeneracy_ratio`).
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct RestartReport {
    /// The scan the schedule moved furthest from its start, or that its
    /// failure names (index into `scans`; null when it names none).
    pub scan: Option<usize>,
    /// How far, metres (its centroid's displacement plus the turn times
    /// its points' RMS radius); null when the schedule failed.
    pub moved_m: Option<f64>,
    /// Why the schedule failed — a stage moved two scans apart that
    /// overlapped at their starts, a match lost every correspondence (the
    /// restart is then the result when it succeeds; when it fails too, the
    /// schedule's error is the command's).
    pub schedule_error: Option<String>,
    /// The restart's stages as they ran.
    pub stages: Vec<StageReport>,
    /// How badly the scans agree at the schedule's poses: the mean over
    /// every reduced point of the squared point-to-plane distance to the
    /// other scans, truncated at the finest correspondence distance (a
    /// point with no partner pays its square), m²; null when the schedule
    /// failed.
    pub schedule_disagreement_m2: Option<f64>,
    /// The same at the restart's poses; null when the restart failed.
    pub restart_disagreement_m2: Option<f64>,
    /// The same at the starts (also after a schedule that failed, since
    /// session 57; null before). A result the scans agree with no better
    /// sets off `further` restarts, and names its long moves
    /// (`unsupported`).
    pub starts_disagreement_m2: Option<f64>,
    /// Why the restart failed.
    pub error: Option<String>,
    /// True when the restart's poses are the result: the schedule's put
    /// points in another scanner's free space and the verification names
    /// nothing of the restart's, or the schedule's disagreement is more
    /// than 1.5 times the restart's, or — with `undecided` scans, or when
    /// the verification named scans of the schedule's and names none of
    /// the restart's — more than the restart's at all.
    pub kept: bool,
    /// What set it off: "moved" (the schedule moved `scan` beyond the
    /// second stage's reach of its start), "failed" (`schedule_error`),
    /// "untrusted" (the schedule's result put points in another scanner's
    /// free space), "disagreeing" (the schedule's links disagree more
    /// than their covariances allow: `variance_factor` above 1), "named"
    /// (the verification names scans of the schedule's result:
    /// `schedule_untrusted`), "creeping" (a pair of `checks` stopped at
    /// its iteration cap still moving beyond the finest voxel —
    /// `converged` false — and the scans agree with the schedule's result
    /// no better than with their starts: `schedule_disagreement_m2` at
    /// least `starts_disagreement_m2`, or not clearly better where it
    /// moved a scan beyond the finest stage's reach, as for
    /// `unsupported`), "abandoned" (a simultaneous
    /// queue of the schedule was abandoned at its cap: a stage of
    /// `stages` not `settled`) or "unsupported" (the schedule moved `scan`
    /// beyond the finest stage's reach of its start, and the scans agree
    /// with its result not clearly better than with their starts — the
    /// test of `unsupported`, made before any restart ran); the last two
    /// session 59, additive.
    pub trigger: String,
    /// The scans the verification names at the schedule's poses (indices
    /// into `scans`): by their pairs (`checks`), or in the modes without a
    /// link graph by their departure from where those pairs agree (above
    /// 1,500 σ² and the finest voxel, as `scans[].departure_chi2` and
    /// `departure_m`); null when the schedule
    /// failed.
    pub schedule_untrusted: Option<Vec<usize>>,
    /// The same at the restart's poses; null when the restart failed, or
    /// was not kept and not verified (only a restart from an impossible
    /// schedule's result, a kept one, or one that places a scan apart from
    /// the schedule's while neither agrees clearly better, is).
    pub restart_untrusted: Option<Vec<usize>>,
    /// The scans the schedule's and the restart's registrations place
    /// apart (their points moved by more than 5 % of the scan's RMS radius:
    /// the centroid's displacement plus the turn times the radius) when the
    /// scans' disagreement prefers neither by 1.5× and the verification
    /// names nothing of either: the data cannot tell which is right, so
    /// they are in `untrusted` (exit 1) — unless `corroborated` —, and the
    /// registration the scans agree with better is the result. Also
    /// (session 60) the scans a `repeated` schedule's result and a shorter
    /// schedule's of `further` place apart, where the scans agree with
    /// that one better, however slightly, and it is kept. Empty otherwise.
    pub undecided: Vec<UndecidedReport>,
    /// True when the `undecided` scans are not in `untrusted` after all:
    /// every further restart (at least one ran; after a `repeated`
    /// schedule, every other from the first that left the schedule's
    /// place) landed where the
    /// registration kept places them (none of them 5 % of its radius
    /// apart) — the one the scans agree with better is also the one every
    /// shorter schedule reaches from the starts.
    pub corroborated: bool,
    /// True when the restart only repeated the schedule: a scan moved
    /// beyond the second stage's reach (`trigger` "moved") and the
    /// restart, not kept, landed where the schedule did (no scan 5 % of
    /// its radius apart). The second stage may drag as the first did, so
    /// every `further` restart runs until one is kept; one that lands
    /// there too is no corroboration (its own coarse stage may drag as
    /// far), and one that lands apart with a better agreement leaves the
    /// scans `undecided` (docs/match.md; session 60).
    pub repeated: bool,
    /// True when the result before the `further` restarts (the
    /// schedule's, or the restart's where `kept`) has links that disagree
    /// beyond a variance factor of 1,000 (`variance_factor`; right
    /// registrations measured up to 470): the further restarts run,
    /// and one the scans agree with better, however slightly, whose links
    /// do not disagree so and that the verification names nothing of is
    /// kept (session 74; docs/match.md).
    pub disagreeing_links: bool,
    /// The scans the result moved from their starts beyond the finest
    /// stage's reach (its `max_correspondence_m`), where the scans agree
    /// with the result not clearly better than with their starts (the
    /// kept registration's disagreement at least 0.99 times
    /// `starts_disagreement_m2`; before session 61 at least that itself —
    /// the building example's scan009, slid 1.22 m along its façade at
    /// 0.9963×, passed): a move a coarser stage decided that nothing in
    /// the data supports.
    /// They are in `untrusted` (exit 1). Empty otherwise.
    pub unsupported: Vec<UnsupportedReport>,
    /// Further restarts from the starts, each without one more of the
    /// schedule's stages (the first without its first two — without its
    /// first after the pipe's restart, `degeneracy_ratio` —, …, the last
    /// with the finest stage alone), run in turn while the result is not
    /// to be trusted — the verification names scans of it, the restart
    /// left some `undecided`, its disagreement is no less than
    /// `starts_disagreement_m2`, or its links disagree grossly
    /// (`disagreeing_links`) — and the schedule has more than two
    /// stages: a restart's second stage can drag scans as the schedule's
    /// first did. One kept replaces every registration before it; they go
    /// on while it is not to be trusted either. Last, when the result is
    /// still named only by moves along what only the starts hold, the
    /// whole schedule once more with a pipe's threshold (its
    /// `degeneracy_ratio`). Empty when none ran.
    pub further: Vec<FurtherReport>,
    /// The blind-direction threshold the restart ran with where it is not
    /// the set's: 0.01, a pipe's (the line test on), the whole schedule
    /// from the starts in place of the schedule without its first stage —
    /// when the schedule's result is named only by moves along what only
    /// the starts hold and a simultaneous queue of it was abandoned at its
    /// cap (each shorter schedule would chase the same slide from the same
    /// starts). Kept where the verification names nothing of it and the
    /// scans agree with it within 1.5× of the schedule's result; else
    /// `further` begins with the schedule without its first stage. Null
    /// for the usual restart.
    pub degeneracy_ratio: Option<f64>,
}

/// A further restart from the starts ([`RestartReport::further`]).
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct FurtherReport {
    /// Its stages as they ran (empty when it failed).
    pub stages: Vec<StageReport>,
    /// The scans' disagreement at its poses, m² a point (as
    /// `schedule_disagreement_m2`); null when it failed.
    pub disagreement_m2: Option<f64>,
    /// Why it failed.
    pub error: Option<String>,
    /// True when its poses are the result (then the restart's `kept` is
    /// false and nothing is `undecided`): the scans disagree more than 1.5
    /// times less there than at the best registration before it, or the
    /// schedule's put points in another scanner's free space and the
    /// verification names nothing of its, or the verification named scans
    /// of the result before it, names none of its, and the scans disagree
    /// less there at all — or 1.05 times less, where the result before it
    /// was itself such a rescue — or the result before it was named only
    /// by moves along what only the starts hold (`scans[].held_chi2`),
    /// the verification names none of its scans, and the scans disagree
    /// there within 1.5 times the best registration before it — or the
    /// scans agreed with the result before it no better than with their
    /// starts, and this one, within 1.5 times the best and named nothing
    /// of, moves them less (`nearer_starts`).
    pub kept: bool,
    /// The scans the verification names at its poses; null when it failed
    /// or was not verified (it is where it may be kept).
    pub untrusted: Option<Vec<usize>>,
    /// The blind-direction threshold it ran with where not the set's:
    /// 0.01, a pipe's, with the line test — the whole schedule from the
    /// starts, run last when the result is still named only by moves
    /// along what only the starts hold (docs/match.md). Null for the
    /// shorter schedules.
    pub degeneracy_ratio: Option<f64>,
    /// The largest move of a scan from its start at its poses, metres (as
    /// the restart's `moved_m`); null when it failed.
    pub moved_m: Option<f64>,
    /// Kept as nearer the starts: the scans agreed with the result before
    /// it no better than with their starts (`starts_disagreement_m2`), or
    /// not clearly better (0.99 times) where it moved scans beyond the
    /// finest stage's reach — its moves no evidence of the data's —, they
    /// agree with this one
    /// within 1.5 times the best registration before it, the verification
    /// names none of its scans and ties each to another by an agreeing
    /// pair, and it moves them less (`moved_m`).
    pub nearer_starts: bool,
}

/// A scan two registrations of the set place apart ([`RestartReport::undecided`]).
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct UndecidedReport {
    /// Index into `scans`.
    pub scan: usize,
    /// How far apart: the displacement of its points' centroid plus the
    /// turn times their RMS radius, metres.
    pub apart_m: f64,
    /// The turn between the two poses, degrees.
    pub apart_deg: f64,
}

/// A scan moved beyond the finest stage's reach of its start by a result
/// the scans agree with no better than with their starts
/// ([`RestartReport::unsupported`]).
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct UnsupportedReport {
    /// Index into `scans`.
    pub scan: usize,
    /// How far from its start: the displacement of its points' centroid
    /// plus the turn times their RMS radius, metres.
    pub moved_m: f64,
}

/// What the scans measured and the settings they were matched with.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct SettingsReport {
    /// The median distance from a point to its nearest neighbour over the
    /// scans' surfaces (one point per cell of a fiftieth of the radius),
    /// metres: the median over the scans.
    pub spacing_m: f64,
    /// The 90th percentile of a scan's points' distances from their
    /// centroid, metres: the median over the scans.
    pub radius_m: f64,
    /// Whether the schedule was derived from the scans (`--schedule auto`).
    pub auto_schedule: bool,
    /// The stages, [voxel, correspondence distance] in metres.
    pub schedule: Vec<[f64; 2]>,
    /// The Huber width, metres (0: least squares).
    pub huber_m: f64,
    /// σ of the start's step between scans, metres (0.2 × the first
    /// voxel).
    pub step_sigma_m: f64,
    /// ICP's convergence tolerance in translation, metres (0.002 × the
    /// last voxel).
    pub translation_tolerance_m: f64,
    /// `simultaneous`: a match that moves its scan by more than this
    /// (metres, 0.2 × the last voxel) or 0.05° re-queues its neighbours.
    pub moved_translation_m: f64,
    /// `--only-covered`: pairs beyond what the other scan sampled around
    /// their partner left out at the finest stage.
    pub only_covered: bool,
    /// The blind-direction threshold the matches ran with (0: off):
    /// `--degeneracy-ratio`, else 0.01 where the scans are a pipe
    /// (`pipe`), else the default, 2e-3.
    pub degeneracy_ratio: f64,
    /// The line test's ratio (0: off): `--line-ratio`, else 0.1 with a
    /// threshold given or a pipe found, else 0.
    pub line_ratio: f64,
    /// `--normal-agreement`: in the matches made both ways, pairs whose
    /// two normals differ by more than this many degrees left out (0:
    /// off).
    pub normal_agreement_deg: f64,
    /// `--corner-ratio`: point-to-plane pairs whose target normal's
    /// neighbourhood has its smallest PCA eigenvalue above this share of
    /// its middle one left out, in every match (0: off).
    pub corner_ratio: f64,
    /// `--corner-everywhere`: with the corner test, every target point's
    /// neighbourhood judged; false: only those whose ten nearest points
    /// reach beyond the stage's correspondence distance.
    pub corner_everywhere: bool,
    /// Where no `--degeneracy-ratio` is given and every scan's points lie
    /// on a tube all round it: the pipe found, whose threshold the matches
    /// then ran with. Null otherwise.
    pub pipe: Option<PipeReport>,
    /// With `--init global`: how the starts were found.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub global: Option<GlobalReport>,
}

/// The pipe the scans are ([`SettingsReport::pipe`]): each scan's tube
/// fitted from its points' principal axes, with no guess.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct PipeReport {
    /// The median of the scans' tubes' radii, metres.
    pub radius_m: f64,
    /// The least share of a scan's points within 5 % of the radius from
    /// its tube's surface (at least 0.8 for a pipe).
    pub share: f64,
    /// The least share of the 36 sectors of 10° about a tube's axis that
    /// those points fill (at least 0.75 for a pipe: a plane is a tube of a
    /// huge radius seen from one side).
    pub around: f64,
}

/// `--init global`'s starts.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct GlobalReport {
    /// The descriptors' cell, metres (a fortieth of the radius).
    pub voxel_m: f64,
    /// Its wall-clock time, seconds (outside `seconds`).
    pub seconds: f64,
    /// Each later scan's match: against which earlier scan, with how many
    /// feature correspondences and inliers.
    pub matches: Vec<GlobalMatchReport>,
}

/// One scan's global match.
#[derive(Debug, Clone, Serialize, schemars::JsonSchema)]
pub struct GlobalMatchReport {
    /// The scan placed (index into `scans`).
    pub source: usize,
    /// The earlier scan it was placed against.
    pub target: usize,
    /// Mutual nearest neighbours in feature space.
    pub correspondences: usize,
    /// Of them, within 1.5 cells after the transform.
    pub inliers: usize,
}

/// One scan in a [`MatchReport`].
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct ScanReport {
    /// The scan as given (`FILE.e57#NAME` for an E57's scans).
    pub file: String,
    /// Its name (the file's stem, or the E57 `data3D`'s name): its frames
    /// file, E57 `data3D` and recording entity.
    pub name: String,
    /// Its number: the input's own (3DTK `scanNNN`, the trailing digits of
    /// the name) when they tell the scans apart, else its input order; each
    /// of its points carries it (LAS `point_source_id`).
    pub number: u16,
    /// Its registered pose, 4×4 row-major, metres.
    pub world_from_scan: [[f64; 4]; 4],
    /// 6×6, order (ωx, ωy, ωz, x, y, z), radians and metres, left
    /// perturbation (as `register`'s) in the world's axes about the first
    /// scan's origin; zero for the first scan, which holds the frame. In
    /// graph mode it carries the links' covariance by pair (each pair's
    /// variance its own squared residual) and each link's pull by its pairs past the other scan's edge; in
    /// the other modes it is that of the verification's matches
    /// (`checks`, both ways) adjusted together in the same model, plus the
    /// pose's departure from that adjustment as far as the departures
    /// exceed its noise (`departure_weight`; docs/match.md).
    pub covariance: [[f64; 6]; 6],
    /// In the modes without a link graph: how far this pose is from where
    /// the verification's matches (`checks`) agree — their adjustment —,
    /// ξ in the order and frame of the covariance (pose ≈ exp(ξ)·adjusted;
    /// zeros for the first scan); part of the covariance (w·ξξᵀ, w the
    /// report's `departure_weight`). Graph mode
    /// would put the scan about there. Null in graph mode (its poses are
    /// the adjustment) or when no pair was verified.
    pub departure: Option<[f64; 6]>,
    /// The departure in the σ of the adjustment it departs from:
    /// ξᵀ·C⁺·ξ, C the adjustment's covariance (this covariance less
    /// w·ξξᵀ) less the scans' sampling.
    /// Above 1,500 — with `departure_m` above the finest voxel — the
    /// strategy stopped in a compromise of its matches apart from where
    /// its pairs agree: the scan is in `untrusted`, exit 1
    /// (docs/match.md). Null where `departure` is.
    pub departure_chi2: Option<f64>,
    /// How far the departure moves the scan's points, metres: its
    /// centroid's displacement plus the turn times their RMS radius (as
    /// `checks[].moved_m`). Null where `departure` is.
    pub departure_m: Option<f64>,
    /// Directions the matches cannot see (unit vectors in the order and
    /// frame of the covariance): held where the start put them, their σ
    /// the start's.
    pub degenerate_directions: Vec<[f64; 6]>,
    /// For a scan with `held_directions`: how far it moved from its start
    /// along them, in χ² of its covariance there. Above the χ²
    /// distribution's 99.9 % point for as many degrees of freedom as
    /// directions — with `held_m` above the finest voxel — what only the
    /// start holds moved further than the start's steps allow: the scan
    /// is in `untrusted`, exit 1 (a pipe at the default
    /// `--degeneracy-ratio`, docs/match.md). Null otherwise.
    pub held_chi2: Option<f64>,
    /// How far that move takes the scan's points, metres: its centroid's
    /// displacement plus the turn times their RMS radius. Null where
    /// `held_chi2` is.
    pub held_m: Option<f64>,
    /// The directions only the start holds (unit vectors in the order and
    /// frame of the covariance), along which `held_chi2` judges the move:
    /// in graph mode `degenerate_directions`; in the other modes those
    /// where the covariance keeps at least half the variance the start's
    /// steps alone give — the matches hold them no better than the start
    /// (docs/match.md). Empty for the first scan and where none.
    pub held_directions: Vec<[f64; 6]>,
    /// Where the scan's scanner stood, as the verification's free-space
    /// test took it; null when neither the input, `--scanner-at-origin`
    /// nor an estimate says (`--no-viewpoint-estimate`, or fewer than 16
    /// points apart).
    pub viewpoint: Option<ViewpointReport>,
}

/// Where a scan's scanner stood ([`ScanReport::viewpoint`]).
#[derive(Debug, Serialize, schemars::JsonSchema)]
pub struct ViewpointReport {
    /// In the scan's frame, metres.
    pub position: [f64; 3],
    /// `stated` (a 3DTK scan, an E57 `data3D` with a pose, a PCD's
    /// VIEWPOINT, a ROS 2 cloud), `origin` (`--scanner-at-origin`) or
    /// `estimated` (from the scan's point spacing, which grows with the
    /// range: docs/match.md, "Where the scanners stood").
    pub source: String,
    /// For an estimate: the share of the log point spacing's spread the
    /// scanner at `position` explains (by the range, or turning about
    /// `axis`), 1 − (MAD of the fit's residuals / MAD of log spacing)²;
    /// null otherwise.
    pub explained: Option<f64>,
    /// Whether the free-space test used it: an estimate explaining less
    /// than 0.7 (a scan thinned on a grid, merged from stations far
    /// apart) is reported, not used.
    pub used: bool,
    /// For an estimate whose spacing showed a scanner turning about an
    /// axis (a 2D scanner on a rotating or nodding table, a terrestrial
    /// scanner's head): that axis, a unit vector in the scan's frame (its
    /// sign arbitrary); null otherwise.
    pub axis: Option<[f64; 3]>,
}

impl ViewpointReport {
    /// Whether the position is an estimate from the scan's spacing.
    pub fn is_estimate(&self) -> bool {
        self.source == ESTIMATED
    }
}

/// [`ViewpointReport::source`] of an estimate.
pub const ESTIMATED: &str = "estimated";

impl Document for MatchReport {
    const NAME: &'static str = "match";
    const VERSION: u32 = 1;
}
