//! Canonical example problems shared by the planner's tests and benches.
#![allow(dead_code)]

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
