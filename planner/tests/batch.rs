//! The sequential filter's last-station covariance equals the dense batch
//! least-squares adjustment of the same dance.

mod common;

use cps::batch::{Network, NetworkReading, adjust};
use cps::{Instrument, RAD_PER_ARCSEC, observe};
use nalgebra::{Matrix4, Vector3, Vector4};
use planner::{Dance, predict};

fn network(dance: &Dance, start_covariance: Matrix4<f64>) -> Network {
    let n = dance.n_children();
    let mut points = Vec::new();
    let mut readings = Vec::new();
    for (k, c) in dance.cycles.iter().enumerate() {
        for (j, p) in c.children.iter().enumerate() {
            let point = k * n + j;
            points.push(*p);
            for station in [c.from, c.to] {
                let reading = observe(&dance.station_pose(station), p).expect("regular");
                readings.push(NetworkReading { station, point, reading });
            }
        }
    }
    Network {
        stations: (0..dance.stations.len()).map(|k| dance.station_pose(k)).collect(),
        start_covariance,
        points,
        readings,
    }
}

fn compare(dance: &Dance, instrument: &Instrument, start: Matrix4<f64>) {
    let filter = predict(dance, instrument, &start).expect("predict");
    let batch = adjust(&network(dance, start), instrument, 5).expect("adjust");
    assert!(batch.converged);
    let last = dance.stations.len() - 1;
    let f = filter.last().expect("cycles").covariance;
    let b = batch.station_covariance(last);
    let rel = (f - b).norm() / b.norm();
    assert!(rel < 1e-6, "relative difference {rel:e}\nfilter {f}\nbatch {b}");
    // The leapfrog chain is an open traverse: later readings only determine
    // the newly placed children and carry no information about earlier
    // stations, so the batch equals the filter at *every* station.
    for c in &filter.cycles {
        let b = batch.station_covariance(c.cycle);
        let rel = (c.covariance - b).norm() / b.norm();
        assert!(rel < 1e-6, "cycle {}: relative difference {rel:e}", c.cycle);
    }
    assert!(batch.redundancy > 0 && batch.sigma0_squared < 1e-12, "exact readings fit exactly");
}

#[test]
fn filter_equals_batch_on_a_straight_route() {
    let inst = Instrument { min_range_m: 1.0, ..Instrument::default() };
    compare(&common::straight_dance(10, 10.0, &common::symmetric(5.0, 10.0)), &inst, Matrix4::zeros());
}

#[test]
fn filter_equals_batch_with_three_children_a_corner_and_an_uncertain_start() {
    let inst = Instrument {
        centring_instrument_m: 0.001,
        centring_target_m: 0.0015,
        min_range_m: 1.0,
        ..Instrument::default()
    };
    let formation = vec![Vector3::new(2.0, 4.0, 0.2), Vector3::new(2.0, -4.0, -0.1), Vector3::new(6.0, 1.0, 0.4)];
    let start = Matrix4::from_diagonal(&Vector4::new(1e-6, 4e-6, 1e-6, (10.0 * RAD_PER_ARCSEC).powi(2)));
    compare(&common::l_shaped_dance(4.0, &formation), &inst, start);
}

#[test]
fn filter_equals_batch_over_150_compact_cycles_where_the_normal_matrix_is_ill_conditioned() {
    let inst = Instrument { min_range_m: 1.0, ..Instrument::default() };
    let dance = common::straight_dance(150, 4.0, &common::symmetric(2.0, 4.0));
    let net = network(&dance, Matrix4::zeros());
    // Show the premise: the batch normal matrix (whitened JᵀJ) is beyond 1e12.
    let batch = adjust(&net, &inst, 3).expect("adjust");
    let eig = batch.covariance.clone().symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    assert!(hi / lo > 1e12, "condition {:e}", hi / lo);
    let filter = predict(&dance, &inst, &Matrix4::zeros()).expect("predict");
    let f = filter.last().expect("cycles").covariance;
    let b = batch.station_covariance(dance.stations.len() - 1);
    let rel = (f - b).norm() / b.norm();
    assert!(rel < 1e-6, "relative difference {rel:e}");
}
