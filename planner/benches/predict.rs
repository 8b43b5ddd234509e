//! Prediction of long routes: `cargo bench -p planner --bench predict`.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Matrix4, Point3, Vector3};

use cps::{Instrument, RAD_PER_ARCSEC};
use planner::{leapfrog, predict, stations};

fn instrument() -> Instrument {
    Instrument {
        sigma_distance_m: 0.003,
        sigma_distance_ppm: 0.0,
        sigma_hz_rad: 5.0 * RAD_PER_ARCSEC,
        sigma_v_rad: 5.0 * RAD_PER_ARCSEC,
        min_range_m: 4.0,
        max_range_m: 400.0,
        ..Instrument::default()
    }
}

fn bench(c: &mut Criterion) {
    let inst = instrument();
    for (cycles, children) in [(10_000usize, 2usize), (10_000, 4)] {
        let route = [Point3::origin(), Point3::new(10.0 * cycles as f64, 0.0, 0.0)];
        let formation: Vec<Vector3<f64>> = (0..children)
            .map(|j| {
                let side = if j % 2 == 0 { 1.0 } else { -1.0 };
                Vector3::new(10.0 + 5.0 * (j / 2) as f64, side * 50.0, 0.0)
            })
            .collect();
        let dance = leapfrog(stations(&route, 10.0).expect("route"), &formation).expect("formation");
        c.bench_function(&format!("predict {cycles} cycles, {children} children"), |b| {
            b.iter(|| predict(&dance, &inst, &Matrix4::zeros()).expect("predict"))
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
