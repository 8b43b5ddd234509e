//! How a registration becomes `poses.json` ([`crate::documents::matching`]).

use fusion::scanset::SetResult;
use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3};

use super::args::ModeArg;
use crate::documents::matching::*;
use crate::documents::records::{Cycle, Link, directions, rows};
use crate::documents::run::CrsReport;
use crate::scans::inputs::InputScan;

pub(super) fn report(
    mode: ModeArg,
    crs: &scanner::io::Crs,
    scans: &[InputScan],
    r: &SetResult,
    seconds: f64,
    settings: SettingsReport,
    joint: bool,
) -> MatchReport {
    use clap::ValueEnum;
    let numbers = crate::scans::inputs::scan_numbers(scans);
    MatchReport {
        // The name the command line takes.
        mode: mode.to_possible_value().map_or_else(String::new, |v| v.get_name().to_owned()),
        crs: CrsReport::new(crs),
        scans: scans
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let m = r.world_from_scan[i].to_homogeneous();
                let c: Matrix6<f64> = r.covariance[i];
                let held = r.held.get(i).filter(|h| h.directions > 0);
                ScanReport {
                    file: s.file.clone(),
                    name: s.name.clone(),
                    number: numbers[i],
                    world_from_scan: rows(&m),
                    covariance: rows(&c),
                    departure: r.departure.get(i).map(|d| std::array::from_fn(|k| d[k])),
                    departure_chi2: r.departure_chi2.get(i).copied(),
                    departure_m: r.departure_m.get(i).copied(),
                    degenerate_directions: directions(&r.unobservable[i]),
                    held_chi2: held.map(|h| h.chi2),
                    held_m: held.map(|h| h.moved_m),
                    held_directions: held.map_or_else(Vec::new, |h| directions(&h.along)),
                    // The caller's: where the scanners stood is not the registration's.
                    viewpoint: None,
                }
            })
            .collect(),
        links: r
            .links
            .iter()
            .map(|l| Link {
                source: l.source,
                targets: l.targets.clone(),
                overlap: l.overlap,
                correspondences: l.result.as_ref().map(|m| m.inliers),
                rmse_m: l.result.as_ref().map(|m| m.rmse_m),
                converged: l.result.as_ref().is_some_and(|m| m.converged),
                iterations: l.result.as_ref().map_or(0, |m| m.iterations),
                accepted: l.rejected.is_none(),
                reason: l.rejected.clone(),
                degenerate_directions: l.result.as_ref().map_or_else(Vec::new, |m| {
                    directions(&link_blind(mode, r, l.targets.first().copied(), &m.unobservable))
                }),
                cycle: l.cycle.as_ref().map(|c| Cycle {
                    scans: c.scans.clone(),
                    angle_deg: c.angle_rad.to_degrees(),
                    translation_m: c.translation_m,
                }),
            })
            .collect(),
        matches: r.matches,
        variance_factor: r.variance_factor,
        lean_variance_factor: r.lean_variance_factor,
        redundancy: r.redundancy,
        noise_factor: r.noise_factor,
        departure_weight: r.departure_weight,
        joint_covariance: joint
            .then(|| r.joint_covariance.as_ref().map(fusion::graph::JointCovariance::rows))
            .flatten(),
        noise: r.noise.map(|n| NoiseReport {
            variance_scale: n.variance_scale,
            dof: n.dof,
            halvings: n.halvings,
            left_out: n.left_out,
            range_scale: n.range_scale,
            rotation_scale: n.rotation_scale,
            translation_scale: n.translation_scale,
            asymmetry: n.asymmetry,
            halves: shares_report(&n.halves),
            quarters: shares_report(&n.quarters),
            seconds: r.noise_seconds,
        }),
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
            starts_disagreement_m2: x.starts_disagreement_m2,
            error: x.error.clone(),
            kept: x.kept,
            trigger: match x.trigger {
                fusion::scanset::Trigger::Moved => "moved",
                fusion::scanset::Trigger::Failed => "failed",
                fusion::scanset::Trigger::Untrusted => "untrusted",
                fusion::scanset::Trigger::Disagreeing => "disagreeing",
                fusion::scanset::Trigger::Named => "named",
                fusion::scanset::Trigger::Creeping => "creeping",
                fusion::scanset::Trigger::Abandoned => "abandoned",
                fusion::scanset::Trigger::Unsupported => "unsupported",
            }
            .into(),
            schedule_untrusted: x.untrusted.0.clone(),
            restart_untrusted: x.untrusted.1.clone(),
            undecided: x
                .undecided
                .iter()
                .map(|&(scan, apart_m, angle)| UndecidedReport { scan, apart_m, apart_deg: angle.to_degrees() })
                .collect(),
            corroborated: x.corroborated,
            repeated: x.repeated,
            disagreeing_links: x.disagreeing_links,
            unsupported: x.unsupported.iter().map(|&(scan, moved_m)| UnsupportedReport { scan, moved_m }).collect(),
            further: x
                .further
                .iter()
                .map(|f| FurtherReport {
                    stages: stage_reports(&f.stages),
                    disagreement_m2: f.disagreement_m2,
                    error: f.error.clone(),
                    kept: f.kept,
                    untrusted: f.untrusted.clone(),
                    degeneracy_ratio: f.degeneracy_ratio,
                    moved_m: f.moved_m,
                    nearer_starts: f.nearer_starts,
                })
                .collect(),
            degeneracy_ratio: x.degeneracy_ratio,
        }),
        checks: r
            .checks
            .iter()
            .map(|c| {
                // At the source scan's origin, from the first scan's (about
                // which the covariances are).
                let at = r.world_from_scan[c.source].translation.vector - r.world_from_scan[0].translation.vector;
                let relative = r.joint_covariance.as_ref().map(|j| relative_sigma(j, c.source, c.target, &at));
                CheckReport {
                    source: c.source,
                    target: c.target,
                    overlap: c.overlap,
                    moved_m: c.moved_m,
                    angle_deg: c.angle_rad.map(f64::to_degrees),
                    chi2: c.chi2,
                    relative_motion: c.relative_motion,
                    seen_motion_m: c.seen_motion_m,
                    rmse_m: c.rmse_m,
                    start_rmse_m: c.start_rmse_m,
                    converged: c.converged,
                    noise_m: c.noise_m,
                    relative_sigma_xyz_m: relative.map(|(_, m)| m),
                    relative_sigma_rot_deg: relative.map(|(rad, _)| rad.to_degrees()),
                    relative_chi2: c.relative_chi2.map(|(chi2, _)| chi2),
                    relative_dof: c.relative_chi2.map(|(_, dof)| dof),
                    consistent: c.consistent,
                    free_space: c.free_space.map(|f| FreeSpaceReport {
                        seen_from: f.seen_from,
                        violations: f.violations,
                        agreements: f.agreements,
                        share: f.share(),
                    }),
                }
            })
            .collect(),
        check_seconds: r.check_seconds,
        untrusted: r.untrusted(),
        blind_without_start: Vec::new(),
    }
}

/// The σ of scan `a`'s pose relative to scan `b`'s: of their relative
/// error ξₐ − ξ_b (covariance Cₐ + C_b − C_ab − C_ba, first order, the
/// world's axes about the first scan's origin) moved to be about the
/// point `at` (from the first scan's origin; the adjoint of the shift
/// there: v + ω × at), √ of the traces of its rotation block, radians,
/// and of its translation block — the displacement of `at` —, metres.
fn relative_sigma(joint: &fusion::graph::JointCovariance, a: usize, b: usize, at: &Vector3<f64>) -> (f64, f64) {
    let about = fusion::se3::adjoint(&Isometry3::from_parts(Translation3::from(-at), UnitQuaternion::identity()));
    let c = about * joint.relative(a, b) * about.transpose();
    let trace = |k: usize| (c[(k, k)] + c[(k + 1, k + 1)] + c[(k + 2, k + 2)]).max(0.0).sqrt();
    (trace(0), trace(3))
}

/// A link's blind directions as every document reports them: in the
/// world's axes, a motion of the source about its (first) partner's
/// origin. Graph mode's matches are in their partner's frame (axes turned
/// into the world's); the other modes' are in the world about its origin
/// (carried to the partner's: at national-grid coordinates the world's
/// origin would turn every rotation into a translation).
fn link_blind(
    mode: ModeArg,
    r: &SetResult,
    partner: Option<usize>,
    blind: &[nalgebra::Vector6<f64>],
) -> Vec<nalgebra::Vector6<f64>> {
    let Some(partner) = partner.and_then(|j| r.world_from_scan.get(j)) else { return blind.to_vec() };
    let to = match mode {
        ModeArg::Graph => Isometry3::from_parts(Translation3::identity(), partner.rotation),
        _ => Isometry3::from_parts(Translation3::from(-partner.translation.vector), UnitQuaternion::identity()),
    };
    let ad = fusion::se3::adjoint(&to);
    blind.iter().map(|d| (ad * d).normalize()).collect()
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

fn shares_report(s: &fusion::noise::Shares) -> SharesReport {
    SharesReport {
        variance_scale: s.variance_scale,
        range_scale: s.range_scale,
        rotation_scale: s.blocks.map(|b| b.0),
        translation_scale: s.blocks.map(|b| b.1),
        asymmetry: s.asymmetry,
        dof: s.dof,
        matched: s.matched,
        left_out: s.left_out,
    }
}
