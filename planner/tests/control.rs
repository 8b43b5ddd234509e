//! A dance tied to control points: the start resected from two, the route
//! closing on two more; the filter's and the batch adjustment's predicted
//! covariances against Monte Carlo of the real procedure (control prisms
//! off their given coordinates by their covariance and their centring,
//! noisy readings, the filter, then the adjustment of every trial).

mod common;

use cps::Instrument;
use cps::batch::{AdjustOptions, adjust};
use nalgebra::{Matrix3, Matrix4, Point3, Vector3};
use planner::ControlPoint;
use planner::montecarlo::{monte_carlo, nees_interval};

fn instrument() -> Instrument {
    Instrument {
        centring_target_m: 0.0005,
        centring_instrument_m: 0.0003,
        min_range_m: 1.0,
        ..common::paper_instrument()
    }
}

fn control() -> Vec<ControlPoint> {
    let fixed = Matrix3::zeros();
    let weighted = Matrix3::from_diagonal(&Vector3::new(1e-6, 1e-6, 4e-6));
    vec![
        ControlPoint { name: "A".into(), position: Point3::new(-6.0, 8.0, 0.5), covariance: fixed },
        ControlPoint { name: "B".into(), position: Point3::new(-6.0, -8.0, 0.3), covariance: fixed },
        ControlPoint { name: "C".into(), position: Point3::new(106.0, 9.0, 0.4), covariance: weighted },
        ControlPoint { name: "D".into(), position: Point3::new(106.0, -9.0, 0.6), covariance: weighted },
    ]
}

/// Ten 10 m cycles; A and B seen from the start, C and D from the end.
fn dance() -> planner::Dance {
    let open = common::straight_dance(10, 10.0, &common::symmetric(5.0, 10.0));
    let mut sightings = vec![Vec::new(); open.stations.len()];
    sightings[0] = vec![0, 1];
    sightings[10] = vec![2, 3];
    open.with_control(control(), sightings)
}

#[test]
fn closing_on_control_improves_every_station_and_monte_carlo_agrees() {
    let inst = instrument();
    let d = dance();
    assert!(d.resects_start());
    // The filter: the start comes from the resection (no start covariance
    // given), the last station from children and control together.
    let filter = planner::predict(&d, &inst, &Matrix4::zeros()).expect("predict");
    assert!(cps::sigma_xy2(&filter.start) > 0.0, "the resected start has its own uncertainty");
    let open = planner::predict(&common::straight_dance(10, 10.0, &common::symmetric(5.0, 10.0)), &inst, &filter.start)
        .expect("open traverse");
    let (closed_last, open_last) = (filter.last().expect("cycles"), open.last().expect("cycles"));
    assert!(closed_last.sigma_xy2_m2() < 0.5 * open_last.sigma_xy2_m2(), "closing on C, D");
    // The adjustment improves every station on the filter (smoothing), the
    // middle most.
    let planned = planner::network::planned(&d, &inst, &Matrix4::zeros()).expect("network");
    let a = adjust(&planned.network, &AdjustOptions { snooping: false, ..AdjustOptions::default() }).expect("adjust");
    assert!(a.sigma0_squared < 1e-12 && a.redundancy > 0);
    for c in &filter.cycles {
        let (f, b) = (c.sigma_xy2_m2(), cps::sigma_xy2(&a.station_covariance(c.cycle)));
        assert!(b <= f * (1.0 + 1e-9), "station {}: adjusted {b:e} vs filter {f:e}", c.cycle);
    }
    let mid = 5;
    assert!(cps::sigma_xy2(&a.station_covariance(mid)) < 0.8 * filter.cycles[mid - 1].sigma_xy2_m2());
    // The last station sees C and D: the filter already uses them there.
    let last = cps::sigma_xy2(&a.station_covariance(10));
    assert!((last / closed_last.sigma_xy2_m2() - 1.0).abs() < 0.05, "{last:e} vs {:e}", closed_last.sigma_xy2_m2());

    // Monte Carlo: 600 trials. Each station's mean NEES (4-D) within 3.5σ
    // of 4 (√(8/n) per trial mean), and its empirical σx² + σy² within
    // 3.5·√(2/n) of the prediction (the bound of an isotropic error, the
    // widest), filter and adjusted alike.
    let trials = 600;
    let mc = monte_carlo(&d, &inst, &Matrix4::zeros(), trials, 3).expect("monte carlo");
    let bound = 3.5 * (8.0 / trials as f64).sqrt();
    let bound_xy = 3.5 * (2.0 / trials as f64).sqrt();
    let (lo, hi) = nees_interval(4, trials);
    assert!(hi - 4.0 < bound && 4.0 - lo < bound, "the 95 % interval lies inside the test's bound");
    assert_eq!(mc.adjusted.len(), 11, "every station, the resected start too");
    for s in mc.filter.iter().chain(&mc.adjusted) {
        assert!((s.nees_mean - 4.0).abs() < bound, "station {}: NEES {:.3} ± {bound:.3}", s.cycle, s.nees_mean);
        let ratio = s.ratio_xy();
        assert!((ratio - 1.0).abs() < bound_xy, "station {}: empirical/predicted σxy² {ratio:.3}", s.cycle);
    }
    // The check can fail: the open traverse's covariance is not the
    // adjusted one in the middle.
    let m = &mc.adjusted[mid];
    let wrong = cps::sigma_xy2(&m.empirical) / filter.cycles[mid - 1].sigma_xy2_m2();
    assert!((wrong - 1.0).abs() > bound_xy, "{wrong}");
}
