//! What a plan's final error is made of, what would change it, and which
//! observations nothing checks.

use nalgebra::{Matrix4, Vector3};

use cps::Instrument;

use crate::dance::{Dance, run_dance, schedule};
use crate::error::PlanError;
use crate::predict::predict;

/// The final σx² + σy² with one group of error sources at a time (the others
/// switched off): the parts add up to the total to first order, since the
/// propagated covariance is linear in the observations' variances for fixed
/// weights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensitivity {
    /// With every error source, m².
    pub total_m2: f64,
    /// Distance errors only (constant and ppm part), m².
    pub range_m2: f64,
    /// Angle errors only (Hz and V), m².
    pub angle_m2: f64,
    /// Centring errors only (instrument and prism), m².
    pub centring_m2: f64,
    /// The datum's uncertainty only — the start pose's and the control
    /// points' given coordinates' — m².
    pub start_m2: f64,
}

impl Sensitivity {
    /// The name of the largest part.
    pub fn dominant(&self) -> &'static str {
        let parts = [
            (self.range_m2, "range"),
            (self.angle_m2, "angle"),
            (self.centring_m2, "centring"),
            (self.start_m2, "start pose"),
        ];
        parts.iter().max_by(|a, b| a.0.total_cmp(&b.0)).map_or("range", |p| p.1)
    }
}

/// A source switched off keeps a negligible variance (1e-6 of its σ) so
/// that every weight matrix stays regular.
const OFF: f64 = 1e-6;

/// Splits the predicted final σx² + σy² of `dance` into its sources.
pub fn sensitivity(
    dance: &Dance,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
) -> Result<Sensitivity, PlanError> {
    // The control points' given coordinates are part of the datum, with
    // the start pose: the other parts run with them exact.
    let exact_control = {
        let mut d = dance.clone();
        d.control.iter_mut().for_each(|c| c.covariance = nalgebra::Matrix3::zeros());
        d
    };
    let run_on = |d: &Dance, inst: &Instrument, start: &Matrix4<f64>| -> Result<f64, PlanError> {
        Ok(predict(d, inst, start)?.last().map_or(0.0, |l| l.sigma_xy2_m2()))
    };
    let run = |inst: &Instrument, start: &Matrix4<f64>| run_on(&exact_control, inst, start);
    let quiet = Instrument {
        sigma_distance_m: instrument.sigma_distance_m * OFF,
        sigma_distance_ppm: instrument.sigma_distance_ppm * OFF,
        sigma_hz_rad: instrument.sigma_hz_rad * OFF,
        sigma_v_rad: instrument.sigma_v_rad * OFF,
        centring_instrument_m: 0.0,
        centring_target_m: 0.0,
        ..instrument.clone()
    };
    let zero = Matrix4::zeros();
    Ok(Sensitivity {
        total_m2: run_on(dance, instrument, start_covariance)?,
        range_m2: run(
            &Instrument {
                sigma_distance_m: instrument.sigma_distance_m,
                sigma_distance_ppm: instrument.sigma_distance_ppm,
                ..quiet.clone()
            },
            &zero,
        )?,
        angle_m2: run(
            &Instrument { sigma_hz_rad: instrument.sigma_hz_rad, sigma_v_rad: instrument.sigma_v_rad, ..quiet.clone() },
            &zero,
        )?,
        centring_m2: if instrument.centring_instrument_m > 0.0 || instrument.centring_target_m > 0.0 {
            run(
                &Instrument {
                    centring_instrument_m: instrument.centring_instrument_m,
                    centring_target_m: instrument.centring_target_m,
                    ..quiet.clone()
                },
                &zero,
            )?
        } else {
            0.0
        },
        start_m2: if start_covariance.iter().any(|v| *v != 0.0)
            || dance.control.iter().any(|c| c.covariance != nalgebra::Matrix3::zeros())
        {
            run_on(dance, &quiet, start_covariance)?
        } else {
            0.0
        },
    })
}

/// What one more child would change: the final σx² + σy² with the
/// formation plus one child straight ahead at the children's mean forward
/// offset and height (`None` when that point coincides with a child).
pub fn with_one_more_child(
    dance: &Dance,
    formation_m: &[Vector3<f64>],
    strategy: crate::Strategy,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
) -> Option<f64> {
    let n = formation_m.len() as f64;
    let mean = formation_m.iter().sum::<Vector3<f64>>() / n;
    let extra = Vector3::new(mean.x, 0.0, mean.z);
    if formation_m.iter().any(|o| (o - extra).norm() < 1e-6) || extra.xy().norm() < 1e-6 {
        return None;
    }
    let mut more = formation_m.to_vec();
    more.push(extra);
    let d = schedule(dance.stations.clone(), &more, strategy)
        .ok()?
        .with_control(dance.control.clone(), dance.sightings.clone());
    if !d.range_violations(instrument).is_empty() {
        return None;
    }
    Some(predict(&d, instrument, start_covariance).ok()?.last()?.sigma_xy2_m2())
}

/// The redundancy numbers of one parent fix's observations.
#[derive(Debug, Clone, PartialEq)]
pub struct FixReliability {
    /// Dance cycle (1-based; 0 for the start's resection).
    pub cycle: usize,
    /// Per sighting — the children in team order, then the control points
    /// sighted at the fix's station in [`Dance::sighted_at`] order:
    /// redundancy numbers of (r, φ, ψ).
    pub redundancy_numbers: Vec<[f64; 3]>,
}

/// Redundancy numbers at or below this are "checked by nothing": a blunder
/// in such an observation leaves no trace in the residuals.
pub const UNCHECKED_REDUNDANCY: f64 = cps::batch::statistics::WEAKLY_CHECKED;

/// The redundancy numbers of every parent fix of `dance`. (Each child's
/// placement is a single pointing — redundancy 0: it is checked only
/// through the following fixes.)
pub fn reliability(
    dance: &Dance,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
) -> Result<Vec<FixReliability>, PlanError> {
    let mut team = cps::TeamState::new(dance.station_pose(0), *start_covariance, dance.n_children())
        .map_err(|source| PlanError::Model { cycle: 0, source })?;
    let mut out = Vec::with_capacity(dance.cycles.len());
    run_dance(dance, &mut team, instrument, true, crate::dance::nominal_reading(dance), |c, _, fix| {
        let r = fix.reliability().redundancy_numbers;
        out.push(FixReliability {
            cycle: c.map_or(0, |c| c.cycle),
            redundancy_numbers: r.chunks(3).map(|c| [c[0], c[1], c[2]]).collect(),
        });
    })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use nalgebra::Point3;

    use super::*;
    use crate::{Strategy, stations};

    fn dance() -> (Dance, Vec<Vector3<f64>>) {
        let route = [Point3::origin(), Point3::new(100.0, 0.0, 0.0)];
        let formation = vec![Vector3::new(5.0, 4.0, 0.0), Vector3::new(5.0, -4.0, 0.0)];
        (schedule(stations(&route, 10.0).expect("route"), &formation, Strategy::Leapfrog).expect("dance"), formation)
    }

    fn instrument() -> Instrument {
        Instrument {
            sigma_distance_m: 0.003,
            sigma_hz_rad: 5.0 * cps::RAD_PER_ARCSEC,
            sigma_v_rad: 5.0 * cps::RAD_PER_ARCSEC,
            centring_instrument_m: 0.001,
            centring_target_m: 0.001,
            ..Instrument::default()
        }
    }

    #[test]
    fn the_parts_add_up_and_short_sight_lines_are_range_dominated() {
        let (d, _) = dance();
        let s = sensitivity(&d, &instrument(), &Matrix4::zeros()).expect("predict");
        let sum = s.range_m2 + s.angle_m2 + s.centring_m2 + s.start_m2;
        // Weights change with the sources switched off, so the split is
        // first order only: within 25 %.
        assert!((sum / s.total_m2 - 1.0).abs() < 0.25, "{s:?}");
        // 3 mm over 6.4 m sight lines is ~97″ of heading: range dominates.
        assert_eq!(s.dominant(), "range", "{s:?}");
        let long =
            Instrument { sigma_distance_m: 1e-5, centring_instrument_m: 0.0, centring_target_m: 0.0, ..instrument() };
        assert_eq!(sensitivity(&d, &long, &Matrix4::zeros()).expect("predict").dominant(), "angle");
    }

    #[test]
    fn one_more_child_helps_and_fixes_have_redundancy() {
        let (d, f) = dance();
        let inst = instrument();
        let base = predict(&d, &inst, &Matrix4::zeros()).expect("predict").last().expect("cycles").sigma_xy2_m2();
        let more = with_one_more_child(&d, &f, Strategy::Leapfrog, &inst, &Matrix4::zeros()).expect("three children");
        assert!(more < base, "{more} vs {base}");
        let r = reliability(&d, &inst, &Matrix4::zeros()).expect("predict");
        assert_eq!(r.len(), 10);
        for fix in &r {
            // 6 observations, 4 unknowns: the numbers sum to 2.
            let sum: f64 = fix.redundancy_numbers.iter().flatten().sum();
            assert!((sum - 2.0).abs() < 1e-9, "{sum}");
            assert!(fix.redundancy_numbers.iter().flatten().all(|r| (-1e-12..=1.0 + 1e-12).contains(r)));
        }
    }
}
