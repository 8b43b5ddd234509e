//! The sequential filter's last-station covariance equals the dense batch
//! least-squares adjustment of the same dance.

mod common;

use cps::batch::{AdjustOptions, Network, NetworkReading, Point, Station, adjust};
use cps::{Instrument, RAD_PER_ARCSEC, observe};
use nalgebra::{Matrix4, Vector3, Vector4};
use planner::{Dance, predict};

fn network(dance: &Dance, start_covariance: Matrix4<f64>, instrument: &Instrument) -> Network {
    let n = dance.n_children();
    let mut points = Vec::new();
    let mut readings = Vec::new();
    for (k, c) in dance.cycles.iter().enumerate() {
        for (j, p) in c.children.iter().enumerate() {
            let point = k * n + j;
            points.push(Point { position: *p, prior: None });
            for station in [c.from, c.to] {
                let reading = observe(&dance.station_pose(station), p).expect("regular");
                readings.push(NetworkReading {
                    station,
                    point,
                    reading,
                    covariance: instrument.reading_covariance(&reading),
                });
            }
        }
    }
    let mut stations: Vec<Station> =
        (0..dance.stations.len()).map(|k| Station { pose: dance.station_pose(k), prior: None }).collect();
    stations[0].prior = Some(start_covariance);
    Network { stations, points, readings }
}

fn options() -> AdjustOptions {
    AdjustOptions { snooping: false, ..AdjustOptions::default() }
}

fn compare(dance: &Dance, instrument: &Instrument, start: Matrix4<f64>) {
    let filter = predict(dance, instrument, &start).expect("predict");
    let batch = adjust(&network(dance, start, instrument), &options()).expect("adjust");
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
    let net = network(&dance, Matrix4::zeros(), &inst);
    // Show the premise: the dense normal matrix (whitened JᵀJ, station 0
    // held) is beyond 1e12.
    let unknowns = 4 * (net.stations.len() - 1) + 3 * net.points.len();
    let mut normal = nalgebra::DMatrix::<f64>::zeros(unknowns, unknowns);
    for r in &net.readings {
        let station = net.stations[r.station].pose;
        let j = cps::observation::observation_jacobians(&station, &net.points[r.point].position).expect("regular");
        let mut row = nalgebra::DMatrix::<f64>::zeros(3, unknowns);
        if r.station > 0 {
            row.view_mut((0, 4 * (r.station - 1)), (3, 4)).copy_from(&j.wrt_parent);
        }
        row.view_mut((0, 4 * (net.stations.len() - 1) + 3 * r.point), (3, 3)).copy_from(&j.wrt_child);
        let w = nalgebra::DMatrix::from_diagonal(
            &r.covariance.diagonal().map(|v| 1.0 / v).into_owned().resize_vertically(3, 0.0),
        );
        normal += row.transpose() * w * &row;
    }
    let eig = normal.symmetric_eigenvalues();
    assert!(eig.max() / eig.min() > 1e12, "condition {:e}", eig.max() / eig.min());
    let batch = adjust(&net, &options()).expect("adjust");
    let filter = predict(&dance, &inst, &Matrix4::zeros()).expect("predict");
    let f = filter.last().expect("cycles").covariance;
    let b = batch.station_covariance(dance.stations.len() - 1);
    let rel = (f - b).norm() / b.norm();
    assert!(rel < 1e-6, "relative difference {rel:e}");
}
