//! The long network of the batch benchmarks (`benches/batch.rs`,
//! `examples/batch_memory.rs`): a leapfrog chain of N stations (two
//! children placed per cycle, each sighted from two stations), a control
//! point beside every 100th station, noisy readings.

use cps::batch::{Network, NetworkReading, Point, Station};
use cps::{Instrument, ParentPose, observe};
use nalgebra::{Matrix3, Matrix4, Point3, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// The network of `n` stations 10 m apart.
pub fn chain(n: usize, seed: u64) -> Network {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut z = move || -> f64 { StandardNormal.sample(&mut rng) };
    let inst = Instrument::default();
    let truth: Vec<ParentPose> = (0..n).map(|k| ParentPose::new(10.0 * k as f64, 0.0, 0.0, 0.0)).collect();
    let mut points = Vec::new();
    let mut readings = Vec::new();
    let mut read = |station: usize, point: usize, at: &Point3<f64>, z: &mut dyn FnMut() -> f64| {
        let r = inst.perturbed(&observe(&truth[station], at).expect("regular"), [z(), z(), z()]);
        readings.push(NetworkReading { station, point, reading: r, covariance: inst.reading_covariance(&r) });
    };
    for k in 0..n - 1 {
        for side in [12.0, -12.0] {
            let at = Point3::new(10.0 * k as f64 + 10.0, side, 0.0);
            points.push(Point { position: at, prior: None });
            let p = points.len() - 1;
            read(k, p, &at, &mut z);
            read(k + 1, p, &at, &mut z);
        }
        if k % 100 == 99 {
            let at = Point3::new(10.0 * k as f64, 20.0, 1.0);
            points.push(Point { position: at, prior: Some(Matrix3::from_diagonal(&Vector3::new(1e-6, 1e-6, 1e-6))) });
            let p = points.len() - 1;
            read(k, p, &at, &mut z);
        }
    }
    let mut stations: Vec<Station> = truth.iter().map(|t| Station { pose: *t, prior: None }).collect();
    stations[0].prior = Some(Matrix4::zeros());
    Network { stations, points, readings }
}
