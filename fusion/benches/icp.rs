//! ICP on the 3DTK pair (scan001 → scan000, 0.5–32.5 m): the preprocessing
//! steps and one registration at voxel 0.1 m, max correspondence 1 m; and
//! the scanner's position estimated from scan000's spacing
//! (`fusion::viewpoint`, what `match` does for each scan that does not say
//! where its scanner stood).
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p fusion --bench icp`

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use fusion::icp::{IcpConfig, Method, Target, align};
use nalgebra::Point3;
use scanner::io::{read, read_3dtk_pose};
use scanner::reduced_points;

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/3dtk_dat").join(rel)
}

fn scan(k: usize) -> Vec<Point3<f32>> {
    let c = read(&data(&format!("scan{k:03}.3d"))).expect("scan");
    c.points.into_iter().filter(|p| (0.5..32.5).contains(&p.coords.norm())).collect()
}

fn icp(c: &mut Criterion) {
    let (target, source) = (scan(0), scan(1));
    let pose = |k: usize| read_3dtk_pose(&data(&format!("scan{k:03}.pose"))).expect("pose");
    let init = pose(0).inverse() * pose(1);
    let (src, tgt) = (reduced_points(&source, 0.1).expect("r"), reduced_points(&target, 0.1).expect("r"));
    let prepared = Target::new(&tgt, 10).expect("target");
    let mut g = c.benchmark_group("icp 3dtk 0←1");
    g.bench_function("reduced points 0.1 m (source)", |b| b.iter(|| reduced_points(black_box(&source), 0.1)));
    g.bench_function("k-d tree only", |b| b.iter(|| Target::new(black_box(&tgt), 0)));
    // Normals are estimated as ICP needs them: `normals()` estimates them all.
    g.bench_function("k-d tree + normals (k = 10)", |b| {
        b.iter(|| Target::new(black_box(&tgt), 10).map(|t| t.normals()))
    });
    for method in [Method::PointToPlane, Method::PointToPoint] {
        let cfg = IcpConfig { method, ..IcpConfig::default() };
        g.bench_function(format!("align {method:?}"), |b| b.iter(|| align(black_box(&src), &prepared, &init, &cfg)));
    }
    g.finish();
}

/// The choice of k-d tree: build the reduced target and answer one
/// nearest-neighbour query per reduced source point (at the odometry guess),
/// single-threaded, with kiddo's `ImmutableKdTree` (its default layout:
/// arena leaves of 32 points), kiddo with flat leaves of 16 (the layout
/// `fusion::icp` uses), `kd-tree` and `rstar`. The others' answers are
/// checked against kiddo's.
fn kd_trees(c: &mut Criterion) {
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    let (target, source) = (scan(0), scan(1));
    let pose = |k: usize| read_3dtk_pose(&data(&format!("scan{k:03}.pose"))).expect("pose");
    let init = (pose(0).inverse() * pose(1)).cast::<f32>();
    let tgt: Vec<[f32; 3]> = reduced_points(&target, 0.1).expect("r").iter().map(|p| [p.x, p.y, p.z]).collect();
    let queries: Vec<[f32; 3]> =
        reduced_points(&source, 0.1).expect("r").iter().map(|p| (init * p).coords.into()).collect();
    type Flat16 = fusion::icp::KdTree;
    let immutable = ImmutableKdTree::<f32, 3>::new_from_slice(&tgt).expect("tree");
    let flat = Flat16::new_from_slice(&tgt).expect("tree");
    let flat_nn = |q: &[f32; 3]| flat.query(q).nearest_one::<SquaredEuclidean<f32>>().execute().distance;
    let kdt = kd_tree::KdTree::build_by_ordered_float(tgt.clone());
    let rtree = rstar::RTree::bulk_load(tgt.clone());
    let kiddo_nn = |q: &[f32; 3]| immutable.query(q).nearest_one::<SquaredEuclidean<f32>>().execute().distance;
    let truth: Vec<f32> = queries.iter().map(kiddo_nn).collect();
    let agree = |d: &[f32]| d.iter().zip(&truth).all(|(a, b)| (a - b).abs() <= 1e-6 * b.max(1.0));
    assert!(agree(&queries.iter().map(flat_nn).collect::<Vec<_>>()));
    assert!(agree(&queries.iter().map(|q| kdt.nearest(q).expect("nn").squared_distance).collect::<Vec<_>>()));
    let d2 = |a: &[f32; 3], b: &[f32; 3]| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2);
    assert!(agree(&queries.iter().map(|q| d2(q, rtree.nearest_neighbor(*q).expect("nn"))).collect::<Vec<_>>()));

    let mut g = c.benchmark_group(format!("k-d trees: {} points, {} queries", tgt.len(), queries.len()));
    g.bench_function("build kiddo ImmutableKdTree", |b| {
        b.iter(|| ImmutableKdTree::<f32, 3>::new_from_slice(black_box(&tgt)))
    });
    g.bench_function("build kiddo flat leaves of 16", |b| b.iter(|| Flat16::new_from_slice(black_box(&tgt))));
    g.bench_function("build kd-tree", |b| b.iter(|| kd_tree::KdTree::build_by_ordered_float(black_box(tgt.clone()))));
    g.bench_function("build rstar", |b| b.iter(|| rstar::RTree::bulk_load(black_box(tgt.clone()))));
    let sum = |f: &dyn Fn(&[f32; 3]) -> f32| queries.iter().map(f).sum::<f32>();
    g.bench_function("query kiddo ImmutableKdTree", |b| b.iter(|| sum(&kiddo_nn)));
    g.bench_function("query kiddo flat leaves of 16", |b| b.iter(|| sum(&flat_nn)));
    let one = std::num::NonZero::<usize>::MIN;
    g.bench_function("query kiddo within 1 m", |b| {
        b.iter(|| {
            sum(&|q| {
                immutable
                    .query(q)
                    .nearest_n::<SquaredEuclidean<f32>>(one)
                    .within(1.0)
                    .execute()
                    .first()
                    .map_or(0.0, |r| r.distance)
            })
        })
    });
    g.bench_function("query kd-tree", |b| b.iter(|| sum(&|q| kdt.nearest(q).map_or(0.0, |r| r.squared_distance))));
    g.bench_function("query rstar", |b| b.iter(|| sum(&|q| rtree.nearest_neighbor(*q).map_or(0.0, |p| p[0]))));
    g.finish();
}

fn viewpoint(c: &mut Criterion) {
    let points = scan(0);
    let mut g = c.benchmark_group("viewpoint 3dtk scan000");
    g.bench_function("estimate", |b| b.iter(|| fusion::viewpoint::estimate(black_box(&points))));
    g.finish();
}

criterion_group!(benches, kd_trees, icp, viewpoint);
criterion_main!(benches);
