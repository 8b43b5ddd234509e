//! Canonical example problems shared by the planner's tests and benches.
#![allow(dead_code)]

use cps::{Instrument, RAD_PER_ARCSEC};
use nalgebra::{Point3, Vector3};
use planner::{Dance, Strategy, leapfrog, schedule, stations};

/// A straight route of `cycles` strides of `stride_m` along +x.
pub fn straight_dance(cycles: usize, stride_m: f64, formation: &[Vector3<f64>]) -> Dance {
    let route = [Point3::origin(), Point3::new(cycles as f64 * stride_m, 0.0, 0.0)];
    leapfrog(stations(&route, stride_m).expect("valid route"), formation).expect("valid formation")
}

/// A straight route of `cycles` strides along +x, danced with `strategy`.
pub fn straight_schedule(cycles: usize, stride_m: f64, formation: &[Vector3<f64>], strategy: Strategy) -> Dance {
    let route = [Point3::origin(), Point3::new(cycles as f64 * stride_m, 0.0, 0.0)];
    schedule(stations(&route, stride_m).expect("valid route"), formation, strategy).expect("valid formation")
}

/// An L-shaped route with a climb: 30 m along x, then 12 m along y up 1 m.
pub fn l_shaped_dance(stride_m: f64, formation: &[Vector3<f64>]) -> Dance {
    let route = [Point3::origin(), Point3::new(30.0, 0.0, 0.0), Point3::new(30.0, 12.0, 1.0)];
    leapfrog(stations(&route, stride_m).expect("valid route"), formation).expect("valid formation")
}

/// Symmetric formation (a, ±b) at height 0.
pub fn symmetric(a: f64, b: f64) -> Vec<Vector3<f64>> {
    vec![Vector3::new(a, b, 0.0), Vector3::new(a, -b, 0.0)]
}

/// The seed's numeric example's total station: 3 mm, 5″, 4–400 m.
pub fn paper_instrument() -> Instrument {
    Instrument {
        sigma_distance_m: 0.003,
        sigma_hz_rad: 5.0 * RAD_PER_ARCSEC,
        sigma_v_rad: 5.0 * RAD_PER_ARCSEC,
        min_range_m: 4.0,
        max_range_m: 400.0,
        ..Instrument::default()
    }
}
