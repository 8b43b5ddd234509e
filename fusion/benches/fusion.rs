//! Direct transformation throughput against a plain memory copy of the same
//! bytes.
//!
//! `cargo bench -p fusion --bench fusion`

use std::hint::black_box;

use cps::ParentPose;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fusion::direct::{transform_into, world_from_scanner};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use scanner::Tilt;

fn direct(c: &mut Criterion) {
    let n = 1_000_000;
    let pts: Vec<Point3<f32>> = (0..n)
        .map(|i| {
            let f = i as f32 * 1e-4;
            Point3::new(f.sin() * 20.0, f.cos() * 10.0, f)
        })
        .collect();
    let iso = world_from_scanner(
        &ParentPose::new(100.0, 50.0, 1.5, 0.7),
        &Tilt { roll_rad: 0.01, pitch_rad: 0.02 },
        &Isometry3::from_parts(Translation3::new(0.1, 0.0, 0.4), UnitQuaternion::identity()),
    );
    let mut out = Vec::with_capacity(n);
    let mut copy = vec![Point3::origin(); n];
    let mut g = c.benchmark_group("direct transformation");
    g.throughput(Throughput::Bytes((n * 12) as u64));
    g.bench_function("memcpy 1M points (12 MB)", |b| {
        b.iter(|| {
            copy.copy_from_slice(black_box(&pts));
            black_box(&copy);
        })
    });
    g.bench_function("transform 1M points (12 MB)", |b| {
        b.iter(|| {
            transform_into(black_box(&pts), &iso, &mut out);
            black_box(&out);
        })
    });
    g.finish();
}

criterion_group!(benches, direct);
criterion_main!(benches);
