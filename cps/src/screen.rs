//! Gross errors: a reading off by more than noise, centring and a drive can
//! explain, and the field test a fix passes before the team takes it.
//!
//! Data snooping ([`crate::batch`]) finds blunders of centimetres in the
//! adjustment; a blunder of metres or degrees (a prism swapped, a distance
//! mistyped, an angle read on the wrong face) breaks the fix itself — its
//! Gauss–Newton start, its linearisation — before any statistic can speak
//! (issue 34, S7: one 10 m distance put a fix 1.8·10⁹ m away). A surveyor's
//! instrument re-measures then; [`field_test`] says which reading to.

use crate::fix::FixOptions;
use crate::instrument::Instrument;
use crate::observation::{Reading, observe};
use crate::state::TeamState;
use crate::{CpsError, ParentFix};

/// A fix whose a-posteriori variance factor σ0² exceeds this fails its
/// test whatever its residuals: its readings disagree some 30 times more
/// than the noise model allows (by chance with probability below e⁻⁵⁰⁰).
/// With two points sighted a least-squares fix spreads one 10° azimuth
/// blunder into residuals below [`GROSS_ANGLE_RAD`] (σ0² ≈ 9·10³), while
/// fixes of the example missions stay below 7 and a 2 cm blunder on a
/// 3 mm distance gives some 30 — left to data snooping.
pub const GROSS_SIGMA0_SQUARED: f64 = 1e3;

/// A slope distance off by more than this is a gross error, metres.
pub const GROSS_DISTANCE_M: f64 = 1.0;
/// An azimuth or elevation off by more than this is a gross error, radians
/// (5.7°).
pub const GROSS_ANGLE_RAD: f64 = 0.1;

/// How far a reading is from what a pose gives: measured − expected
/// (azimuth wrapped).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Misclosure {
    /// Slope distance, metres.
    pub slope_m: f64,
    /// Azimuth, radians in (−π, π].
    pub azimuth_rad: f64,
    /// Elevation, radians.
    pub elevation_rad: f64,
}

impl Misclosure {
    /// `got` − `expected`.
    pub fn between(got: &Reading, expected: &Reading) -> Self {
        let [slope_m, azimuth_rad, elevation_rad] = got.minus(expected);
        Self { slope_m, azimuth_rad, elevation_rad }
    }

    /// The largest part in units of its gross bound: above 1 is gross
    /// (infinite when a part is NaN).
    pub fn excess(&self) -> f64 {
        let parts = [
            self.slope_m.abs() / GROSS_DISTANCE_M,
            self.azimuth_rad.abs() / GROSS_ANGLE_RAD,
            self.elevation_rad.abs() / GROSS_ANGLE_RAD,
        ];
        parts.into_iter().fold(0.0, |a, p| if p.is_nan() { f64::INFINITY } else { a.max(p) })
    }

    /// Off by more than [`GROSS_DISTANCE_M`] or [`GROSS_ANGLE_RAD`] (a NaN
    /// part counts as gross).
    pub fn is_gross(&self) -> bool {
        self.excess() > 1.0
    }
}

/// The verdict of [`field_test`] on a fix's readings.
#[derive(Debug, Clone, PartialEq)]
pub enum FieldTest {
    /// The fix converges and every reading agrees with it within the gross
    /// bounds: the team may take it.
    Passed,
    /// Without reading `index` the fix passes, and that reading disagrees
    /// with it by `misclosure`: measure it again.
    Culprit {
        /// Position in the readings given.
        index: usize,
        /// The reading against the fix from the others.
        misclosure: Misclosure,
    },
    /// No single reading explains the failure.
    Failed {
        /// The fix from every reading failed with this error.
        error: Option<CpsError>,
        /// Else the reading the fix from every reading disagrees with most,
        /// and by how much.
        worst: Option<(usize, Misclosure)>,
        /// The fix from every reading, when there is one: whether it
        /// converged, in how many iterations, and its σ0².
        fix: Option<(bool, usize, f64)>,
    },
}

/// The field test of a parent fix from `readings` (team-state point,
/// reading, noise model), the state unchanged: the fix must converge, have
/// σ0² within [`GROSS_SIGMA0_SQUARED`] and agree with every reading within
/// [`GROSS_DISTANCE_M`] and [`GROSS_ANGLE_RAD`], and with three or more points sighted, no reading
/// may disagree that grossly with the fix from the others (itself
/// passing). Such a reading is the culprit (the one whose absence leaves the
/// smallest σ0² among several).
pub fn field_test(state: &TeamState, readings: &[(usize, Reading, &Instrument)], options: &FixOptions) -> FieldTest {
    let full = state.trial_fix(readings, options);
    let (mut passes, worst) = match &full {
        Ok(fix) => match worst_misclosure(state, readings, fix) {
            Ok(worst) => (agrees(fix, worst), worst),
            Err(_) => (false, None),
        },
        Err(_) => (false, None),
    };
    // Least squares spreads a blunder over every reading (a 10° azimuth on
    // one of four hides below 5.7° on each): each reading is also held
    // against the fix from the others.
    let mut best: Option<(usize, Misclosure, f64)> = None;
    if readings.len() >= 3 {
        for k in 0..readings.len() {
            let others: Vec<(usize, Reading, &Instrument)> =
                readings.iter().enumerate().filter(|(i, _)| *i != k).map(|(_, r)| *r).collect();
            let Ok(fix) = state.trial_fix(&others, options) else { continue };
            let consistent = matches!(worst_misclosure(state, &others, &fix), Ok(w) if agrees(&fix, w));
            let Some(position) = state.child(readings[k].0) else { continue };
            let Ok(expected) = observe(&fix.pose, &position) else { continue };
            let misclosure = Misclosure::between(&readings[k].1, &expected);
            if consistent && misclosure.is_gross() {
                passes = false;
                if best.as_ref().is_none_or(|(_, _, s)| fix.sigma0_squared < *s) {
                    best = Some((k, misclosure, fix.sigma0_squared));
                }
            }
        }
    }
    match best {
        _ if passes => FieldTest::Passed,
        Some((index, misclosure, _)) => FieldTest::Culprit { index, misclosure },
        None => {
            let fix = full.as_ref().ok().map(|f| (f.converged, f.iterations, f.sigma0_squared));
            FieldTest::Failed { error: full.err(), worst, fix }
        }
    }
}

/// Whether `fix` converged, with σ0² within [`GROSS_SIGMA0_SQUARED`], and
/// its `worst` reading within the gross bounds.
fn agrees(fix: &ParentFix, worst: Option<(usize, Misclosure)>) -> bool {
    fix.converged && fix.sigma0_squared <= GROSS_SIGMA0_SQUARED && !worst.is_some_and(|(_, m)| m.is_gross())
}

/// The reading of `readings` that disagrees most with `fix` (in units of
/// the gross bounds), with its misclosure; `None` for no readings.
fn worst_misclosure(
    state: &TeamState,
    readings: &[(usize, Reading, &Instrument)],
    fix: &ParentFix,
) -> crate::Result<Option<(usize, Misclosure)>> {
    let mut worst: Option<(usize, Misclosure)> = None;
    for (k, (j, reading, _)) in readings.iter().enumerate() {
        let position = state.child(*j).ok_or(CpsError::ChildNotPlaced { child: *j })?;
        let m = Misclosure::between(reading, &observe(&fix.pose, &position)?);
        if worst.is_none_or(|(_, w)| m.excess() > w.excess()) {
            worst = Some((k, m));
        }
    }
    Ok(worst)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observation::ParentPose;
    use nalgebra::{Matrix4, Point3};

    fn instrument() -> Instrument {
        Instrument { centring_target_m: 0.001, min_range_m: 0.5, ..Instrument::default() }
    }

    /// A team at the origin with four children placed, the parent moved to
    /// `truth`, and its exact readings of them.
    fn team(truth: &ParentPose) -> (TeamState, Vec<Reading>) {
        let at = [
            Point3::new(8.0, 9.0, 0.3),
            Point3::new(9.0, -7.0, -0.2),
            Point3::new(20.0, 1.0, 0.5),
            Point3::new(-6.0, 5.0, 0.1),
        ];
        let start = ParentPose::new(0.0, 0.0, 0.0, 0.0);
        let mut state =
            TeamState::new(start, Matrix4::from_diagonal(&nalgebra::Vector4::new(1e-6, 1e-6, 1e-6, 1e-8)), at.len())
                .expect("state");
        for (j, p) in at.iter().enumerate() {
            state.place_child(j, &observe(&start, p).expect("observe"), &instrument()).expect("place");
        }
        let readings = at.iter().map(|p| observe(truth, p).expect("observe")).collect();
        (state, readings)
    }

    fn with<'i>(readings: &[Reading], i: &'i Instrument) -> Vec<(usize, Reading, &'i Instrument)> {
        readings.iter().enumerate().map(|(j, r)| (j, *r, i)).collect()
    }

    #[test]
    fn exact_readings_pass() {
        let truth = ParentPose::new(3.0, 1.0, 0.1, 0.4);
        let (state, readings) = team(&truth);
        let i = instrument();
        assert_eq!(field_test(&state, &with(&readings, &i), &FixOptions::default()), FieldTest::Passed);
    }

    #[test]
    fn a_gross_blunder_on_any_reading_names_that_reading_and_its_size() {
        let truth = ParentPose::new(3.0, 1.0, 0.1, 0.4);
        let (state, readings) = team(&truth);
        let i = instrument();
        // 10 m on a distance; 10°, 90° and 180° on an azimuth; 10° on an
        // elevation: each found on each reading, its size measured against
        // the others' fix (exact readings: to 1e-6).
        let blunders: [(usize, f64); 5] =
            [(0, 10.0), (1, 10f64.to_radians()), (1, 90f64.to_radians()), (1, 179.9f64.to_radians()), (2, 0.2)];
        for (k, _) in readings.iter().enumerate() {
            for &(part, size) in &blunders {
                let mut bad = readings.clone();
                match part {
                    0 => bad[k].slope_m += size,
                    1 => bad[k].azimuth_rad += size,
                    _ => bad[k].elevation_rad += size,
                }
                let verdict = field_test(&state, &with(&bad, &i), &FixOptions::default());
                let FieldTest::Culprit { index, misclosure } = verdict else {
                    panic!("reading {k}, part {part} off by {size}: {verdict:?}")
                };
                assert_eq!(index, k);
                let got = [misclosure.slope_m, misclosure.azimuth_rad, misclosure.elevation_rad];
                for (p, g) in got.iter().enumerate() {
                    let want = if p == part { size } else { 0.0 };
                    assert!((g - want).abs() < 1e-6, "reading {k}, part {p}: {g} against {want}");
                }
            }
        }
    }

    #[test]
    fn a_blunder_below_the_gross_bounds_is_left_to_the_statistics() {
        let truth = ParentPose::new(3.0, 1.0, 0.1, 0.4);
        let (state, mut readings) = team(&truth);
        readings[2].slope_m += 0.02;
        let i = instrument();
        assert_eq!(field_test(&state, &with(&readings, &i), &FixOptions::default()), FieldTest::Passed);
    }

    #[test]
    fn a_10_degree_azimuth_blunder_between_two_points_fails_by_its_variance_factor() {
        let truth = ParentPose::new(3.0, 1.0, 0.1, 0.4);
        let (state, mut readings) = team(&truth);
        readings.truncate(2);
        let i = instrument();
        let options = FixOptions::default();
        assert_eq!(field_test(&state, &with(&readings, &i), &options), FieldTest::Passed);
        readings[1].azimuth_rad += 10f64.to_radians();
        let fix = state.trial_fix(&with(&readings, &i), &options).expect("the fix itself succeeds");
        let worst = worst_misclosure(&state, &with(&readings, &i), &fix).expect("misclosures").expect("two");
        assert!(!worst.1.is_gross(), "spread below the bounds: {worst:?}");
        assert!(fix.sigma0_squared > GROSS_SIGMA0_SQUARED, "σ0² = {}", fix.sigma0_squared);
        let verdict = field_test(&state, &with(&readings, &i), &options);
        assert!(matches!(verdict, FieldTest::Failed { error: None, worst: Some(_), .. }), "{verdict:?}");
    }

    #[test]
    fn two_points_cannot_name_a_culprit() {
        let truth = ParentPose::new(3.0, 1.0, 0.1, 0.4);
        let (state, mut readings) = team(&truth);
        readings.truncate(2);
        readings[0].slope_m += 10.0;
        let i = instrument();
        let verdict = field_test(&state, &with(&readings, &i), &FixOptions::default());
        assert!(matches!(verdict, FieldTest::Failed { .. }), "{verdict:?}");
    }

    #[test]
    fn misclosures_wrap_the_azimuth_and_count_nan_as_gross() {
        let a = Reading { slope_m: 10.0, azimuth_rad: 3.1, elevation_rad: 0.0 };
        let b = Reading { slope_m: 10.0, azimuth_rad: -3.1, elevation_rad: 0.0 };
        let m = Misclosure::between(&a, &b);
        assert!((m.azimuth_rad - (6.2 - std::f64::consts::TAU)).abs() < 1e-12);
        assert!(!m.is_gross());
        assert!(Misclosure { slope_m: f64::NAN, ..m }.is_gross());
        assert!(Misclosure { slope_m: 1.01, ..m }.is_gross());
        assert!(!Misclosure { slope_m: -0.99, elevation_rad: 0.099, ..m }.is_gross());
    }
}
