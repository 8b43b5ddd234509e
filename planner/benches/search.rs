//! Formation/stride/strategy search: `cargo bench -p planner --bench search`.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Matrix4, Point3};

#[path = "../tests/common/mod.rs"]
mod common;

use cps::Instrument;
use planner::constraints::Limits;
use planner::{Objective, Problem, SearchSpace, Strategy, search};

fn bench(c: &mut Criterion) {
    let inst = common::paper_instrument();
    let no_scans = |_: usize| false;
    // The seed's 1 km route, open space, sight lines ≤ 100 m.
    let route = [Point3::origin(), Point3::new(1000.0, 0.0, 0.0)];
    let open = Problem {
        route_m: &route,
        instrument: &inst,
        start_covariance: Matrix4::zeros(),
        n_children: 2,
        scene: None,
        limits: Limits::range(4.0, 400.0),
        scan_at: &no_scans,
        control: &[],
        control_at: &[],
    };
    let leapfrog =
        SearchSpace { strategies: vec![Strategy::Leapfrog], strides_m: vec![10.0], max_sight_line_m: 100.0, up_m: 0.0 };
    c.bench_function("search 1 km, leapfrog, stride 10 m", |b| {
        b.iter(|| search(&open, &leapfrog, Objective::MinVariance).expect("search"))
    });
    let all = SearchSpace {
        strategies: [Strategy::Leapfrog, Strategy::ParentHops { hops: 2 }, Strategy::ParentHops { hops: 3 }].to_vec(),
        strides_m: vec![5.0, 7.5, 10.0, 12.5, 15.0, 20.0],
        max_sight_line_m: 100.0,
        up_m: 0.0,
    };
    c.bench_function("search 1 km, 3 strategies × 6 strides", |b| {
        b.iter(|| search(&open, &all, Objective::MinVariance).expect("search"))
    });
    // The hall: 28 m, every sight line, move and clearance against the scene.
    let scene = cps::geom::builtin("hall").expect("hall");
    let hall_route = [Point3::new(2.0, 4.5, 1.5), Point3::new(30.0, 4.5, 1.5)];
    let every = |_: usize| true;
    let hall = Problem {
        route_m: &hall_route,
        instrument: &Instrument { min_range_m: 2.0, max_range_m: 500.0, ..inst.clone() },
        start_covariance: Matrix4::zeros(),
        n_children: 2,
        scene: Some(&scene),
        limits: Limits { footprint_radius_m: Some(0.3), scanner_max_range_m: Some(32.0), ..Limits::range(2.0, 500.0) },
        scan_at: &every,
        control: &[],
        control_at: &[],
    };
    let space = SearchSpace {
        strategies: [Strategy::Leapfrog, Strategy::ParentHops { hops: 2 }, Strategy::ParentHops { hops: 3 }].to_vec(),
        strides_m: vec![2.0, 3.0, 4.0, 6.0, 8.0],
        max_sight_line_m: 200.0,
        up_m: -0.5,
    };
    c.bench_function("search hall scene, 3 strategies × 5 strides", |b| {
        b.iter(|| search(&hall, &space, Objective::FewestCycles { max_sigma_xy_m: 0.05 }).expect("search"))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
