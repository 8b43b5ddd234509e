//! The simulated total station: the CPS noise model (distance, Hz, V and
//! centring) on the true sight line, the instrument's range limits, line of
//! sight through the scene, and the prism constant.

use cps::{Instrument, observe};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::{SimWorld, rng, stream};
use crate::devices::{Prism, Target, TotalStation, TsMeasurement};
use crate::error::{Result, ScannerError};

/// A simulated total station on the parent.
#[derive(Debug, Clone)]
pub struct SimTotalStation {
    world: SimWorld,
    instrument: Instrument,
    pub(super) rng: ChaCha8Rng,
}

impl SimTotalStation {
    /// A total station with the given noise model and limits.
    pub fn new(world: SimWorld, instrument: Instrument, seed: u64) -> Self {
        Self { world, instrument, rng: rng(seed, stream::TOTAL_STATION) }
    }
}

impl TotalStation for SimTotalStation {
    fn name(&self) -> &str {
        "simulated total station"
    }

    fn measure(&mut self, target: &Target) -> Result<TsMeasurement> {
        let truth = self.world.truth();
        let (prism, sighting) = match target.prism {
            Prism::Child(j) => (truth.children.get(j), self.instrument.clone()),
            // A control prism's centring is in its true position.
            Prism::Control(k) => (truth.control.get(k), self.instrument.without_target_centring()),
        };
        let Some(&child) = prism else {
            let message = format!("no {} in this world", target.prism);
            return Err(ScannerError::Device { device: self.name().into(), message });
        };
        let from = truth.parent.position;
        if let Some(hit) = self.world.scene().obstruction(&from, &child) {
            return Err(ScannerError::NoLineOfSight {
                device: self.name().into(),
                target: target.prism.to_string(),
                blocked_by: self.world.scene().object_name(hit.object).into(),
                at_m: hit.distance_m,
            });
        }
        let exact = observe(&truth.parent, &child)?;
        let inst = &sighting;
        if exact.slope_m < inst.min_range_m || exact.slope_m > inst.max_range_m {
            return Err(ScannerError::OutOfRange {
                device: self.name().into(),
                what: format!("slope distance to {} (m)", target.prism),
                value: exact.slope_m,
                expected: format!("{} m … {} m", inst.min_range_m, inst.max_range_m),
            });
        }
        let z = [(); 3].map(|()| self.rng.sample(StandardNormal));
        Ok(TsMeasurement::from_reading(&inst.perturbed(&exact, z), inst))
    }
}

#[cfg(test)]
mod tests {
    use cps::ParentPose;
    use cps::geom::builtin;
    use nalgebra::Point3;

    use super::*;

    fn world() -> SimWorld {
        let parent = ParentPose::new(15.0, 6.0, 1.5, 0.3);
        let children = vec![Point3::new(25.0, 6.0, 1.0), Point3::new(25.0, 3.0, 1.0), Point3::new(15.5, 6.0, 1.0)];
        SimWorld::new(builtin("hall").expect("hall"), parent, children)
    }

    fn target(child: usize) -> Target {
        Target {
            prism: Prism::Child(child),
            predicted: cps::Reading { slope_m: 10.0, azimuth_rad: 0.0, elevation_rad: 0.0 },
        }
    }

    #[test]
    fn errors_name_the_obstruction_and_the_range() {
        let inst = Instrument { prism_constant_m: 0.0175, ..Instrument::default() };
        let mut ts = SimTotalStation::new(world(), inst.clone(), 1);
        let e = ts.measure(&target(0)).expect_err("pillar 2 is in the way");
        assert!(e.to_string().contains("blocked by 'pillar 2'"), "{e}");
        let e = ts.measure(&target(2)).expect_err("0.5 m is below the 4 m minimum");
        assert!(e.to_string().contains("slope distance to child 2"), "{e}");
        let e = ts.measure(&target(5)).expect_err("no such child");
        assert!(e.to_string().contains("no child 5"), "{e}");
    }

    /// Mean and spread of many measurements match the truth and the model,
    /// with the prism constant applied by `to_reading`.
    #[test]
    fn noise_matches_the_instrument_model() {
        let inst = Instrument { prism_constant_m: 0.0175, ..Instrument::default() };
        let w = world();
        let mut ts = SimTotalStation::new(w.clone(), inst.clone(), 7);
        let truth = w.truth();
        let exact = observe(&truth.parent, &truth.children[1]).expect("observe");
        let n = 4000;
        let mut sum = nalgebra::Vector3::zeros();
        let mut sq = nalgebra::Vector3::zeros();
        for _ in 0..n {
            let m = ts.measure(&target(1)).expect("clear sight");
            let e = m.to_reading(&inst).to_vector() - exact.to_vector();
            sum += e;
            sq += e.component_mul(&e);
        }
        let sigma = inst.reading_variances(&exact).map(f64::sqrt);
        for k in 0..3 {
            let mean = sum[k] / n as f64;
            let sd = (sq[k] / n as f64).sqrt();
            assert!(mean.abs() < 4.0 * sigma[k] / (n as f64).sqrt(), "component {k}: mean {mean}");
            assert!((sd / sigma[k] - 1.0).abs() < 0.05, "component {k}: sd {sd} vs {}", sigma[k]);
        }
        // Same seed, same bytes.
        let a = SimTotalStation::new(w.clone(), inst.clone(), 3).measure(&target(1)).expect("m");
        let b = SimTotalStation::new(w, inst, 3).measure(&target(1)).expect("m");
        assert_eq!(a, b);
    }
}
