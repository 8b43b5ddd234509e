//! The formation/stride/strategy search on the seed's 1 km example.

mod common;

use common::paper_instrument as instrument;
use cps::Instrument;
use nalgebra::{Matrix4, Point3};
use planner::constraints::Limits;
use planner::{FormationKind, Objective, Problem, SearchSpace, Strategy, search};

fn best(max_sight_line_m: f64, strategies: Vec<Strategy>) -> planner::search::Evaluated {
    let route = [Point3::origin(), Point3::new(1000.0, 0.0, 0.0)];
    let inst = instrument();
    let no_scans = |_: usize| false;
    let problem = Problem {
        route_m: &route,
        instrument: &inst,
        start_covariance: Matrix4::zeros(),
        n_children: 2,
        scene: None,
        limits: Limits::range(inst.min_range_m, inst.max_range_m),
        scan_at: &no_scans,
        control: &[],
        control_at: &[],
    };
    let space = SearchSpace { strategies, strides_m: vec![10.0], max_sight_line_m, up_m: 0.0 };
    let result = search(&problem, &space, Objective::MinVariance).expect("search");
    result.best.expect("a feasible plan")
}

#[test]
fn long_sight_lines_reach_the_floor_of_the_model() {
    let b = best(100.0, vec![Strategy::Leapfrog]);
    // The floor for 3 mm / 5″ over 100 cycles of 10 m is about 0.0204 m².
    assert!(b.sigma_xy2_m2 < 0.0204 * 1.03, "{b:?}");
    assert!(b.sigma_xy2_m2 > 0.0204 * 0.9, "{b:?}");
    let FormationKind::Symmetric { forward_m, lateral_m } = b.candidate.formation else { panic!("symmetric") };
    assert!(forward_m.hypot(lateral_m) <= 100.0 + 1e-9);
    for c in &b.dance.cycles {
        for p in &c.children {
            for s in [c.from, c.to] {
                assert!((p - b.dance.stations[s].position).norm() <= 100.0 + 1e-9);
            }
        }
    }
}

#[test]
fn short_sight_lines_give_the_best_compact_formation() {
    let b = best(20.0, vec![Strategy::Leapfrog]);
    let wide = best(100.0, vec![Strategy::Leapfrog]);
    assert!(b.sigma_xy2_m2 > wide.sigma_xy2_m2);
    for c in &b.dance.cycles {
        for p in &c.children {
            for s in [c.from, c.to] {
                let r = (p - b.dance.stations[s].position).norm();
                assert!((4.0 - 1e-9..=20.0 + 1e-9).contains(&r), "{r}");
            }
        }
    }
    // No symmetric formation within 20 m does better (a dense independent
    // scan of the same family).
    let route = [Point3::origin(), Point3::new(1000.0, 0.0, 0.0)];
    let st = planner::stations(&route, 10.0).expect("route");
    let inst = Instrument { max_range_m: 20.0, ..instrument() };
    let mut floor = f64::INFINITY;
    for i in 0..=80 {
        for k in 1..=40 {
            let (a, b) = (-20.0 + 0.5 * i as f64, 0.5 * k as f64);
            let f = FormationKind::Symmetric { forward_m: a, lateral_m: b }.offsets(2, 0.0);
            let d = planner::leapfrog(st.clone(), &f).expect("dance");
            if let Ok(p) = planner::predict(&d, &inst, &Matrix4::zeros()) {
                floor = floor.min(p.last().expect("cycles").sigma_xy2_m2());
            }
        }
    }
    assert!(b.sigma_xy2_m2 <= floor * 1.01, "search {} vs scan {floor}", b.sigma_xy2_m2);
}
