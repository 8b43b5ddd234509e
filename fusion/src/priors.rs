//! Scans with an absolute prior each (the CPS poses and their joint
//! covariance) and ICP between overlapping scans, adjusted together in a
//! pose graph — `cps-icp` fusion — with the gate a match must pass against
//! the priors.

use nalgebra::{Isometry3, Matrix6, Point3};
use rayon::prelude::*;

use crate::error::{FusionError, Result};
use crate::graph::{Edge, JointPrior};
use crate::icp::{IcpConfig, IcpResult, Method, align};
use crate::multiview::{IcpTrace, Matcher, MultiviewConfig, check, prepare};

/// What [`register_with_priors`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct PriorFusionResult {
    /// The adjusted pose of every scan.
    pub world_from_scan: Vec<Isometry3<f64>>,
    /// Each pose's 6×6 covariance (ξ = (ω, v), left perturbation, world frame).
    pub covariance: Vec<Matrix6<f64>>,
    /// The ICP matches that became edges: (target scan, source scan, result).
    pub matches: Vec<(usize, usize, IcpResult)>,
    /// Matches of the last round that failed (target, source, the error):
    /// they give no edge, and the scan keeps its prior and its other edges.
    pub failed: Vec<(usize, usize, String)>,
    /// χ² of the final adjustment and its redundancy.
    pub chi2: f64,
    /// 6 × (priors + edges) − 6 × scans.
    pub redundancy: usize,
    /// Every ICP run of every round in order (the source scan's world pose
    /// per iteration, its partner's pose held), with [`IcpConfig::trace`]
    /// set; empty otherwise.
    pub traces: Vec<IcpTrace>,
}

/// Scans with an absolute prior each (the CPS pose and its covariance) and
/// ICP between overlapping scans, adjusted together in a pose graph
/// ([`crate::graph`]): each scan is matched against up to `max_partners`
/// earlier scans with the most overlap (more than
/// [`min_pairs`](MultiviewConfig::min_pairs) correspondences), every match
/// is an edge whose covariance is the ICP covariance times
/// `edge_variance_factor` (ICP's covariance treats point errors as
/// independent, which can make it optimistic), and the graph is solved.
/// That is one round per entry of `schedule`, the ICP correspondence
/// distance of the round (coarse to fine); each round's matches start from
/// the previous round's adjusted poses.
pub fn register_with_priors<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    prior: &JointPrior,
    config: &MultiviewConfig,
    max_partners: usize,
    edge_variance_factor: f64,
    schedule: &[f64],
    progress: &mut dyn FnMut(usize, usize),
) -> Result<PriorFusionResult> {
    if prior.len() != scans.len() {
        return Err(FusionError::OutOfRange {
            what: "prior poses".into(),
            value: prior.len() as f64,
            expected: format!("one per scan: {}", scans.len()),
        });
    }
    let guesses: Vec<Isometry3<f64>> = (0..prior.len()).map(|i| prior.mean(i)).collect();
    check(scans, &guesses, config)?;
    FusionError::require_positive("edge variance factor", edge_variance_factor)?;
    if config.icp.method != Method::PointToPlane {
        return Err(FusionError::OutOfRange {
            what: "ICP method with priors".into(),
            value: 0.0,
            expected: "point-to-plane".into(),
        });
    }
    for d in schedule {
        FusionError::require_positive("correspondence distance of a round (m)", *d)?;
    }
    let mut prepared = prepare(scans, config)?;
    let n = scans.len();
    let mut poses = guesses;
    let total = schedule.len() * n;
    let mut result = None;
    let mut traces = Vec::new();
    for (round, distance) in schedule.iter().enumerate() {
        let round_config = MultiviewConfig {
            icp: IcpConfig { max_correspondence_m: *distance, ..config.icp },
            overlap_m: Some(config.overlap_distance()),
            ..*config
        };
        let m = Matcher {
            prepared,
            config: &round_config,
            poses,
            last_match: vec![None; n],
            partners: vec![Vec::new(); n],
            matches: 0,
            settled: true,
            traces: Vec::new(),
            occupancy: crate::candidates::Occupancy::empty(2.0 * round_config.overlap_distance()),
        };
        let mut matches = Vec::new();
        let mut failed = Vec::new();
        // The exact overlap only with the earlier scans that share the
        // most cells ([`crate::candidates`]).
        let occupancy = crate::candidates::Occupancy::new(
            &m.prepared.iter().map(|p| p.source.as_slice()).collect::<Vec<_>>(),
            &m.poses,
            2.0 * m.overlap_distance(),
        );
        for c in 0..n {
            progress(round * n + c + 1, total);
            let screened = occupancy.ranked(c, |j| j < c, crate::candidates::SCREEN * max_partners);
            let mut overlaps: Vec<(usize, usize)> = screened.into_iter().map(|j| (j, m.overlap(c, j))).collect();
            overlaps.retain(|&(_, pairs)| pairs > config.min_pairs);
            overlaps.sort_by_key(|&(j, pairs)| std::cmp::Reverse((pairs, j)));
            overlaps.truncate(max_partners);
            let found: Vec<(usize, Result<IcpResult>)> = overlaps
                .par_iter()
                .map(|&(j, _)| {
                    let init = m.poses[j].inverse() * m.poses[c];
                    (j, align(&m.prepared[c].source, &m.prepared[j].local, &init, &round_config.icp))
                })
                .collect();
            for (j, r) in found {
                if let Ok(r) = &r
                    && !r.trace.is_empty()
                {
                    let world_from_scan = r.trace.iter().map(|t| m.poses[j] * t).collect();
                    traces.push(IcpTrace { scan: c, partners: vec![j], world_from_scan });
                }
                match r.and_then(|r| gate(&r, prior, j, c, edge_variance_factor).map(|()| r)) {
                    Ok(r) => matches.push((j, c, r)),
                    Err(e) => failed.push((j, c, e.to_string())),
                }
            }
        }
        let edges: Vec<Edge> = matches
            .iter()
            .map(|(t, s, r)| Edge {
                target: *t,
                source: *s,
                target_from_source: r.target_from_source,
                information: r.information / edge_variance_factor,
            })
            .collect();
        let g = crate::graph::optimize_joint(&m.poses, prior, &edges, 20)?;
        prepared = m.prepared;
        poses = g.world_from_scan.clone();
        result = Some(PriorFusionResult {
            world_from_scan: g.world_from_scan,
            covariance: g.covariance,
            matches,
            failed,
            chi2: g.chi2,
            redundancy: g.redundancy,
            traces: Vec::new(),
        });
    }
    result.map(|r| PriorFusionResult { traces, ..r }).ok_or_else(|| FusionError::OutOfRange {
        what: "rounds in the schedule".into(),
        value: 0.0,
        expected: "at least one correspondence distance".into(),
    })
}

/// χ²₆ at 99.9 %: a match whose disagreement with the priors exceeds it
/// is an outlier.
pub const GATE_CHI2: f64 = crate::chi2::chi2_999(6);

/// Checks that an ICP match between scans j (target) and c (source) agrees
/// with their priors: e = ξ(Z · (Pⱼ⁻¹ P_c)⁻¹), whose covariance is the
/// match's (times `factor`) plus Ad(Pⱼ⁻¹)(Σⱼⱼ + Σ_cc − Σⱼ_c − Σ_cⱼ)Ad(Pⱼ⁻¹)ᵀ —
/// the relative uncertainty of the two priors, their correlation included
/// — must give eᵀS⁻¹e ≤ [`GATE_CHI2`]. A match that converged into the
/// wrong place (too little overlap, a degenerate geometry) fails.
fn gate(r: &IcpResult, prior: &JointPrior, j: usize, c: usize, factor: f64) -> Result<()> {
    let inv_j = prior.mean(j).inverse();
    let predicted = inv_j * prior.mean(c);
    let e = crate::se3::left_difference(&r.target_from_source, &predicted);
    let ad = crate::se3::adjoint(&inv_j);
    // A match blind along some directions (degeneracy-aware ICP) says
    // nothing there: its pseudo-inverse leaves them to the priors.
    let match_cov = match r.covariance() {
        Some(c) => c * factor,
        None if !r.unobservable.is_empty() => {
            r.information.pseudo_inverse(1e-12 * r.information.amax()).unwrap_or_else(|_| Matrix6::zeros()) * factor
        }
        None => Matrix6::from_diagonal_element(f64::INFINITY),
    };
    let relative = prior.covariance_block(j, j) + prior.covariance_block(c, c)
        - prior.covariance_block(j, c)
        - prior.covariance_block(c, j);
    let s = match_cov + ad * relative * ad.transpose();
    let chi2 = s.try_inverse().map_or(f64::INFINITY, |si| (e.transpose() * si * e)[(0, 0)]);
    if chi2.is_finite() && chi2 <= GATE_CHI2 {
        Ok(())
    } else {
        Err(FusionError::Degenerate {
            what: format!(
                "the match disagrees with the priors (χ² = {chi2:.1} > {GATE_CHI2}, {:.3} m and {:.3}° apart); left out",
                e.fixed_rows::<3>(3).norm(),
                e.fixed_rows::<3>(0).norm().to_degrees()
            ),
        })
    }
}
