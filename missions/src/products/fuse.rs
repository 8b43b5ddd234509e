//! Fusion of a mission's scans by `[fusion] mode` — at the end of `run`, or
//! afterwards from a run directory with `cps-survey fuse RUN_DIR --mode`.
//!
//! - `direct`: each scan with its CPS pose and measured tilt;
//! - `icp`: scan matching alone — simultaneous matching (seed 000 §4.2)
//!   from the odometry's guesses (where each drive believed it stopped, with
//!   the measured tilt), the first scan held at its CPS pose;
//! - `cps-icp`: the scans' CPS poses as a joint prior (every station's 4×4
//!   covariance and the cross-covariances the leapfrog chain creates between
//!   stations, and the tilt sensor's σ: [`fusion::graph::JointPrior::cps`])
//!   and ICP between overlapping scans as relative measurements, adjusted
//!   together ([`fusion::priors::register_with_priors`]).
//!
//! A run's scans ([`ScanView`]) come from the runner as it goes, or from a
//! run directory's journal ([`crate::products::load::load`]).

use std::time::Instant;

use anyhow::{Context, Result};
use cps::ParentPose;
use fusion::icp::{IcpConfig, Kernel};
use fusion::multiview::{MultiviewConfig, Strategy};
use nalgebra::{Isometry3, Matrix4, Point3, Translation3, Vector3};
use scanner::Tilt;

use crate::mission::{FusionMode, FusionPlan};

/// One scan of a run with everything fusion needs.
#[derive(Debug, Clone)]
pub struct ScanView {
    /// The parent station it was taken at.
    pub station: usize,
    /// Its file, relative to the run directory.
    pub file: String,
    /// The points in the body frame.
    pub body: Vec<Point3<f32>>,
    /// The CPS pose of the station.
    pub pose: ParentPose,
    /// Its 4×4 covariance (x, y, z, θ).
    pub covariance: Matrix4<f64>,
    /// How the CPS chain correlates the station with the earlier scans'.
    pub correlation: Correlation,
    /// The measured tilt.
    pub tilt: Tilt,
    /// Where the parent's drive believed it stood (odometry).
    pub odometry: ParentPose,
    /// The simulator's true `world_from_body`, when known.
    pub truth: Option<Isometry3<f64>>,
    /// When it was taken: GPS seconds (from the journal's UNIX time), if
    /// journaled.
    pub gps_time_s: Option<f64>,
}

/// How a scan station's pose is correlated with the earlier ones'.
#[derive(Debug, Clone)]
pub enum Correlation {
    /// cov(this station, each earlier scan's station), 4×4 each, in scan
    /// order, as a version 1 or 2 journal keeps them (shorter or empty
    /// where nothing is known: taken as zero).
    Earlier(Vec<Matrix4<f64>>),
    /// The station's link in the chain (version 3, [`cps::chain`]).
    Chain(cps::chain::ChainLink),
}

impl ScanView {
    /// The scan the journal records at `station` (`scanned`: its file and
    /// time) with its `body` points: the CPS `estimate` (pose, covariance,
    /// correlation with the earlier scan stations), its `tilt`; the pose
    /// its odometry believed (x, y, heading; the nominal station's height
    /// — without a belief, the nominal station) and the simulator's true
    /// pose and tilt, when known.
    pub fn new(
        station: usize,
        scanned: &crate::journal::Scanned,
        body: Vec<Point3<f32>>,
        estimate: (ParentPose, Matrix4<f64>, Correlation),
        tilt: Tilt,
        (believed, nominal): (Option<scanner::PlanarPose>, &ParentPose),
        truth: Option<(&ParentPose, &Tilt)>,
    ) -> Self {
        let (pose, covariance, correlation) = estimate;
        Self {
            station,
            file: scanned.file.clone(),
            body,
            pose,
            covariance,
            correlation,
            tilt,
            odometry: believed.map_or(*nominal, |b| ParentPose::new(b.x_m, b.y_m, nominal.position.z, b.heading_rad)),
            truth: truth.map(|(parent, tilt)| tilt.world_from_body(parent)),
            gps_time_s: scanned.unix_time_s.map(scanner::io::gps_time_of_unix),
        }
    }

    /// `world_from_body` of the direct transformation.
    pub fn direct(&self) -> Isometry3<f64> {
        self.tilt.world_from_body(&self.pose)
    }

    /// `world_from_body` from odometry and the measured tilt.
    pub fn odometry_guess(&self) -> Isometry3<f64> {
        self.tilt.world_from_body(&self.odometry)
    }
}

/// One scan's fused pose.
#[derive(Debug, Clone, PartialEq)]
pub struct FusedScan {
    /// The parent station.
    pub station: usize,
    /// The fused `world_from_body`.
    pub world_from_body: Isometry3<f64>,
    /// RMS residual of the scan's last ICP match, metres (`None` for direct
    /// fusion and for the scan that fixes the frame).
    pub rmse_m: Option<f64>,
    /// The fused pose's 6×6 covariance (ξ = (ω, v): rotation then
    /// translation, left perturbation, world frame), where the fusion
    /// estimates one: `cps-icp`'s; `icp`'s last match, its partners held,
    /// with odometry's step (0.1 m, 1°) along what it cannot see (zero for
    /// the first scan, which holds the frame).
    pub covariance: Option<nalgebra::Matrix6<f64>>,
    /// `icp` with `[fusion] degeneracy_ratio`: the directions its last
    /// match could not see (unit ξ = (ω, v), world frame), left where
    /// odometry put the scan.
    pub unobservable: Vec<nalgebra::Vector6<f64>>,
}

/// One ICP match of a fusion: a scan (the source) against its partners.
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// The source scan's station.
    pub source: usize,
    /// The partner scans' stations (one for a pairwise match, the merged
    /// neighbours for simultaneous matching).
    pub targets: Vec<usize>,
    /// Correspondences within the gate (inliers), when it ran.
    pub correspondences: Option<usize>,
    /// RMS residual, metres, when it ran.
    pub rmse_m: Option<f64>,
    /// Whether ICP converged.
    pub converged: bool,
    /// ICP iterations (0 when it did not run).
    pub iterations: usize,
    /// Whether the match is used, and if not why.
    pub rejected: Option<String>,
    /// `icp` with `[fusion] degeneracy_ratio`: the directions the match
    /// could not see (unit ξ = (ω, v), the world's axes, a motion of the
    /// source about its first partner's origin), held where the start put
    /// them.
    pub unobservable: Vec<nalgebra::Vector6<f64>>,
}

impl Link {
    /// A match that ran: `m` of the scan at `source` against `targets`,
    /// its twists about `origin` (the world's axes), the blind directions
    /// reported about the first partner's origin `partner` (in the same
    /// frame).
    fn matched(
        source: usize,
        targets: Vec<usize>,
        m: &fusion::icp::IcpResult,
        partner: &nalgebra::Vector3<f64>,
    ) -> Self {
        let about = fusion::se3::adjoint(&Isometry3::translation(-partner.x, -partner.y, -partner.z));
        Self {
            source,
            targets,
            correspondences: Some(m.inliers),
            rmse_m: Some(m.rmse_m),
            converged: m.converged,
            iterations: m.iterations,
            rejected: None,
            unobservable: m.unobservable.iter().map(|d| (about * d).normalize()).collect(),
        }
    }
}

/// The fusion of a run's scans.
#[derive(Debug, Clone)]
pub struct Fused {
    /// The mode.
    pub mode: FusionMode,
    /// Every scan, in order.
    pub scans: Vec<FusedScan>,
    /// ICP runs.
    pub matches: usize,
    /// False when a simultaneous queue (`icp`) hit `[fusion]
    /// max_matches_per_scan` and was abandoned still moving its scans.
    pub settled: bool,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Every ICP run iteration by iteration, when asked for (`trace`).
    pub traces: Vec<fusion::multiview::IcpTrace>,
    /// The last round's ICP matches, used or not.
    pub links: Vec<Link>,
}

/// The tilt sensor's standard deviation the `cps-icp` fusion gives every
/// measured tilt: the simulated sensor's, 0.01°.
pub const TILT_SIGMA_RAD: f64 = scanner::sim::TILT_SIGMA_RAD;

/// The ICP settings of `plan` for scans in the body frame whose scanner
/// stands at `scanner_in_body`: back faces rejected.
fn multiview_config(plan: &FusionPlan, strategy: Strategy, scanner_in_body: Point3<f64>) -> MultiviewConfig {
    MultiviewConfig {
        strategy,
        icp: IcpConfig {
            max_correspondence_m: plan.max_correspondence_m,
            max_iterations: plan.max_iterations,
            kernel: if plan.huber_m > 0.0 { Kernel::Huber { width_m: plan.huber_m } } else { Kernel::None },
            reject_back_faces: true,
            source_viewpoint: scanner_in_body,
            corner_ratio: (plan.corner_ratio > 0.0).then_some(plan.corner_ratio),
            ..IcpConfig::default()
        },
        source_voxel_m: plan.voxel_m,
        target_voxel_m: plan.voxel_m / 2.0,
        min_pairs: plan.min_pairs,
        max_matches_per_scan: plan.max_matches_per_scan,
        ..MultiviewConfig::default()
    }
}

/// Fuses `views` by `mode` with the settings of `plan`, the scanner at
/// `scanner_in_body` in the body frame the scans are in; `progress(done,
/// total)` is called as scans are matched. With `trace`, every ICP run is
/// kept iteration by iteration ([`Fused::traces`]).
pub fn fuse(
    views: &[ScanView],
    mode: FusionMode,
    plan: &FusionPlan,
    scanner_in_body: Point3<f64>,
    trace: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Fused> {
    if mode != FusionMode::Direct {
        let cells: Vec<usize> = views.iter().map(|v| cells(v, plan)).collect();
        if cells.iter().any(|&c| c <= plan.min_pairs) {
            return fuse_without(views, &cells, mode, plan, scanner_in_body, trace, progress);
        }
    }
    let started = Instant::now();
    let scans: Vec<&[Point3<f32>]> = views.iter().map(|v| v.body.as_slice()).collect();
    let mut traces = Vec::new();
    let mut links = Vec::new();
    let mut covariance = vec![None; views.len()];
    let mut unobservable = vec![Vec::new(); views.len()];
    let station = |k: usize| views[k].station;
    let traced = |mut c: MultiviewConfig| {
        c.icp.trace = trace;
        c
    };
    // The matching runs in a frame at the first scan's station, its axes
    // the world's, wherever the world's origin lies: at national-grid
    // coordinates (E 500 000, N 5 500 000, H 300) points moved into the
    // world in single precision lost their millimetres (0.5 m steps) and a
    // prior about the far origin made the normal equations singular; and
    // ICP's linearisation and the blind-direction analysis depend on the
    // frame, so only a frame that moves with the survey gives at UTM what
    // it gives at the origin. Poses come back by the shift; covariances
    // stay about the first scan's station.
    let base = views.first().map_or_else(Vector3::zeros, |v| v.pose.position.coords);
    let to_local = Translation3::from(-base);
    let to_world = Translation3::from(base);
    let mut settled = true;
    let (poses, rmse, matches): (Vec<Isometry3<f64>>, Vec<Option<f64>>, usize) = match mode {
        FusionMode::Direct => (views.iter().map(ScanView::direct).collect(), vec![None; views.len()], 0),
        _ if views.is_empty() => (Vec::new(), Vec::new(), 0),
        FusionMode::Icp => {
            // The first scan holds the frame at its CPS pose; the rest start
            // from odometry. A coarse pass, then a fine one from its result.
            let mut guesses: Vec<Isometry3<f64>> = views.iter().map(|v| to_local * v.odometry_guess()).collect();
            let shift = to_local * views[0].direct() * guesses[0].inverse();
            guesses.iter_mut().for_each(|g| *g = shift * *g);
            let mut config = traced(multiview_config(plan, Strategy::Simultaneous, scanner_in_body));
            // Nothing but the start holds a scan here: what the matches
            // cannot see is left where odometry put it.
            config.icp.degeneracy_ratio = (plan.degeneracy_ratio > 0.0).then_some(plan.degeneracy_ratio);
            // … judged on the pairs whose partner's normal is a surface's.
            config.icp.line_ratio = (plan.degeneracy_ratio > 0.0 && plan.line_ratio > 0.0).then_some(plan.line_ratio);
            let coarse = fusion::multiview::register_views(&scans, &guesses, &config, progress)
                .context("ICP fusion (simultaneous matching, coarse pass)")?;
            config.overlap_m = Some(plan.max_correspondence_m);
            config.icp.max_correspondence_m = plan.fine_correspondence_m;
            let r = fusion::multiview::register_views(&scans, &coarse.world_from_scan, &config, progress)
                .context("ICP fusion (simultaneous matching, fine pass)")?;
            settled = coarse.settled && r.settled;
            traces = coarse.traces.into_iter().chain(r.traces).collect();
            for (s, (m, partners)) in r.last_match.iter().zip(&r.partners).enumerate() {
                if let Some(m) = m {
                    // The match's twists are about the local frame's origin.
                    let partner = partners
                        .first()
                        .map_or_else(nalgebra::Vector3::zeros, |&k| r.world_from_scan[k].translation.vector);
                    links.push(Link::matched(station(s), partners.iter().map(|&k| station(k)).collect(), m, &partner));
                }
            }
            let rmse = r.last_match.iter().map(|m| m.as_ref().map(|m| m.rmse_m)).collect();
            unobservable =
                r.last_match.iter().map(|m| m.as_ref().map_or_else(Vec::new, |m| m.unobservable.clone())).collect();
            // Each scan's last match (its partners held), odometry's step —
            // `match`'s 0.1 m and 1° — along what it cannot see; the first
            // scan holds the frame.
            let step = fusion::links::LinkConfig::default().step_information();
            covariance = r
                .last_match
                .iter()
                .map(|m| Some(m.as_ref().map_or_else(nalgebra::Matrix6::zeros, |m| m.covariance_held(&step))))
                .collect();
            (r.world_from_scan.iter().map(|t| to_world * t).collect(), rmse, coarse.matches + r.matches)
        }
        FusionMode::CpsIcp => {
            let prior = joint_prior(views, &base)?;
            let r = fusion::priors::register_with_priors(
                &scans,
                &prior,
                &traced(multiview_config(plan, Strategy::Pairwise, scanner_in_body)),
                plan.max_partners,
                plan.icp_variance_factor,
                &[plan.max_correspondence_m, plan.fine_correspondence_m],
                progress,
            )
            .context("CPS+ICP fusion")?;
            let mut rmse = vec![None; views.len()];
            for (t, s, m) in &r.matches {
                rmse[*s] = Some(m.rmse_m);
                // In the partner's frame, about its origin.
                links.push(Link::matched(station(*s), vec![station(*t)], m, &nalgebra::Vector3::zeros()));
            }
            for (t, s, why) in &r.failed {
                links.push(Link {
                    source: station(*s),
                    targets: vec![station(*t)],
                    correspondences: None,
                    rmse_m: None,
                    converged: false,
                    iterations: 0,
                    rejected: Some(why.clone()),
                    unobservable: Vec::new(),
                });
            }
            covariance = r.covariance.iter().copied().map(Some).collect();
            traces = r.traces;
            (r.world_from_scan.iter().map(|t| to_world * t).collect(), rmse, r.matches.len())
        }
    };
    for t in &mut traces {
        t.world_from_scan.iter_mut().for_each(|p| *p = to_world * *p);
    }
    let scans = views
        .iter()
        .zip(poses)
        .zip(rmse)
        .zip(covariance)
        .zip(unobservable)
        .map(|((((v, world_from_body), rmse_m), covariance), unobservable)| FusedScan {
            station: v.station,
            world_from_body,
            rmse_m,
            covariance,
            unobservable,
        })
        .collect();
    Ok(Fused { mode, scans, matches, settled, seconds: started.elapsed().as_secs_f64(), traces, links })
}

/// The points a scan keeps through the voxel filter; a scan is matched
/// only with more than `min_pairs` of them (an empty scan — nothing within
/// the scanner's range — stopped the ICP modes, issue 35's scaling runs).
fn cells(v: &ScanView, plan: &FusionPlan) -> usize {
    scanner::reduced_points(&v.body, plan.voxel_m).map_or(0, |r| r.len())
}

/// [`fuse`] with the scans whose `cells` ([`cells`]) are too few left out
/// of matching: they keep their start — the CPS pose (`cps-icp`), the
/// odometry's (`icp`) — without a covariance, and a link says why; the
/// others fuse as ever, `cps-icp`'s prior their marginal of the joint one.
fn fuse_without(
    views: &[ScanView],
    cells: &[usize],
    mode: FusionMode,
    plan: &FusionPlan,
    scanner_in_body: Point3<f64>,
    trace: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Fused> {
    let started = Instant::now();
    let sparse: Vec<bool> = cells.iter().map(|&c| c <= plan.min_pairs).collect();
    let kept: Vec<usize> = (0..views.len()).filter(|&i| !sparse[i]).collect();
    // cps-icp: the kept stations' cross-covariances, made explicit from the
    // whole chain (a chain link refers to the previous scan station, kept
    // or not). `icp` uses no prior.
    let mut cross = vec![Vec::new(); views.len()];
    if mode == FusionMode::CpsIcp {
        let joint = joint_cps_covariance(views)?;
        for (n, &i) in kept.iter().enumerate() {
            cross[i] = kept[..n].iter().map(|&k| Matrix4::from_fn(|r, c| joint[(4 * i + r, 4 * k + c)])).collect();
        }
    }
    let sub: Vec<ScanView> = kept
        .iter()
        .map(|&i| ScanView { correlation: Correlation::Earlier(std::mem::take(&mut cross[i])), ..views[i].clone() })
        .collect();
    let mut fused = if sub.is_empty() {
        Fused {
            mode,
            scans: Vec::new(),
            matches: 0,
            settled: true,
            seconds: 0.0,
            traces: Vec::new(),
            links: Vec::new(),
        }
    } else {
        fuse(&sub, mode, plan, scanner_in_body, trace, progress)?
    };
    for t in &mut fused.traces {
        t.scan = kept[t.scan];
        t.partners.iter_mut().for_each(|p| *p = kept[*p]);
    }
    // icp: the odometry's starts, shifted as the fusion shifts them (the
    // first kept scan at its CPS pose).
    let shift = sub.first().map_or_else(Isometry3::identity, |v| v.direct() * v.odometry_guess().inverse());
    let mut matched = std::mem::take(&mut fused.scans).into_iter();
    for (i, v) in views.iter().enumerate() {
        if sparse[i] {
            let start =
                if mode == FusionMode::Icp && !sub.is_empty() { shift * v.odometry_guess() } else { v.direct() };
            fused.scans.push(FusedScan {
                station: v.station,
                world_from_body: start,
                rmse_m: None,
                covariance: None,
                unobservable: Vec::new(),
            });
            fused.links.push(Link {
                source: v.station,
                targets: Vec::new(),
                correspondences: None,
                rmse_m: None,
                converged: false,
                iterations: 0,
                rejected: Some(format!(
                    "{} points, {} in {} m cells: too few to match (expected more than {}); the scan keeps its {} pose",
                    v.body.len(),
                    cells[i],
                    plan.voxel_m,
                    plan.min_pairs,
                    if mode == FusionMode::Icp { "odometry" } else { "CPS" }
                )),
                unobservable: Vec::new(),
            });
        } else {
            fused.scans.push(matched.next().context("a fused scan for every kept one")?);
        }
    }
    fused.seconds = started.elapsed().as_secs_f64();
    Ok(fused)
}

/// The 4N×4N CPS covariance of the scan stations (x, y, z, θ each), from
/// the chain's links or a version 1/2 journal's cross-covariances.
fn joint_cps_covariance(views: &[ScanView]) -> Result<faer::Mat<f64>> {
    let n = views.len();
    let mut joint = faer::Mat::<f64>::zeros(4 * n, 4 * n);
    let mut put = |i: usize, k: usize, block: &Matrix4<f64>| {
        for r in 0..4 {
            for c in 0..4 {
                joint[(4 * i + r, 4 * k + c)] = block[(r, c)];
                joint[(4 * k + c, 4 * i + r)] = block[(r, c)];
            }
        }
    };
    let chain: Option<Vec<cps::chain::ChainLink>> = views
        .iter()
        .map(|v| match &v.correlation {
            Correlation::Chain(link) => Some(link.clone()),
            Correlation::Earlier(_) => None,
        })
        .collect();
    match chain {
        Some(links) => cps::chain::for_each_cross_covariance(&links, put).context("the scan stations' joint prior")?,
        None => {
            for (i, v) in views.iter().enumerate() {
                if let Correlation::Earlier(cross) = &v.correlation {
                    cross.iter().take(i).enumerate().for_each(|(k, block)| put(i, k, block));
                }
                put(i, i, &v.covariance);
            }
        }
    }
    Ok(joint)
}

/// The scans' joint CPS prior: the 4N×4N covariance of their stations
/// from each view's covariance and cross-covariances, mapped to the
/// scanners' poses with the tilt ([`fusion::graph::JointPrior::cps`]), in
/// a frame whose origin is the world's `base` (the world's axes).
pub fn joint_prior(views: &[ScanView], base: &Vector3<f64>) -> Result<fusion::graph::JointPrior> {
    let joint = joint_cps_covariance(views)?;
    let to_local = Translation3::from(-base);
    let scanners: Vec<Isometry3<f64>> = views.iter().map(|v| to_local * v.direct()).collect();
    let poses: Vec<ParentPose> =
        views.iter().map(|v| ParentPose { position: v.pose.position - base, ..v.pose }).collect();
    let tilts: Vec<Tilt> = views.iter().map(|v| v.tilt).collect();
    Ok(fusion::graph::JointPrior::cps(&scanners, &poses, &tilts, &joint, TILT_SIGMA_RAD)?)
}

/// Horizontal distance between the body origins of two poses, metres.
pub fn error_xy(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    (a.translation.vector.xy() - b.translation.vector.xy()).norm()
}

/// Heading difference of two poses (rotation of the body x axis about z), radians.
pub fn error_heading(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    let (xa, xb) = (a.rotation * nalgebra::Vector3::x(), b.rotation * nalgebra::Vector3::x());
    cps::wrap_angle(xa.y.atan2(xa.x) - xb.y.atan2(xb.x))
}

/// A scan's name: its file's stem (`scan003`).
fn scan_name(view: &ScanView) -> String {
    let stem = std::path::Path::new(&view.file).file_stem().map(|s| s.to_string_lossy().into_owned());
    stem.unwrap_or_else(|| format!("scan{:03}", view.station))
}

impl ScanView {
    /// Who the scan is in the merged cloud: its name, the station's index
    /// as its number (LAS `point_source_id`: 65535 for stations from 65535
    /// on), its time.
    pub fn label(&self) -> crate::output::ScanLabel {
        crate::output::ScanLabel {
            name: scan_name(self),
            number: u16::try_from(self.station).unwrap_or(u16::MAX),
            gps_time_s: self.gps_time_s,
        }
    }
}

/// Writes each scan's fused pose into `dir` as a 3DTK `.frames` file named
/// after its scan file (`scan003.3d` → `scan003.frames`): beside the scans,
/// slam6d's `show` places them as fused. Returns the names written.
pub fn write_frames(dir: &std::path::Path, views: &[ScanView], fused: &Fused) -> Result<Vec<String>> {
    let mut names = Vec::with_capacity(views.len());
    for (v, f) in views.iter().zip(&fused.scans) {
        let name = format!("{}.frames", scan_name(v));
        scanner::io::write_3dtk_frames(&dir.join(&name), &f.world_from_body)
            .with_context(|| format!("writing {}", dir.join(&name).display()))?;
        names.push(name);
    }
    Ok(names)
}
