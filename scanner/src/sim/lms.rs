//! The simulated SICK LMS-2xx: 180° field of view at 1°, 0.5° or 0.25°, the
//! protocol's measuring modes (mm with 8/16/32 m, cm with 80 m), Gaussian
//! range noise, quantisation to the mode's unit and the protocol's
//! "value greater than maximum" code (…F7h) for no return.

use cps::geom::Ray;
use nalgebra::{Isometry3, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::{SimWorld, rng, stream};
use crate::devices::{HeadKind, RangeFinder2D, Slice};
use crate::error::Result;

/// Angular resolution of a 180° scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LmsResolution {
    /// 1° (181 values).
    One,
    /// 0.5° (361 values).
    Half,
    /// 0.25° (721 values; interlaced on the real device).
    Quarter,
}

impl LmsResolution {
    /// Step in degrees.
    pub fn degrees(&self) -> f64 {
        match self {
            LmsResolution::One => 1.0,
            LmsResolution::Half => 0.5,
            LmsResolution::Quarter => 0.25,
        }
    }

    /// Number of values in a 180° scan.
    pub fn values(&self) -> usize {
        (180.0 / self.degrees()).round() as usize + 1
    }
}

/// Measuring mode: unit and range (configuration bytes 5 and 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LmsRangeMode {
    /// mm, 13 distance bits, 8.183 m.
    Mm8,
    /// mm, 14 distance bits, 16.375 m.
    Mm16,
    /// mm, 15 distance bits, 32.759 m.
    Mm32,
    /// cm, 13 distance bits, 81.83 m.
    Cm80,
}

impl LmsRangeMode {
    /// Metres per count.
    pub fn metres_per_count(&self) -> f64 {
        if *self == LmsRangeMode::Cm80 { 0.01 } else { 0.001 }
    }

    /// The first non-distance code (…F7h, "value greater than maximum").
    pub fn max_valid(&self) -> u16 {
        let bits = match self {
            LmsRangeMode::Mm8 | LmsRangeMode::Cm80 => 13,
            LmsRangeMode::Mm16 => 14,
            LmsRangeMode::Mm32 => 15,
        };
        (1u16 << bits) - 9
    }

    /// Largest measurable range, metres.
    pub fn max_range_m(&self) -> f64 {
        f64::from(self.max_valid() - 1) * self.metres_per_count()
    }
}

/// Configuration of a simulated LMS.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmsConfig {
    /// Angular resolution.
    pub resolution: LmsResolution,
    /// Measuring mode.
    pub mode: LmsRangeMode,
    /// 1σ range noise, metres (LMS200 datasheet: 5 mm statistical in mm mode).
    pub sigma_range_m: f64,
}

impl Default for LmsConfig {
    /// 0.5°, mm mode up to 32 m, 5 mm noise.
    fn default() -> Self {
        Self { resolution: LmsResolution::Half, mode: LmsRangeMode::Mm32, sigma_range_m: 0.005 }
    }
}

/// A simulated LMS-2xx mounted on the parent's scan head.
#[derive(Debug, Clone)]
pub struct SimLms {
    world: SimWorld,
    config: LmsConfig,
    head: HeadKind,
    body_from_head: Isometry3<f64>,
    pub(super) rng: ChaCha8Rng,
}

impl SimLms {
    /// A scanner on a head of kind `head`, mounted at `body_from_head`.
    pub fn new(world: SimWorld, config: LmsConfig, head: HeadKind, body_from_head: Isometry3<f64>, seed: u64) -> Self {
        Self { world, config, head, body_from_head, rng: rng(seed, stream::LMS) }
    }

    /// The configuration.
    pub fn config(&self) -> &LmsConfig {
        &self.config
    }

    /// Changes resolution, mode or noise (the noise stream goes on).
    pub fn set_config(&mut self, config: LmsConfig) {
        self.config = config;
    }
}

impl RangeFinder2D for SimLms {
    fn name(&self) -> &str {
        "simulated LMS-2xx"
    }

    fn scan(&mut self) -> Result<Slice> {
        let truth = self.world.truth();
        let world_from_scanner = truth.tilt.world_from_body(&truth.parent)
            * self.body_from_head
            * self.head.head_from_scanner(truth.head_angle_rad);
        let origin = world_from_scanner.translation.vector.into();
        let step = self.config.resolution.degrees().to_radians();
        let mode = self.config.mode;
        let (mpc, max_valid) = (mode.metres_per_count(), mode.max_valid());
        let reach = mode.max_range_m() + 1.0;
        let scene = self.world.scene();
        let values = (0..self.config.resolution.values())
            .map(|i| {
                let a = i as f64 * step;
                let noise: f64 = self.config.sigma_range_m * self.rng.sample::<f64, _>(StandardNormal);
                let direction = world_from_scanner.rotation * Vector3::new(a.cos(), a.sin(), 0.0);
                let hit = Ray::new(origin, direction).ok().and_then(|ray| scene.cast(&ray, reach));
                match hit {
                    Some(h) => {
                        let counts = ((h.distance_m + noise) / mpc).round().max(0.0);
                        if counts >= f64::from(max_valid) { max_valid } else { counts as u16 }
                    }
                    None => max_valid,
                }
            })
            .collect();
        Ok(Slice { start_rad: 0.0, step_rad: step, values, metres_per_count: mpc, max_valid })
    }
}

#[cfg(test)]
mod tests {
    use cps::ParentPose;
    use cps::geom::builtin;

    use super::*;

    fn lms(mode: LmsRangeMode, resolution: LmsResolution, sigma: f64, x: f64) -> SimLms {
        let world = SimWorld::new(builtin("hall").expect("hall"), ParentPose::new(x, 6.0 - 2.0, 1.0, 0.0), vec![]);
        let config = LmsConfig { resolution, mode, sigma_range_m: sigma };
        SimLms::new(world, config, HeadKind::PitchingMount, Isometry3::identity(), 11)
    }

    /// A noiseless horizontal slice (pitch 0) in the hall from (12, 4): beam 0 looks
    /// right (−y) to the wall at y = 0, beam 90° forward to x = 40.
    #[test]
    fn slice_geometry_and_codes() {
        let mut s = lms(LmsRangeMode::Mm32, LmsResolution::Half, 0.0, 12.0);
        let slice = s.scan().expect("scan");
        assert_eq!(slice.values.len(), 361);
        assert_eq!(slice.range_m(0), Some(4.0), "wall at y = 0");
        assert_eq!(slice.range_m(180), Some(28.0), "end wall at x = 40");
        assert_eq!(slice.range_m(360), Some(8.0), "wall at y = 12");
        // In the 8 m mode, the 20 m end wall is beyond the maximum.
        let mut short = lms(LmsRangeMode::Mm8, LmsResolution::One, 0.0, 20.0);
        let slice = short.scan().expect("scan");
        assert_eq!(slice.values.len(), 181);
        assert_eq!(slice.values[90], 0x1FF7);
        assert_eq!(slice.range_m(90), None);
        assert_eq!(slice.range_m(0), Some(4.0));
        // cm mode quantises to centimetres.
        let mut cm = lms(LmsRangeMode::Cm80, LmsResolution::Quarter, 0.0, 20.123);
        let slice = cm.scan().expect("scan");
        assert_eq!(slice.values.len(), 721);
        assert_eq!(slice.values[360], 1988, "19.877 m → 1988 cm");
    }

    #[test]
    fn range_modes_follow_the_protocol() {
        assert_eq!(LmsRangeMode::Mm8.max_valid(), 0x1FF7);
        assert_eq!(LmsRangeMode::Mm16.max_valid(), 0x3FF7);
        assert_eq!(LmsRangeMode::Mm32.max_valid(), 0x7FF7);
        assert!((LmsRangeMode::Cm80.max_range_m() - 81.82).abs() < 1e-9);
        assert!((LmsRangeMode::Mm32.max_range_m() - 32.758).abs() < 1e-9);
    }

    /// Noise: the spread of one beam over many slices is σ (quantisation of
    /// 1 mm adds 1/12 mm²), and the same seed repeats the same bytes.
    #[test]
    fn noise_and_determinism() {
        let mut s = lms(LmsRangeMode::Mm32, LmsResolution::One, 0.01, 20.0);
        let n = 3000;
        let r: Vec<f64> = (0..n).map(|_| s.scan().expect("scan").range_m(0).expect("wall")).collect();
        let mean = r.iter().sum::<f64>() / n as f64;
        let sd = (r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
        let expected = (0.01f64.powi(2) + 1e-6 / 12.0).sqrt();
        assert!((mean - 4.0).abs() < 4.0 * expected / (n as f64).sqrt(), "mean {mean}");
        assert!((sd / expected - 1.0).abs() < 0.06, "sd {sd}");
        let a = lms(LmsRangeMode::Mm32, LmsResolution::Half, 0.01, 20.0).scan().expect("scan");
        let b = lms(LmsRangeMode::Mm32, LmsResolution::Half, 0.01, 20.0).scan().expect("scan");
        assert_eq!(a, b);
    }
}
