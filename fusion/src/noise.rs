//! What the data's noise does to a match, measured on the data: each scan
//! dealt into two random halves, the second put in a frame of its own by
//! a known turn, and the halves matched as the set's pairs are matched —
//! where the truth is known. The halves' errors
//! against their own reported covariances say by how much the covariance
//! model misjudges these data ([`calibrate`]), and two quarters of each
//! scan, matched alike, how that changes with the density: the factor is
//! carried on to the scans' own ([`at_full_density`]). The set's
//! covariances are scaled by it ([`crate::icp::IcpConfig::noise_scale`],
//! [`crate::links::LinkConfig::range_scale`]).
//!
//! Why it is needed: a match's covariance treats its pairs' scores as
//! independent. On real scans they are not quite — neighbouring pairs
//! share normals, the nearest-neighbour association follows the noise,
//! a range error is common to a beam's neighbours — and how far that goes
//! depends on the scanner and the scene: on random shares of three real
//! scans the same model was 1.7× optimistic on one and 3.4× and 1.9×
//! pessimistic on the others, and no formula of the residuals alone
//! (a sandwich estimate, tried) told them apart (BENCHMARKS.md,
//! "Covariances the data calibrate"). What halves of one scan cannot
//! show is noise common to both (a beam's range bias).

use nalgebra::{Isometry3, Matrix6, Point3, Vector6};
use rayon::prelude::*;

use crate::icp::Method;
use crate::icp::correspondences::Partners;
use crate::icp::degeneracy::projector_off;
use crate::icp::solve::{Reverse, align_both, align_from};
use crate::multiview::MultiviewConfig;

/// Random halvings of each scan, at least ([`halvings`]).
pub const HALVINGS: u64 = 2;

/// Random halvings of each scan, at most ([`halvings`]).
pub const MAX_HALVINGS: u64 = 4;

/// The degrees of freedom the halves' calibration aims at ([`halvings`]):
/// 6 a halving, so 96 is 16 halvings. The calibration is a χ² over its
/// degrees of freedom: on 48 (two halvings of four scans) it scattered
/// from one set of scans to the next with a standard deviation of
/// 0.23–0.32 in its logarithm (the quarters' step on to full density
/// counts the halves' error twice where it is taken), and every
/// covariance of the set with it — on random shares of three real scans
/// the reported covariance's size followed it (correlation 0.84–0.94)
/// while the actual errors did not (0.01–0.06), the NEES swinging with
/// it. On 96, 0.17–0.22, each trial's NEES nearer the χ² law; on 192,
/// 0.12–0.17 but at twice the cost for little more (BENCHMARKS.md, "The
/// calibration's own scatter").
pub const CALIBRATION_DOF: usize = 96;

/// How many random halvings of each of `scans` scans the calibration
/// matches: enough for [`CALIBRATION_DOF`], between [`HALVINGS`] and
/// [`MAX_HALVINGS`] — a set of eight scans or more needs no more than
/// two each, five or fewer get four (a pair 48 degrees of freedom).
pub fn halvings(scans: usize) -> u64 {
    (CALIBRATION_DOF.div_ceil(6 * scans.max(1)) as u64).clamp(HALVINGS, MAX_HALVINGS)
}

/// A halving whose χ² per degree of freedom exceeds this many times the
/// halvings' median is a mismatch of a half (a scene that repeats, too
/// few points), not the noise: it is left out.
const GROSS: f64 = 25.0;

/// The noise calibration of a set ([`calibrate`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// The factor on every covariance of the set's finest matches: the
    /// halves' Σ χ² / Σ degrees of freedom against their covariances,
    /// carried on to the scans' own density by the quarters'
    /// ([`at_full_density`]); 1 when nothing could be measured.
    pub variance_scale: f64,
    /// The halves' degrees of freedom (6 a halving, less its blind
    /// directions); 0 when nothing could be measured.
    pub dof: usize,
    /// Halvings matched.
    pub halvings: usize,
    /// Halvings left out as gross mismatches (χ²/dof beyond 25× the median).
    pub left_out: usize,
    /// The same against the covariance by pair
    /// ([`crate::icp::IcpResult::range_covariance`]: each pair's variance
    /// its own squared residual; the name is its first model's, by range
    /// from the scanner): the factor on it (1 when nothing could be
    /// measured).
    pub range_scale: f64,
    /// The same for the covariance by pair's rotation and its translation
    /// apart, each about the source's centroid (frame-free: [`by_blocks`]):
    /// the halves' mean χ² of each block against its own 3×3 block, over
    /// 3, carried on to the scans' own density by the quarters' — from
    /// the halvings that see all six directions; `range_scale` both where
    /// none does. The covariance by pair can misjudge the two by
    /// different factors: halves of random quarters of a 3DTK hall scan
    /// 1.67 and 1.51 where `range_scale` is 1.46, those of the whole
    /// scans 1.26 and 1.92 where it is 1.61 (BENCHMARKS.md).
    pub rotation_scale: f64,
    /// See [`rotation_scale`](Self::rotation_scale).
    pub translation_scale: f64,
    /// How far each halving's two ways disagree
    /// ([`crate::icp::IcpResult::asymmetry`] Δ): the halves' mean ΔᵀC⁻¹Δ
    /// against their covariance by pair C calibrated (× `range_scale`) —
    /// what the scans' noise alone makes of Δ, one scan's halves sharing
    /// its viewpoint and sampling —, carried on to the scans' own density
    /// by the quarters' ([`at_full_density`]: the hall's halves 5.4, its
    /// quarters 3.9). 0 when nothing could be measured, or matched one
    /// way. Beyond it, the links' Δ is their scans' sampling
    /// ([`crate::links`]).
    pub asymmetry: f64,
    /// What the halves measured.
    pub halves: Shares,
    /// What two quarters of each scan measured, matched as the halves are.
    pub quarters: Shares,
}

/// What one density of shares measured ([`Calibration`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shares {
    /// Σ χ² / Σ degrees of freedom against the covariance from one
    /// variance for all pairs (1 when nothing could be measured).
    pub variance_scale: f64,
    /// The same against the covariance by pair.
    pub range_scale: f64,
    /// The mean χ² of the covariance by pair's rotation block and of its
    /// translation block about the source's centroid, over 3, from the
    /// shares that see all six directions ([`Calibration::rotation_scale`]);
    /// `None` when none does.
    pub blocks: Option<(f64, f64)>,
    /// The mean ΔᵀC⁻¹Δ of the shares' two ways
    /// ([`crate::icp::IcpResult::asymmetry`]) against their covariance by
    /// pair C (not scaled); 0 matched one way.
    pub asymmetry: f64,
    /// The degrees of freedom they rest on.
    pub dof: usize,
    /// Shares matched.
    pub matched: usize,
    /// Shares left out as gross mismatches.
    pub left_out: usize,
}

/// The most a doubling of the density is taken to multiply a factor by
/// ([`at_full_density`]).
pub const DENSITY_STEP_MAX: f64 = 2.0;

/// A factor measured on halves (`halves`) and on quarters (`quarters`)
/// carried on to the scans' own density: × (halves / quarters), the
/// step from quarters to halves, between 1 and [`DENSITY_STEP_MAX`].
/// Denser shares misjudge more — the nearest neighbour follows the noise
/// where the noise is not small beside the spacing: on the boards of
/// `fusion/tests/covariance.rs` the covariance by range (the first model of the covariance by pair) was 1.8, 2.1, 2.4
/// and 2.8× optimistic at 3,000, 6,000, 12,000 and 24,000 points a scan
/// (no kernel), so halves alone under-calibrate the scans they come from
/// (real scans' parts: 1.2–1.75× optimistic, BENCHMARKS.md). The step is a
/// ratio of two noisy measurements, hence bounded: a step below 1 is
/// taken as none.
pub fn at_full_density(halves: f64, quarters: f64) -> f64 {
    halves * (halves / quarters).clamp(1.0, DENSITY_STEP_MAX)
}

/// Each scan dealt into two halves by a mixing hash of its points'
/// indices (`share`; [`halvings`] times, each time another salt), the
/// second half turned about the scanner (`turned`), the halves reduced as
/// `config` reduces the scans and matched from near that turn (`off`) —
/// both ways when `both_ways` (point-to-plane) — with `config`'s ICP
/// settings and no noise scale. Each halving's error ξ against the turn
/// gives χ² = ξᵀ·I·ξ with I its reported information, whose mean is the
/// observed degrees of freedom when I is honest — and the same against
/// its covariance by pair
/// ([`crate::icp::IcpResult::range_covariance`]: `range_scale`). A
/// half that cannot be matched (too few points, no more pairs than
/// `min_pairs`) is passed over. The same again with two quarters of each
/// scan (halves of a half): the factors are carried from the halves' to
/// the scans' own density by their step from the quarters'
/// ([`at_full_density`]).
pub fn calibrate<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    config: &MultiviewConfig,
    both_ways: bool,
) -> Calibration {
    let icp = crate::icp::IcpConfig { noise_scale: 1.0, trace: false, range_noise: true, ..config.icp };
    let halves = pooled(&shares(scans, config, both_ways, icp, 1));
    let quarters = pooled(&shares(scans, config, both_ways, icp, 2));
    let range_scale = at_full_density(halves.range_scale, quarters.range_scale);
    let (rotation_scale, translation_scale) = match (halves.blocks, quarters.blocks) {
        (Some(h), Some(q)) => (at_full_density(h.0, q.0), at_full_density(h.1, q.1)),
        (Some(h), None) => h,
        _ => (range_scale, range_scale),
    };
    Calibration {
        variance_scale: at_full_density(halves.variance_scale, quarters.variance_scale),
        dof: halves.dof,
        halvings: halves.matched,
        left_out: halves.left_out,
        range_scale,
        rotation_scale,
        translation_scale,
        asymmetry: if halves.asymmetry > 0.0 && quarters.asymmetry > 0.0 {
            at_full_density(halves.asymmetry, quarters.asymmetry) / range_scale
        } else {
            0.0
        },
        halves,
        quarters,
    }
}

/// Each scan's shares matched, each share `1 / 2^bits` of its points
/// (halves: 1; quarters: 2), as [`calibrate`] says.
fn shares<S: AsRef<[Point3<f32>]> + Sync>(
    scans: &[S],
    config: &MultiviewConfig,
    both_ways: bool,
    icp: crate::icp::IcpConfig,
    bits: u32,
) -> Vec<Sample> {
    let count = halvings(scans.len());
    let jobs: Vec<(usize, u64)> = (0..scans.len()).flat_map(|i| (0..count).map(move |h| (i, h))).collect();
    jobs.par_iter()
        .filter_map(|&(i, h)| {
            let points = scans[i].as_ref();
            let salt = (i as u64).wrapping_mul(0xD1B5_4A32_D192_ED03) ^ (h + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            // The second half in a frame of its own, turned about the
            // scanner: in one frame the two halves' reduced points fall in
            // the same cells, which ties them (one link of the 3DTK scan's
            // shares: calibrated NEES 10.5 without the turn, 9.2 with it).
            let truth = turned(&icp.source_viewpoint, h);
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for (j, p) in points.iter().enumerate() {
                match share(j as u64 ^ salt, bits) {
                    0 => a.push(*p),
                    1 => b.push((truth * p.cast::<f64>()).cast::<f32>()),
                    _ => {}
                }
            }
            // Reduced and modelled as the set's scans are.
            let halves = crate::multiview::prepare(&[a, b], config).ok()?;
            let (sa, ta, sb, tb) = (&halves[0].source, &halves[0].local, &halves[1].source, &halves[1].local);
            let start = off(sa, &truth, icp.max_correspondence_m);
            let partners = Partners::at(sa, tb, &start);
            let r = if both_ways && icp.method == Method::PointToPlane {
                align_both(sa, tb, &start, &icp, partners, Reverse { points: sb, model: ta })
            } else {
                align_from(sa, tb, &start, &icp, partners)
            }
            .ok()?;
            if r.inliers <= config.min_pairs {
                return None;
            }
            let xi = crate::se3::left_difference(&r.target_from_source, &truth);
            let dof = 6 - r.unobservable.len().min(6);
            let chi2 = (xi.transpose() * r.information * xi)[0];
            let information = r.range_covariance.map(|c| {
                // The covariance by pair has nothing along its blind
                // directions, but rounding leaves a trace there that a
                // pseudo-inverse may keep (a pipe's halves slid along its
                // axis gave 10¹³): judged along what the match sees.
                c.pseudo_inverse(1e-12 * c.amax()).unwrap_or_else(|_| nalgebra::Matrix6::zeros())
            });
            let by_range = information.map(|information| {
                let seen = projector_off(&r.unobservable) * xi;
                (seen.transpose() * information * seen)[0]
            });
            let by_range = by_range.filter(|c| c.is_finite()).unwrap_or(chi2);
            let asymmetry = information
                .map(|information| (r.asymmetry.transpose() * information * r.asymmetry)[0])
                .filter(|c| c.is_finite())
                .unwrap_or(0.0);
            let blocks = r
                .range_covariance
                .filter(|_| r.unobservable.is_empty())
                .and_then(|c| blocks_chi2(&xi, &c, &r.source_centroid));
            (dof > 0 && chi2.is_finite()).then_some(Sample { chi2, by_range, dof, asymmetry, blocks })
        })
        .collect()
}

/// Which of `2^bits` shares the point with salted index `key` goes to:
/// the top `bits` of SplitMix64's finaliser, a hash whose every output bit
/// depends on every input bit. Not a multiplicative hash (`key ×` an odd
/// constant, as Fibonacci hashing): on consecutive indices — a scan line's
/// neighbours — its top bits follow a low-discrepancy sequence, and the
/// next point fell in the same half 37 % of the time (the same quarter
/// 12 %) where a random split gives 50 % (25 %). Such halves interleave
/// along every line, far more alike than two scans' samples are, and
/// quarters misled the step to full density: on the 3DTK set's scans
/// the quarters' factor was 6.2 where the halves' was 1.6 (dealt by this
/// hash, 1.8 and 1.8; BENCHMARKS.md, "Halves dealt at random").
pub(crate) fn share(key: u64, bits: u32) -> u64 {
    let mut z = key.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) >> (64 - bits)
}

/// The second half's frame of halving `h`: turned 0.4 + 0.3·h rad about
/// an axis through the scanner (`viewpoint`, which stays where it is, so
/// back faces are judged as in the first half's frame).
fn turned(viewpoint: &Point3<f64>, h: u64) -> Isometry3<f64> {
    let axis = nalgebra::Unit::new_normalize(nalgebra::Vector3::new(0.3, -0.5, 1.0));
    let turn = nalgebra::UnitQuaternion::from_axis_angle(&axis, 0.4 + 0.3 * h as f64);
    Isometry3::from_parts(nalgebra::Translation3::from(viewpoint.coords - turn * viewpoint.coords), turn)
}

/// Where a halving's match starts: `truth` off by a quarter of the
/// correspondence distance along a fixed direction of ξ, rotation counted
/// at the source's RMS radius — as a finest stage starts from a coarser
/// stage's result. From
/// the truth itself the match stops within its tolerances of where it
/// started, nearer than a match that comes from elsewhere ends.
fn off(source: &[Point3<f32>], truth: &Isometry3<f64>, max_correspondence_m: f64) -> Isometry3<f64> {
    let (_, radius) = crate::icp::degeneracy::centroid_and_lever_arm(source);
    let d = 0.25 * max_correspondence_m;
    let xi = nalgebra::Vector6::new(0.6, -0.3, 0.74, -0.5, 0.8, 0.33).normalize();
    let xi = nalgebra::Vector6::new(
        xi[0] * d / radius,
        xi[1] * d / radius,
        xi[2] * d / radius,
        xi[3] * d,
        xi[4] * d,
        xi[5] * d,
    );
    crate::se3::exp(&xi) * truth
}

/// One matched share ([`shares`]).
struct Sample {
    /// χ² against its reported information.
    chi2: f64,
    /// χ² against its covariance by pair.
    by_range: f64,
    /// Its degrees of freedom.
    dof: usize,
    /// ΔᵀC⁻¹Δ of its two ways against its covariance by pair (0 one way).
    asymmetry: f64,
    /// Its rotation's and its translation's χ² about the source's
    /// centroid, each against its own block of the covariance by pair
    /// ([`blocks_chi2`]); `None` with blind directions.
    blocks: Option<(f64, f64)>,
}

/// ξ = (ω, v) (left, its frame) and its covariance `cov` about the point
/// `c` rather than the frame's origin: v − c × ω, the motion there — ξ in
/// the frame moved to `c`, the adjoint of the translation by −c:
/// `A = [I 0; −[c]× I]`.
fn about(c: &Point3<f64>) -> Matrix6<f64> {
    crate::se3::adjoint(&Isometry3::translation(-c.x, -c.y, -c.z))
}

/// The χ² of `xi`'s rotation and of its translation about `c`, each
/// against its own 3×3 block of `cov` about `c` ([`about`]); `None` when
/// a block is singular or a χ² not finite.
fn blocks_chi2(xi: &Vector6<f64>, cov: &Matrix6<f64>, c: &Point3<f64>) -> Option<(f64, f64)> {
    let a = about(c);
    let (x, cov) = (a * xi, a * cov * a.transpose());
    let block = |k: usize| {
        let part = x.fixed_rows::<3>(k).into_owned();
        let inverse = cov.fixed_view::<3, 3>(k, k).into_owned().try_inverse()?;
        Some((part.transpose() * inverse * part)[0]).filter(|v| v.is_finite())
    };
    Some((block(0)?, block(3)?))
}

/// `cov` (of ξ = (ω, v), left, its frame) with its rotation scaled by
/// `rotation` and its translation by `translation`, both about the point
/// `c` (in the same frame): A⁻¹·D·(A·cov·Aᵀ)·D·A⁻ᵀ with `A = [I 0; −[c]× I]`
/// (ξ about `c`: v − c × ω) and D = diag(√rotation I, √translation I). About the
/// source's centroid the split is the same in every frame — where the
/// frame's origin lies far from the points (a national grid), a turn
/// about it is mostly translation. Equal factors scale `cov` alone.
pub fn by_blocks(cov: &Matrix6<f64>, c: &Point3<f64>, rotation: f64, translation: f64) -> Matrix6<f64> {
    let (a, back) = (about(c), about(&Point3::from(-c.coords)));
    let (r, t) = (rotation.sqrt(), translation.sqrt());
    let d = Matrix6::from_diagonal(&Vector6::new(r, r, r, t, t, t));
    let scaled = back * d * (a * cov * a.transpose()) * d * back.transpose();
    0.5 * (scaled + scaled.transpose())
}

/// Σ χ² / Σ dof of the samples, those whose χ²/dof is beyond [`GROSS`]
/// times the median left out, and their mean asymmetry.
fn pooled(samples: &[Sample]) -> Shares {
    let mut ratios: Vec<f64> = samples.iter().map(|s| s.chi2 / s.dof as f64).collect();
    ratios.sort_by(f64::total_cmp);
    let median = ratios.get(ratios.len() / 2).copied().unwrap_or(0.0);
    let kept: Vec<&Sample> = samples.iter().filter(|s| s.chi2 / s.dof as f64 <= GROSS * median.max(1e-12)).collect();
    let dof: usize = kept.iter().map(|s| s.dof).sum();
    let scale = |chi2: f64| if dof > 0 && chi2 > 0.0 { chi2 / dof as f64 } else { 1.0 };
    Shares {
        variance_scale: scale(kept.iter().map(|s| s.chi2).sum()),
        range_scale: scale(kept.iter().map(|s| s.by_range).sum()),
        asymmetry: if kept.is_empty() {
            0.0
        } else {
            kept.iter().map(|s| s.asymmetry).sum::<f64>() / kept.len() as f64
        },
        blocks: {
            let blocks: Vec<(f64, f64)> = kept.iter().filter_map(|s| s.blocks).collect();
            let n = 3.0 * blocks.len() as f64;
            (!blocks.is_empty())
                .then(|| (blocks.iter().map(|b| b.0).sum::<f64>() / n, blocks.iter().map(|b| b.1).sum::<f64>() / n))
        },
        dof,
        matched: samples.len(),
        left_out: samples.len() - kept.len(),
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion, Vector3};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    use super::*;
    use crate::icp::{IcpConfig, Kernel, Target};

    /// A room's corner with a wavy floor, sampled at random, each point
    /// off along a random direction by a mixture: 75 % σ 1 mm, 25 %
    /// σ 40 mm (a sharp core and heavy tails, as real scans' residuals).
    fn scan(rng: &mut ChaCha8Rng) -> Vec<Point3<f32>> {
        let (core, tail) = (Normal::new(0.0, 0.001).expect("σ"), Normal::new(0.0, 0.04).expect("σ"));
        (0..40_000)
            .map(|i| {
                let (u, v): (f64, f64) = (rng.random_range(0.2..4.0), rng.random_range(0.2..4.0));
                let p = match i % 3 {
                    0 => Vector3::new(u, v, 0.05 * (1.3 * u).sin() * (0.9 * v).cos()),
                    1 => Vector3::new(0.0, u, 0.7 * v),
                    _ => Vector3::new(u, 0.0, 0.7 * v),
                };
                let d =
                    Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                        .normalize();
                let s = if rng.random_bool(0.25) { tail.sample(rng) } else { core.sample(rng) };
                Point3::from((p + d * s).cast::<f32>())
            })
            .collect()
    }

    fn config() -> MultiviewConfig {
        MultiviewConfig {
            icp: IcpConfig {
                max_correspondence_m: 0.15,
                kernel: Kernel::Huber { width_m: 0.01 },
                source_viewpoint: Point3::new(2.0, 2.0, 1.5),
                degeneracy_ratio: Some(1e-3),
                ..IcpConfig::default()
            },
            source_voxel_m: 0.05,
            target_voxel_m: 0.05,
            min_pairs: 100,
            ..MultiviewConfig::default()
        }
    }

    /// The calibration is what Monte Carlo finds: two scans of the same
    /// corner with independent noise, matched as a link is from near the
    /// truth, 24 times — their mean χ² against the match's own information
    /// is far below 6 (the residuals' mean square counts the tails the
    /// kernel bounds: 0.30–0.47 of it over seeds 38–43), and against it
    /// scaled by the calibration of four scans' halves within 1.8× (0.89,
    /// 1.00, 1.21, 1.03, 0.85, 1.32 of it over seeds 38–43 on their 16
    /// halvings dealt by [`share`]; 0.61, 1.35, 1.07, 0.93, 0.85, 1.26
    /// dealt by a multiplicative hash; 0.69, 2.07, 1.15, 0.87 over 38–41
    /// on the 8 halvings they had before [`CALIBRATION_DOF`]: on such tails
    /// a halving's χ² spreads wider than χ²₆, and 24 trials measure the
    /// truth to ±25 %). The factor carried on to full density by the
    /// quarters is not asserted: these scans' density changes only how
    /// many points a voxel's mean rests on, and on such tails the step
    /// from the quarters is noise (0.89, 0.90, 1.21, 1.03, 0.75, 1.32 of
    /// it over seeds 38–43).
    #[test]
    fn the_calibration_makes_a_match_s_covariance_what_monte_carlo_finds() {
        let mut rng = ChaCha8Rng::seed_from_u64(38);
        let c = config();
        let scans: Vec<Vec<Point3<f32>>> = (0..4).map(|_| scan(&mut rng)).collect();
        let calibration = calibrate(&scans, &c, false);
        assert_eq!((calibration.halvings, calibration.left_out), (16, 0));
        assert_eq!(calibration.dof, 96);
        let trials = 24;
        let mut raw = 0.0;
        for _ in 0..trials {
            let (a, b) = (scan(&mut rng), scan(&mut rng));
            let truth = Isometry3::from_parts(
                Translation3::new(rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5), 0.1),
                UnitQuaternion::from_euler_angles(0.02, -0.01, rng.random_range(-0.8..0.8)),
            );
            let b: Vec<Point3<f32>> = b.iter().map(|p| (truth * p.cast::<f64>()).cast::<f32>()).collect();
            let source = scanner::reduced_points(&a, c.source_voxel_m).expect("reduced");
            let mut target =
                Target::new(&scanner::reduced_points(&b, c.target_voxel_m).expect("reduced"), 10).expect("target");
            target.orient_normals_towards(&(truth * c.icp.source_viewpoint));
            let start = off(&source, &truth, c.icp.max_correspondence_m);
            let r = crate::icp::align(&source, &target, &start, &c.icp).expect("matches");
            let xi = crate::se3::left_difference(&r.target_from_source, &truth);
            raw += (xi.transpose() * r.information * xi)[0];
        }
        let raw = raw / (6 * trials) as f64;
        let calibrated = raw / calibration.halves.variance_scale;
        assert!(!(0.5..2.0).contains(&raw), "uncalibrated {raw}");
        assert!(
            (0.55..1.8).contains(&calibrated),
            "calibrated {calibrated} (scale {})",
            calibration.halves.variance_scale
        );
    }

    /// A gross halving (a mismatch) is left out of the pool, noise is not.
    #[test]
    fn gross_halvings_are_left_out() {
        let sample = |chi2, by_range, asymmetry, blocks| Sample { chi2, by_range, dof: 6, asymmetry, blocks };
        let c = pooled(&[
            sample(6.0, 12.0, 2.0, Some((3.0, 9.0))),
            sample(5.0, 10.0, 3.0, Some((6.0, 3.0))),
            sample(7.0, 14.0, 4.0, None),
            sample(600.0, 1.0, 90.0, Some((300.0, 300.0))),
        ]);
        assert_eq!((c.left_out, c.dof, c.matched), (1, 18, 4));
        assert!((c.variance_scale - 1.0).abs() < 1e-12);
        assert!((c.range_scale - 2.0).abs() < 1e-12);
        assert!((c.asymmetry - 3.0).abs() < 1e-12);
        // The blocks from the kept samples that have them, over 3.
        let (rotation, translation) = c.blocks.expect("blocks");
        assert!((rotation - 1.5).abs() < 1e-12 && (translation - 2.0).abs() < 1e-12, "{:?}", c.blocks);
        let none = pooled(&[]);
        assert_eq!((none.variance_scale, none.dof, none.blocks), (1.0, 0, None));
    }

    /// A covariance scaled by blocks about a point: sampled errors whose
    /// rotation is stretched by √fr and whose motion at the point by √ft
    /// (ω' = √fr·ω, v' = √ft·(v − c×ω) + c×ω') have it as their covariance
    /// (Monte Carlo), and judged against the unscaled covariance their
    /// blocks' mean χ² is 3·fr and 3·ft — what the calibration measures
    /// is what the links take. Equal factors scale the covariance alone,
    /// and the scaling is the same in every frame (the adjoint).
    #[test]
    fn a_covariance_scaled_by_blocks_about_a_point_is_what_its_errors_have() {
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let l = Matrix6::from_fn(|r, c| if r >= c { 0.3 + 0.1 * (r as f64) - 0.07 * (c as f64) } else { 0.0 })
            + Matrix6::from_diagonal(&Vector6::new(0.01, 0.02, 0.015, 0.5, 0.4, 0.6));
        let cov = l * l.transpose() * 1e-4;
        let c = Point3::new(40.0, -25.0, 3.0);
        let (fr, ft) = (2.5, 0.6);
        let scaled = by_blocks(&cov, &c, fr, ft);
        let n = 40_000;
        let mut sum = Matrix6::zeros();
        let (mut rotation, mut translation) = (0.0, 0.0);
        for _ in 0..n {
            let z = Vector6::from_fn(|_, _| StandardNormal.sample(&mut rng));
            let xi = l * z * 1e-2;
            let w = xi.fixed_rows::<3>(0).into_owned();
            let at_c = xi.fixed_rows::<3>(3) - c.coords.cross(&w);
            let w2 = w * fr.sqrt();
            let v2 = at_c * ft.sqrt() + c.coords.cross(&w2);
            let stretched = Vector6::new(w2.x, w2.y, w2.z, v2.x, v2.y, v2.z);
            sum += stretched * stretched.transpose();
            let (r, t) = blocks_chi2(&stretched, &cov, &c).expect("blocks");
            rotation += r;
            translation += t;
        }
        let sampled = sum / n as f64;
        for i in 0..6 {
            for j in 0..6 {
                let tolerance = 0.03 * (scaled[(i, i)] * scaled[(j, j)]).sqrt();
                assert!((sampled[(i, j)] - scaled[(i, j)]).abs() < tolerance, "({i}, {j}): {sampled} against {scaled}");
            }
        }
        let (rotation, translation) = (rotation / (3 * n) as f64, translation / (3 * n) as f64);
        assert!(
            (rotation / fr - 1.0).abs() < 0.03 && (translation / ft - 1.0).abs() < 0.03,
            "{rotation} {translation}"
        );

        let same = by_blocks(&cov, &c, 1.7, 1.7);
        assert!((same - cov * 1.7).amax() < 1e-12 * cov.amax());
        let t = Isometry3::new(Vector3::new(3.0e5, 5.8e6, 120.0), Vector3::new(0.2, -0.4, 1.1));
        let ad = crate::se3::adjoint(&t);
        let moved = by_blocks(&(ad * cov * ad.transpose()), &(t * c), fr, ft);
        let expected = ad * scaled * ad.transpose();
        assert!((moved - expected).amax() < 1e-9 * expected.amax(), "{moved} against {expected}");
    }

    /// Enough halvings for the calibration's degrees of freedom, within
    /// their bounds: up to five scans four each, six and seven three,
    /// eight and more two.
    #[test]
    fn a_set_is_halved_enough_times_for_the_calibrations_degrees_of_freedom() {
        let counts: Vec<u64> = [1, 2, 3, 4, 5, 6, 7, 8, 40].iter().map(|&n| halvings(n)).collect();
        assert_eq!(counts, [4, 4, 4, 4, 4, 3, 3, 2, 2]);
        assert!((4..40).all(|n| 6 * n * halvings(n) as usize >= CALIBRATION_DOF));
    }

    /// The shares are dealt as at random along a scan's order: a point's
    /// next neighbour falls in its share as often as chance has it (1/2,
    /// 1/4), where the multiplicative hash interleaved them (0.37 and 0.12
    /// on average over the salts of three scans' four halvings),
    /// and each share holds its part of the points.
    #[test]
    fn consecutive_points_fall_in_the_same_share_as_often_as_at_random() {
        for bits in [1, 2] {
            let k = 1u64 << bits;
            for (i, h) in [(0u64, 0u64), (3, 1), (40, 3)] {
                let salt = i.wrapping_mul(0xD1B5_4A32_D192_ED03) ^ (h + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                let n = 200_000u64;
                let dealt: Vec<u64> = (0..n).map(|j| share(j ^ salt, bits)).collect();
                let same = dealt.windows(2).filter(|w| w[0] == w[1]).count() as f64 / (n - 1) as f64;
                assert!(
                    (same - 1.0 / k as f64).abs() < 0.005,
                    "bits {bits}, salt of ({i}, {h}): next in the same share {same}"
                );
                let mut counts = vec![0u64; k as usize];
                dealt.iter().for_each(|&s| counts[s as usize] += 1);
                assert!(counts.iter().all(|&c| (c as f64 / n as f64 - 1.0 / k as f64).abs() < 0.005), "{counts:?}");
            }
        }
    }

    /// The step from quarters to halves carries a factor on, bounded.
    #[test]
    fn a_factor_is_carried_to_full_density_by_its_step_from_the_quarters() {
        assert!((at_full_density(1.5, 1.2) - 1.875).abs() < 1e-12);
        assert_eq!(at_full_density(1.5, 2.0), 1.5);
        assert_eq!(at_full_density(3.0, 1.0), 3.0 * DENSITY_STEP_MAX);
        assert_eq!(at_full_density(1.0, 1.0), 1.0);
    }
}
