//! The ICP iteration: correspondences, then Horn's closed-form update
//! (point-to-point) or a Gauss–Newton step (point-to-plane, optionally with
//! a pose prior in its normal equations), until an update falls below the
//! tolerances; and the coarse-to-fine schedule.

use nalgebra::{Isometry3, Matrix3, Matrix4, Matrix6, Point3, SymmetricEigen, Translation3, UnitQuaternion, Vector6};

use super::config::{IcpConfig, Kernel, Method};
use super::correspondences::{Partners, Sums, accumulate, edge_zone, own_model};
use super::degeneracy::{Observability, projector_off};
use super::target::Target;
use crate::error::{FusionError, Result};
use crate::se3::Prior;

/// What an ICP run returns.
#[derive(Debug, Clone, PartialEq)]
pub struct IcpResult {
    /// The estimate: maps source points into the target frame.
    pub target_from_source: Isometry3<f64>,
    /// Whether an update fell below the tolerances before the cap.
    pub converged: bool,
    /// Iterations done.
    pub iterations: usize,
    /// Correspondences within the distance at the last linearisation
    /// point (the estimate before the last update, which moved it by less
    /// than the tolerances when `converged`): the source's points with a
    /// target partner (also in a match both ways).
    pub inliers: usize,
    /// RMS of the residuals at the last linearisation point (point-to-plane
    /// distances or point-to-point distances; in a match both ways, of
    /// both ways' residuals), metres.
    pub rmse_m: f64,
    /// RMS of the residuals at the start (the first pass, at `init`),
    /// metres: with [`rmse_m`](Self::rmse_m), how much the match improved
    /// on where it began.
    pub start_rmse_m: f64,
    /// 6×6 information of ξ = (ω, v) at the last linearisation point, see
    /// the module docs; with [`IcpConfig::degeneracy_ratio`], zero along
    /// the [`unobservable`](Self::unobservable) directions.
    pub information: Matrix6<f64>,
    /// With [`IcpConfig::trace`]: `target_from_source` after each
    /// iteration (the last is the estimate); empty otherwise.
    pub trace: Vec<Isometry3<f64>>,
    /// With [`IcpConfig::degeneracy_ratio`]: the directions of ξ = (ω, v)
    /// (unit vectors, target frame) the match cannot see at the estimate
    /// (the last iteration left them where they were, and
    /// [`information`](Self::information) carries nothing along them);
    /// empty otherwise.
    pub unobservable: Vec<Vector6<f64>>,
    /// With [`IcpConfig::edge_bias`] (point-to-plane): how the pairs
    /// beyond the target's sampled edge pull the estimate — the step the
    /// fit without them would take from it, less the step the fit with
    /// them would take, both linearised at the last pass (ξ = (ω, v), left,
    /// target frame; nothing along the unobservable directions). Zero
    /// otherwise, or when no pair lies beyond the edge.
    pub edge_bias: Vector6<f64>,
    /// With [`IcpConfig::edge_bias`] (point-to-plane): how the edge leans
    /// the estimate — the same step with the covered pairs nearest the
    /// edge left out too, those within three target spacings of a pair
    /// beyond it, whose partners' neighbourhoods the edge cuts as well
    /// (one-sided normals, nearest samples all inward). Longer than
    /// `edge_bias` and along it where an overlap ends across a surface
    /// (a real room's wedges: 1.55× at the median); the link graph judges whether
    /// the links' misfit is it ([`crate::links`]). Zero otherwise, or
    /// when no pair lies beyond the edge.
    pub edge_lean: Vector6<f64>,
    /// With [`IcpConfig::range_noise`] too: [`edge_bias`](Self::edge_bias)'s
    /// square against what the pairs' noise alone would scatter it by (its
    /// covariance were each pair's score's variance its own squared
    /// residual, as in [`range_covariance`](Self::range_covariance)): a
    /// pull of nothing but noise has a mean of 6 less the blind
    /// directions; infinite without the scores, zero with no pull. The
    /// link graph takes only the pull's square beyond it
    /// ([`crate::links::beyond_noise`]).
    pub edge_bias_chi2: f64,
    /// The same for [`edge_lean`](Self::edge_lean).
    pub edge_lean_chi2: f64,
    /// With [`IcpConfig::range_noise`] (point-to-plane): the estimate's
    /// covariance with each pair's variance its own squared residual,
    /// H⁻¹·B·H⁻¹ ([`IcpConfig::range_noise`]), not scaled by
    /// [`IcpConfig::noise_scale`] (which calibrates `information`); `None`
    /// otherwise.
    pub range_covariance: Option<Matrix6<f64>>,
    /// Matched both ways (point-to-plane): half the difference of the
    /// steps each way alone would take from the estimate — the source's
    /// points on the target's planes less the target's points on the
    /// source's — from the covered pairs (those beyond an edge and, with
    /// [`IcpConfig::edge_bias`], its zone left out: the edge's pull is
    /// [`edge_bias`](Self::edge_bias)'s), linearised at the last pass (ξ =
    /// (ω, v), left, target frame; nothing along the unobservable
    /// directions). Each way leans on one scan's sampled surfaces — its
    /// normals, its nearest samples —, and how far the two disagree
    /// measures what that sampling does to the match, which the residuals
    /// do not show: on a simulated hall's scans 3.6 m apart its ΔᵀC⁻¹Δ
    /// (C the covariance by pair) had a median of 6.8 and a mean of 57,
    /// on the same scans' random halves, which share their sampling, a
    /// mean of 5.4 ([`crate::links`], [`crate::noise::Shares::asymmetry`]).
    /// Zero one way.
    pub asymmetry: Vector6<f64>,
    /// The source's centroid where the estimate puts it (target frame):
    /// where the covariance's rotation and translation are told apart
    /// ([`crate::noise::by_blocks`]).
    pub source_centroid: Point3<f64>,
}

impl IcpResult {
    /// The 6×6 covariance of ξ = (ω, v) (the inverse of
    /// [`information`](Self::information)), or `None` when the information
    /// is singular (a degenerate geometry).
    pub fn covariance(&self) -> Option<Matrix6<f64>> {
        self.information.cholesky().map(|c| c.inverse())
    }

    /// The covariance with `held` (an information, e.g. a start's step σ)
    /// along the directions the match cannot see — its
    /// [`unobservable`](Self::unobservable) ones, or every direction when
    /// the information is singular beyond them (point-to-point on
    /// collinear points, the analysis off): always finite for a positive
    /// definite `held`.
    pub fn covariance_held(&self, held: &Matrix6<f64>) -> Matrix6<f64> {
        let blind = Matrix6::identity() - projector_off(&self.unobservable);
        let filled = self.information + blind * held * blind;
        let c = filled
            .try_inverse()
            .or_else(|| (self.information + held).try_inverse())
            .unwrap_or_else(|| held.try_inverse().unwrap_or_else(|| Matrix6::from_diagonal_element(f64::INFINITY)));
        0.5 * (c + c.transpose())
    }
}

/// Horn's closed-form rotation: the unit quaternion is the eigenvector of
/// the largest eigenvalue of N built from S = Σ (p − p̄)(q − q̄)ᵀ.
pub(crate) fn horn_rotation(s: &Matrix3<f64>) -> UnitQuaternion<f64> {
    let (sxx, sxy, sxz) = (s[(0, 0)], s[(0, 1)], s[(0, 2)]);
    let (syx, syy, syz) = (s[(1, 0)], s[(1, 1)], s[(1, 2)]);
    let (szx, szy, szz) = (s[(2, 0)], s[(2, 1)], s[(2, 2)]);
    #[rustfmt::skip]
    let n = Matrix4::new(
        sxx + syy + szz, syz - szy,        szx - sxz,        sxy - syx,
        syz - szy,       sxx - syy - szz,  sxy + syx,        szx + sxz,
        szx - sxz,       sxy + syx,        -sxx + syy - szz, syz + szy,
        sxy - syx,       szx + sxz,        syz + szy,        -sxx - syy + szz,
    );
    let eig = SymmetricEigen::new(n);
    let q = eig.eigenvectors.column(eig.eigenvalues.imax());
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// Aligns `source` to `target` from `init` (`target_from_source`).
pub fn align(source: &[Point3<f32>], target: &Target, init: &Isometry3<f64>, config: &IcpConfig) -> Result<IcpResult> {
    align_impl(source, target, init, config, None, None, None)
}

/// [`align`] with the first pass's nearest neighbours already found
/// (`partners` = `Partners::at(source, target, init)`, e.g. while counting
/// the overlap): the same result without searching them again.
pub(crate) fn align_from(
    source: &[Point3<f32>],
    target: &Target,
    init: &Isometry3<f64>,
    config: &IcpConfig,
    partners: Partners,
) -> Result<IcpResult> {
    align_impl(source, target, init, config, None, Some(partners), None)
}

/// The other way of a symmetric match: the target's data points and the
/// source's model (points with normals, in the source frame).
pub(crate) struct Reverse<'a> {
    /// The target scan's data points, target frame.
    pub(crate) points: &'a [Point3<f32>],
    /// The source scan's model, source frame.
    pub(crate) model: &'a Target,
}

/// Point-to-plane [`align_from`] matched both ways: every iteration also
/// finds each of the target's data points' nearest source model point (at
/// the estimate's inverse, back faces left out as the other way) and sums
/// those residuals, on the source's normals, into the same normal
/// equations. Swapping the scans gives the inverse transform: the
/// one-way match is not antisymmetric — on two random halves of one real
/// scan it put the source about 0.4 mm off along the same direction
/// whichever half was the source (BENCHMARKS, "Matching both ways").
pub(crate) fn align_both(
    source: &[Point3<f32>],
    target: &Target,
    init: &Isometry3<f64>,
    config: &IcpConfig,
    partners: Partners,
    reverse: Reverse<'_>,
) -> Result<IcpResult> {
    if config.method != Method::PointToPlane || !reverse.model.has_normals() {
        return Err(FusionError::OutOfRange {
            what: "a match both ways".into(),
            value: 0.0,
            expected: "point-to-plane with the source's model normals".into(),
        });
    }
    align_impl(source, target, init, config, None, Some(partners), Some(reverse))
}

/// Point-to-plane ICP whose normal equations include a prior: each
/// Gauss–Newton step minimises Σ r²/σ̂² + eᵀ Λ e, with σ̂² the current
/// residual variance and e ≈ ξ(T · T_prior⁻¹) the prior's error (first
/// order). The result is the fused estimate; its `information` is the
/// fused one, H/σ̂² + Λ, so directions the scans do not constrain (along a
/// corridor, about a pipe's axis) keep the prior's uncertainty instead of
/// failing as singular.
pub fn align_with_prior(
    source: &[Point3<f32>],
    target: &Target,
    init: &Isometry3<f64>,
    prior: &Prior,
    config: &IcpConfig,
) -> Result<IcpResult> {
    if config.method != Method::PointToPlane {
        return Err(FusionError::OutOfRange {
            what: "ICP method with a prior".into(),
            value: 0.0,
            expected: "point-to-plane".into(),
        });
    }
    let l = &prior.information;
    let symmetric = (l - l.transpose()).amax() <= 1e-9 * l.amax().max(1.0);
    let psd = l.symmetric_eigenvalues().iter().all(|v| *v >= -1e-9 * l.amax().max(1.0));
    if !(l.iter().all(|v| v.is_finite()) && symmetric && psd) {
        return Err(FusionError::OutOfRange {
            what: "prior information".into(),
            value: l.amax(),
            expected: "a finite, symmetric, positive semi-definite 6×6".into(),
        });
    }
    align_impl(source, target, init, config, Some(prior), None, None)
}

fn align_impl(
    source: &[Point3<f32>],
    target: &Target,
    init: &Isometry3<f64>,
    config: &IcpConfig,
    prior: Option<&Prior>,
    first: Option<Partners>,
    reverse: Option<Reverse<'_>>,
) -> Result<IcpResult> {
    check(config)?;
    if config.reject_back_faces && !target.oriented {
        return Err(FusionError::OutOfRange {
            what: "target normals".into(),
            value: 0.0,
            expected:
                "normals oriented towards the target's scanner (Target::orient_normals_towards) to reject back faces"
                    .into(),
        });
    }
    if config.method == Method::PointToPlane && !target.has_normals() {
        return Err(FusionError::OutOfRange {
            what: "target normals".into(),
            value: 0.0,
            expected: "a target built with normal_neighbours > 0 for point-to-plane".into(),
        });
    }
    let max_sq = config.max_correspondence_m * config.max_correspondence_m;
    let mut estimate = *init;
    let mut converged = false;
    let mut iterations = 0;
    let mut trace = Vec::new();
    // The statistics come from the last iteration's pass (as small_gicp's
    // do): one more nearest-neighbour pass at the final estimate would cost
    // a sixth of a typical run and change them by the last, sub-tolerance
    // update.
    let mut last = Sums::default();
    let mut at_last = estimate;
    let mut partners = first.filter(|p| p.len() == source.len()).unwrap_or_else(|| Partners::new(source.len()));
    let mut back_partners = Partners::new(reverse.as_ref().map_or(0, |r| r.points.len()));
    // How the estimate (and its inverse) moved since the last pass (none
    // before the first).
    let (mut moved, mut back_moved) = (None, None);
    // The one-way correspondences of the last pass (`inliers`).
    let mut forward = 0;
    let mut start_rmse_m = None;
    let mut unobservable = Vec::new();
    // With blind directions asked for, the analysis runs about the
    // source's centroid (where the estimate puts it in the target's frame:
    // the same verdict in every frame), rotation made comparable with
    // translation by the source's RMS radius about it (at least 1 mm).
    // The centroid is the result's too (`source_centroid`).
    let (centre, lever_arm_m) = match config.degeneracy_ratio {
        Some(_) => super::degeneracy::centroid_and_lever_arm(source),
        None => (super::degeneracy::centroid(source), 1.0),
    };
    // Each way's points' own normals, for the normal agreement: the
    // source's model and the target's.
    let own = reverse.as_ref().and_then(|r| own_model(config, source, r.model));
    let back_own = reverse.as_ref().and_then(|r| own_model(config, r.points, target));
    // Both ways: the last pass's sums each way (the back's in its own ξ).
    let mut ways: Option<(Sums, Sums)> = None;
    while iterations < config.max_iterations {
        let mut sums = accumulate(source, target, &estimate, max_sq, config, &mut partners, moved, own);
        forward = sums.n;
        if let Some(r) = &reverse {
            let inverse = estimate.inverse();
            let back =
                accumulate(r.points, r.model, &inverse, max_sq, config, &mut back_partners, back_moved, back_own);
            let both = sums.clone().both_ways(&back, &estimate);
            ways = Some((sums, back));
            sums = both;
        }
        last = sums;
        at_last = estimate;
        let sums = &last;
        start_rmse_m.get_or_insert_with(|| sums.rmse());
        if forward < 6 {
            return Err(FusionError::TooFewCorrespondences {
                found: forward,
                needed: 6,
                max_distance_m: config.max_correspondence_m,
                iteration: iterations,
            });
        }
        let update = match config.method {
            Method::PointToPoint => {
                let n = sums.sw;
                let (cp, cq) = (sums.sp / n, sums.sq_t / n);
                let s = sums.spq - n * cp * cq.transpose();
                let r = horn_rotation(&s);
                Isometry3::from_parts(Translation3::from(cq - r * cp), r)
            }
            Method::PointToPlane => {
                let (h, surface, b) = match prior {
                    None => (sums.h, sums.h - sums.line_h, sums.b),
                    Some(p) => {
                        let sigma2 = residual_variance(sums, config.method);
                        let e = crate::se3::left_difference(&estimate, &p.target_from_source);
                        (
                            sums.h / sigma2 + p.information,
                            (sums.h - sums.line_h) / sigma2 + p.information,
                            sums.b / sigma2 + p.information * e,
                        )
                    }
                };
                let delta = match config.degeneracy_ratio {
                    Some(ratio) => {
                        let o = Observability::judged(&h, &surface, &(estimate * centre), lever_arm_m, ratio);
                        unobservable = o.unobservable();
                        o.solve(&(-b))
                    }
                    None => h
                        .cholesky()
                        .ok_or_else(|| FusionError::Degenerate {
                            what: format!("point-to-plane normal equations at iteration {iterations}"),
                        })?
                        .solve(&(-b)),
                };
                crate::se3::exp(&delta)
            }
        };
        let last = estimate;
        estimate = update * estimate;
        moved = Some(motion(&estimate, &last));
        if reverse.is_some() {
            back_moved = Some(motion(&estimate.inverse(), &last.inverse()));
        }
        iterations += 1;
        if config.trace {
            trace.push(estimate);
        }
        if update.translation.vector.norm() < config.translation_tolerance_m
            && update.rotation.angle() < config.rotation_tolerance_rad
        {
            converged = true;
            break;
        }
    }
    let mut sums = last;
    if config.edge_bias && config.method == Method::PointToPlane {
        // At the last pass's estimate, each point on its partner there.
        let mut z = edge_zone(source, target, &at_last, max_sq, config, &partners, own);
        if let Some(r) = &reverse {
            let back = edge_zone(r.points, r.model, &at_last.inverse(), max_sq, config, &back_partners, back_own);
            if let Some((f, b)) = &mut ways {
                (f.zone_h, f.zone_b, b.zone_h, b.zone_b) = (z.zone_h, z.zone_b, back.zone_h, back.zone_b);
            }
            z = z.both_ways(&back, &at_last);
        }
        sums.zone_h = z.zone_h;
        sums.zone_b = z.zone_b;
        sums.zone_scores = z.zone_scores;
    }
    let rmse_m = sums.rmse();
    let prior_information = prior.map_or_else(Matrix6::zeros, |p| p.information);
    let sigma2 = residual_variance(&sums, config.method);
    // The pairs taken as independent, H/σ̂², then scaled by what the data's
    // halves measured of that model (`noise_scale`). (A sandwich estimate,
    // H·B⁻¹·H with B = Σ (w·r)² JJᵀ, judged rotation against translation
    // better on real scans' halves, but weighed the 3DTK set's links
    // otherwise and moved its triangle's scans 0.1° further from the
    // references: BENCHMARKS.md, "Covariances the data calibrate".)
    let data = sums.normal_matrix(config.method) / sigma2;
    let independent = data + prior_information;
    // What the surfaces alone see (point-to-point has no lines: `line_h` is zero).
    let surface = independent - sums.line_h / sigma2;
    let measured = data / config.noise_scale + prior_information;
    let information = match config.degeneracy_ratio {
        Some(ratio) => {
            // What the match cannot see it does not know: its information
            // leaves those directions out (to the prior, another match, or
            // odometry in a pose graph). Which directions those are is
            // judged on the residuals' own scatter, as the iteration
            // judges them.
            let o = Observability::judged(&independent, &surface, &(estimate * centre), lever_arm_m, ratio);
            unobservable = o.unobservable();
            o.project(&measured)
        }
        None => measured,
    };
    let (edge_bias, edge_bias_chi2) = without(&sums, &sums.edge_h, &sums.edge_b, &sums.edge_scores, &unobservable);
    let (edge_lean, edge_lean_chi2) = without(
        &sums,
        &(sums.edge_h + sums.zone_h),
        &(sums.edge_b + sums.zone_b),
        &(sums.edge_scores + sums.zone_scores),
        &unobservable,
    );
    let range_covariance = (config.range_noise && config.method == Method::PointToPlane && sums.n > 0).then(|| {
        let p = projector_off(&unobservable);
        p * sandwich(&sums) * p
    });
    let asymmetry = ways.map_or_else(Vector6::zeros, |(f, b)| asymmetry(&f, &b, &at_last, &unobservable));
    Ok(IcpResult {
        target_from_source: estimate,
        converged,
        iterations,
        inliers: forward,
        rmse_m,
        start_rmse_m: start_rmse_m.unwrap_or(rmse_m),
        information,
        trace,
        unobservable,
        edge_bias,
        edge_bias_chi2,
        edge_lean,
        edge_lean_chi2,
        range_covariance,
        asymmetry,
        source_centroid: estimate * centre,
    })
}

/// The covariance of the match's estimate with each pair's variance its
/// own squared residual ([`IcpConfig::range_noise`]): the iteration
/// weighs every pair alike (but for the kernel), so it is H⁺·B·H⁺ with
/// B = Σ (w·r)²·JJᵀ, each pair's score by its own residual (the
/// heteroscedasticity-consistent sandwich) — whatever makes a pair
/// noisier, its range from the scanner or its surface.
fn sandwich(sums: &Sums) -> Matrix6<f64> {
    let inverse = pseudo_inverse(&sums.h);
    let c = inverse * sums.scores * inverse;
    0.5 * (c + c.transpose())
}

/// The step the last pass's `sums` would take without some of their
/// pairs (theirs `edge_h`, `edge_b`): δ = H_c⁺(−b_c) − H⁺(−b), the rest's
/// normal equations (H_c, b_c: the sums less those pairs') against all
/// pairs', the `unobservable` directions projected out — without the
/// pairs beyond the edge, [`IcpResult::edge_bias`]; without those and the
/// edge's zone, [`IcpResult::edge_lean`]. Zero when nothing is left out.
/// And δᵀV⁺δ with V what the pairs' noise alone would scatter δ by:
/// δ = (H⁺ − H_c⁺)·b_c + H⁺·b_e (b_e the left-out pairs' share of b), so
/// with each pair's score's variance its own squared residual (the
/// covariance by pair's model: `edge_scores` the left-out pairs' share of
/// `scores`, B_c the rest) V = (H⁺ − H_c⁺)·B_c·(H⁺ − H_c⁺)ᵀ + H⁺·B_e·H⁺;
/// infinite without the scores ([`IcpConfig::range_noise`] off), zero
/// where δ is.
fn without(
    sums: &Sums,
    edge_h: &Matrix6<f64>,
    edge_b: &Vector6<f64>,
    edge_scores: &Matrix6<f64>,
    unobservable: &[Vector6<f64>],
) -> (Vector6<f64>, f64) {
    if *edge_h == Matrix6::zeros() {
        return (Vector6::zeros(), 0.0);
    }
    let (covered, all) = (pseudo_inverse(&(sums.h - edge_h)), pseudo_inverse(&sums.h));
    let p = projector_off(unobservable);
    let d = p * (-(covered * (sums.b - edge_b)) + all * sums.b);
    if !d.iter().all(|v| v.is_finite()) {
        return (Vector6::zeros(), 0.0);
    }
    if sums.scores == Matrix6::zeros() {
        return (d, f64::INFINITY);
    }
    let m = all - covered;
    let v = p * (m * (sums.scores - edge_scores) * m.transpose() + all * edge_scores * all) * p;
    let chi2 = (d.transpose() * pseudo_inverse(&v) * d)[0];
    (d, if chi2.is_finite() { chi2 } else { f64::INFINITY })
}

/// [`IcpResult::asymmetry`] from the last pass's sums each way, `forward`
/// (the source's points into the target) and `back` (the target's into
/// the source at `target_from_source⁻¹`, in its own ξ′ = −Ad(T⁻¹)·ξ as
/// [`Sums::both_ways`] takes it): ½(H_f⁺(−b_f) − H_b⁺(−b_b)) over each
/// way's covered pairs, `unobservable` projected out; zero when not finite.
fn asymmetry(
    forward: &Sums,
    back: &Sums,
    target_from_source: &Isometry3<f64>,
    unobservable: &[Vector6<f64>],
) -> Vector6<f64> {
    let a = -crate::se3::adjoint(&target_from_source.inverse());
    let covered = |s: &Sums| (s.h - s.edge_h - s.zone_h, s.b - s.edge_b - s.zone_b);
    let ((hf, bf), (hb, bb)) = (covered(forward), covered(back));
    let (hb, bb) = (a.transpose() * hb * a, a.transpose() * bb);
    let d = projector_off(unobservable) * (0.5 * (-(pseudo_inverse(&hf) * bf) + pseudo_inverse(&hb) * bb));
    if d.iter().all(|v| v.is_finite()) { d } else { Vector6::zeros() }
}

/// The pseudo-inverse of a symmetric 6×6, singular values below 1e-12 of
/// the largest left out (zero when it cannot be formed).
pub(crate) fn pseudo_inverse(m: &Matrix6<f64>) -> Matrix6<f64> {
    (0.5 * (m + m.transpose())).pseudo_inverse(1e-12 * m.amax()).unwrap_or_else(|_| Matrix6::zeros())
}

/// How `now` moved from `last` (both `target_from_source`), as a pass's
/// distance bounds need it: (the turn of `now · last⁻¹`, the translations'
/// difference) — T_now·p − T_last·p = (R_now − R_last)·p + (t_now − t_last),
/// so a point p moved by at most turn·|p| + difference.
fn motion(now: &Isometry3<f64>, last: &Isometry3<f64>) -> (f64, f64) {
    ((now * last.inverse()).rotation.angle(), (now.translation.vector - last.translation.vector).norm())
}

/// σ̂² per scalar residual: point-to-plane has one per pair, point-to-point three.
fn residual_variance(sums: &Sums, method: Method) -> f64 {
    let scalars = if method == Method::PointToPlane { sums.n } else { 3 * sums.n };
    (sums.sq / scalars.saturating_sub(6).max(1) as f64).max(1e-18)
}

fn check(c: &IcpConfig) -> Result<()> {
    FusionError::require_positive("max correspondence distance (m)", c.max_correspondence_m)?;
    if let Kernel::Huber { width_m } = c.kernel {
        FusionError::require_positive("Huber width (m)", width_m)?;
    }
    FusionError::require_positive("noise scale", c.noise_scale)?;
    FusionError::require_non_negative("translation tolerance (m)", c.translation_tolerance_m)?;
    FusionError::require_non_negative("rotation tolerance (rad)", c.rotation_tolerance_rad)?;
    if let Some(ratio) = c.degeneracy_ratio {
        FusionError::require_positive("degeneracy eigenvalue ratio", ratio)?;
    }
    if let Some(ratio) = c.line_ratio
        && !(ratio.is_finite() && ratio > 0.0 && ratio < 1.0)
    {
        return Err(FusionError::OutOfRange {
            what: "scan-line eigenvalue ratio".into(),
            value: ratio,
            expected: "in (0, 1)".into(),
        });
    }

    for (what, value) in
        [("normal agreement cosine", c.normal_agreement_cos), ("corner eigenvalue ratio", c.corner_ratio)]
    {
        if let Some(v) = value
            && !(v.is_finite() && v > 0.0 && v <= 1.0)
        {
            return Err(FusionError::OutOfRange { what: what.into(), value: v, expected: "in (0, 1]".into() });
        }
    }
    if c.max_iterations == 0 {
        return Err(FusionError::OutOfRange { what: "iteration cap".into(), value: 0.0, expected: "≥ 1".into() });
    }
    Ok(())
}

/// One stage of a coarse-to-fine schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stage {
    /// Reduced-points cell of both clouds, metres.
    pub voxel_m: f64,
    /// Correspondence distance, metres.
    pub max_correspondence_m: f64,
}

/// Runs [`align`] stage by stage (voxel-reducing both clouds each time),
/// each stage starting from the previous result. Returns the last stage's
/// result with the total iteration count.
pub fn align_coarse_to_fine(
    source: &[Point3<f32>],
    target: &[Point3<f32>],
    init: &Isometry3<f64>,
    stages: &[Stage],
    config: &IcpConfig,
) -> Result<IcpResult> {
    let mut estimate = *init;
    let mut last = None;
    let mut total = 0;
    for st in stages {
        let neighbours = if config.method == Method::PointToPlane { config.normal_neighbours } else { 0 };
        let (src, tgt) = rayon::join(
            || scanner::reduced_points(source, st.voxel_m),
            || Target::new(&scanner::reduced_points(target, st.voxel_m)?, neighbours),
        );
        let (src, tgt) = (src?, tgt?);
        let cfg = IcpConfig { max_correspondence_m: st.max_correspondence_m, ..*config };
        let r = align(&src, &tgt, &estimate, &cfg)?;
        estimate = r.target_from_source;
        total += r.iterations;
        last = Some(r);
    }
    let mut r = last.ok_or_else(|| FusionError::OutOfRange {
        what: "number of stages".into(),
        value: 0.0,
        expected: "≥ 1".into(),
    })?;
    r.iterations = total;
    Ok(r)
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// A scene (floor, two walls, a curved wall) sampled twice at random
    /// with 5 mm noise, the two scans overlapping partly. Matched both
    /// ways, A onto B is the inverse of B onto A to the last digits; one
    /// way they differ by millimetres (the one-way match is not
    /// antisymmetric).
    #[test]
    fn a_match_both_ways_does_not_depend_on_which_scan_is_the_source() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut sample = |x0: f64, x1: f64| -> Vec<Point3<f32>> {
            (0..6000)
                .map(|k| {
                    let (a, b): (f64, f64) = (rng.random_range(x0..x1), rng.random_range(0.0..3.0));
                    // A room 6 × 3 × 3 m: floor, side walls (one curved),
                    // a pillar's face across it, and the end wall each
                    // scan reaches.
                    let p: Vector3<f64> = match k % 5 {
                        0 => Vector3::new(a, b - 1.5, 0.0),
                        1 => Vector3::new(a, -1.5, b),
                        2 => Vector3::new(a, 1.5 + 0.2 * (a * 1.3).sin(), b),
                        3 => Vector3::new(2.7, -0.9 + 0.6 * (a - x0) / (x1 - x0), b),
                        _ => Vector3::new(if x0 == 0.0 { 0.0 } else { 6.0 }, b - 1.5, rng.random_range(0.0..3.0)),
                    };
                    let n: Vector3<f64> = Vector3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    );
                    Point3::from((p + 0.005 * n).cast::<f32>())
                })
                .collect()
        };
        let (a, b_world) = (sample(0.0, 4.0), sample(1.5, 6.0));
        // B in its own frame: B_world = truth · B.
        let truth = Isometry3::from_parts(
            nalgebra::Translation3::new(1.2, 0.3, 0.1),
            UnitQuaternion::from_euler_angles(0.02, -0.01, 0.3),
        );
        let b: Vec<Point3<f32>> = b_world.iter().map(|p| (truth.inverse() * p.cast::<f64>()).cast()).collect();
        let target = |p: &[Point3<f32>]| Target::new(p, 10).expect("target");
        let (ta, tb) = (target(&a), target(&b));
        let config = IcpConfig {
            max_correspondence_m: 0.3,
            max_iterations: 100,
            translation_tolerance_m: 1e-8,
            rotation_tolerance_rad: 1e-8,
            ..IcpConfig::default()
        };
        let off = Isometry3::from_parts(
            nalgebra::Translation3::new(0.03, -0.02, 0.01),
            UnitQuaternion::from_euler_angles(0.0, 0.005, -0.01),
        );
        // a_from_b, matched with B as the source and with A as the source.
        let both = |source: &[Point3<f32>], st: &Target, tt: &Target, points: &[Point3<f32>], init: &Isometry3<f64>| {
            let reverse = Reverse { points, model: st };
            align_both(source, tt, init, &config, Partners::new(source.len()), reverse).expect("both ways")
        };
        let ab_from_b = both(&b, &tb, &ta, &a, &(off * truth));
        let ab_from_a = both(&a, &ta, &tb, &b, &(off * truth).inverse()).target_from_source.inverse();
        assert!(ab_from_b.converged);
        let gap = |x: &Isometry3<f64>, y: &Isometry3<f64>| {
            let d = x.inverse() * y;
            (d.rotation.angle(), d.translation.vector.norm())
        };
        let (rot, m) = gap(&ab_from_b.target_from_source, &ab_from_a);
        assert!(rot < 1e-7 && m < 1e-7, "both ways: {rot} rad, {m} m apart by which is the source");
        let one_b = align(&b, &ta, &(off * truth), &config).expect("one way").target_from_source;
        let one_a = align(&a, &tb, &(off * truth).inverse(), &config).expect("one way").target_from_source.inverse();
        let (one_rot, one_m) = gap(&one_b, &one_a);
        // (2.5 mrad and 1.7 mm apart here.)
        assert!(one_m > 5e-4, "one way: {one_rot} rad, {one_m} m apart");
        // The asymmetry is half the step between the two one-way matches,
        // each converged on its own (the asymmetry linearises them at the
        // both-ways estimate, its pairs held).
        let half = 0.5 * crate::se3::left_difference(&one_b, &one_a);
        let d = ab_from_b.asymmetry;
        let (cos, ratio) = (d.normalize().dot(&half.normalize()), d.norm() / half.norm());
        assert!(
            cos > 0.95 && (0.8..1.25).contains(&ratio),
            "asymmetry {d:?} against {half:?}: cos {cos}, ratio {ratio}"
        );
        // One way there is none.
        assert_eq!(align(&b, &ta, &(off * truth), &config).expect("one way").asymmetry, Vector6::zeros());
        // And both ways lands on the truth.
        let (err_rot, err_m) = gap(&ab_from_b.target_from_source, &truth);
        assert!(err_rot < 1.5e-3 && err_m < 3e-3, "{err_rot} rad, {err_m} m off the truth");
        // Its information is one match's, not two: the two ways see the
        // same pairs from either side.
        let one = align(&b, &ta, &ab_from_b.target_from_source, &config).expect("one way");
        let ratio = ab_from_b.information.trace() / one.information.trace();
        assert!((0.5..2.0).contains(&ratio), "information both ways / one way: {ratio}");
    }

    /// Points every `step` metres on the rectangle `corner + a·u + b·v`,
    /// a, b ∈ [0, 1].
    fn grid(corner: [f64; 3], u: [f64; 3], v: [f64; 3], step: f64) -> Vec<Vector3<f64>> {
        let (c, u, v) = (Vector3::from(corner), Vector3::from(u), Vector3::from(v));
        let (nu, nv) = ((u.norm() / step) as usize, (v.norm() / step) as usize);
        (0..=nu)
            .flat_map(|i| (0..=nv).map(move |j| c + u * (i as f64 / nu as f64) + v * (j as f64 / nv as f64)))
            .collect()
    }

    /// A plate 0.1 m thick between two scanners: the target (scanner at
    /// x = −3) sees its face x = 0, the source (scanner at x = +3, its
    /// frame's origin) its back x = 0.1; both see a floor, a side wall and
    /// an end wall at x = 5. Pairing the back with the face pulls the
    /// source 0.1 m towards the target's scanner, weighted by how many
    /// pairs that is; rejecting back faces leaves only surfaces both saw,
    /// and the known pose comes out exactly.
    #[test]
    fn back_faces_are_rejected() {
        let common: Vec<Vector3<f64>> = [
            grid([-3.0, -2.0, -1.0], [8.0, 0.0, 0.0], [0.0, 4.0, 0.0], 0.1), // floor
            grid([-3.0, -2.0, -1.0], [8.0, 0.0, 0.0], [0.0, 0.0, 3.0], 0.1), // side wall
            grid([5.0, -2.0, -1.0], [0.0, 4.0, 0.0], [0.0, 0.0, 3.0], 0.1),  // end wall
        ]
        .concat();
        let face = grid([0.0, -0.5, -0.5], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], 0.05);
        let back: Vec<Vector3<f64>> = face.iter().map(|p| p + Vector3::new(0.1, 0.0, 0.0)).collect();
        let cast = |v: &[Vector3<f64>]| -> Vec<Point3<f32>> { v.iter().map(|p| Point3::from(p.cast())).collect() };
        let mut target = Target::new(&cast(&[common.clone(), face].concat()), 10).expect("target");
        let eye = Vector3::new(3.0, 0.0, 0.0);
        let truth = Isometry3::translation(eye.x, eye.y, eye.z);
        let source: Vec<Vector3<f64>> = [common, back].concat().iter().map(|p| p - eye).collect();
        let source = cast(&source);
        let config = IcpConfig { max_correspondence_m: 0.5, ..IcpConfig::default() };
        let rejecting = IcpConfig { reject_back_faces: true, ..config };

        assert!(!target.has_oriented_normals());
        let e = align(&source, &target, &truth, &rejecting).expect_err("normals not oriented yet");
        assert!(e.to_string().contains("oriented towards"), "{e}");
        target.orient_normals_towards(&Point3::new(-3.0, 0.0, 0.0));
        assert!(target.has_oriented_normals());
        for (n, q) in target.normals().iter().zip(target.points()) {
            assert!(n.dot(&(Vector3::new(-3.0, 0.0, 0.0) - q.coords.cast())) >= 0.0);
        }
        let start = Isometry3::translation(0.05, -0.03, 0.02) * truth;
        let plain = align(&source, &target, &start, &config).expect("plain");
        let clean = align(&source, &target, &start, &rejecting).expect("rejecting");
        let along = |r: &IcpResult| (r.target_from_source.translation.vector - eye).x;
        assert!(along(&plain) < -0.01, "the back pulls the source back: {} m", along(&plain));
        assert!((clean.target_from_source.translation.vector - eye).norm() < 1e-4, "{}", clean.target_from_source);
        assert!(clean.target_from_source.rotation.angle_to(&truth.rotation) < 1e-5);
        assert_eq!(clean.inliers, source.len() - 21 * 21, "every back point left out, nothing else");

        // The same source in a frame whose origin is in front of the plate
        // (x = −1), its scanner still at x = 3: only with the scanner's
        // place given are the back points left out.
        let origin = Vector3::new(-1.0, 0.0, 0.0);
        let moved: Vec<Point3<f32>> =
            source.iter().map(|p| Point3::from((p.coords.cast() + eye - origin).cast())).collect();
        let truth = Isometry3::translation(origin.x, origin.y, origin.z);
        let start = Isometry3::translation(0.05, -0.03, 0.02) * truth;
        let unplaced = align(&moved, &target, &start, &rejecting).expect("scanner taken at the origin");
        let placed = IcpConfig { source_viewpoint: Point3::from(eye - origin), ..rejecting };
        let placed = align(&moved, &target, &start, &placed).expect("scanner placed");
        let along = |r: &IcpResult| (r.target_from_source.translation.vector - origin).x;
        assert!(along(&unplaced) < -0.01, "a wrong viewpoint keeps the back: {} m", along(&unplaced));
        assert!((placed.target_from_source.translation.vector - origin).norm() < 1e-4, "{}", placed.target_from_source);
        assert_eq!(placed.inliers, clean.inliers);
    }

    /// Horn recovers an exact rotation from noiseless pairs.
    #[test]
    fn horn_exact() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let truth = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
        let ps: Vec<Vector3<f64>> = (0..50)
            .map(|_| {
                Vector3::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0))
            })
            .collect();
        let cp = ps.iter().sum::<Vector3<f64>>() / 50.0;
        let s = ps.iter().fold(Matrix3::zeros(), |s, p| s + (p - cp) * (truth * (p - cp)).transpose());
        assert!(horn_rotation(&s).angle_to(&truth) < 1e-12);
    }
}
