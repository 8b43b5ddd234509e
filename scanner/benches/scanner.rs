//! Simulator and scan-file throughput.
//!
//! `cargo bench -p scanner --bench scanner`

use std::hint::black_box;

use cps::ParentPose;
use cps::geom::builtin;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Isometry3, Translation3};
use scanner::io::{Format, PcdData, PlyEncoding, read, write};
use scanner::sim::{LmsConfig, SimHead, SimLms, SimWorld};
use scanner::{HeadKind, PointCloud, reduced_points, scan_3d};

fn hall_scan() -> scanner::Scan {
    let world = SimWorld::new(builtin("hall").expect("hall"), ParentPose::new(14.0, 4.0, 1.4, 0.4), vec![]);
    let body_from_head = Isometry3::from_parts(Translation3::new(0.1, 0.0, 0.3), nalgebra::UnitQuaternion::identity());
    let mut lms = SimLms::new(world.clone(), LmsConfig::default(), HeadKind::RotatingTable, body_from_head, 1);
    let mut head = SimHead::new(world, HeadKind::RotatingTable);
    scan_3d(&mut head, &mut lms, 720, &body_from_head, &mut |_, _| {}).expect("scan")
}

fn simulate(c: &mut Criterion) {
    let mut g = c.benchmark_group("simulate");
    g.sample_size(10);
    g.throughput(Throughput::Elements(720 * 361));
    g.bench_function("hall rotating table 0.5°×0.5° (259,920 rays)", |b| b.iter(|| black_box(hall_scan())));
    g.finish();
}

fn reduce(c: &mut Criterion) {
    let scan = hall_scan();
    let mut g = c.benchmark_group("reduced points");
    g.throughput(Throughput::Elements(scan.len() as u64));
    for cell in [0.05, 0.2] {
        g.bench_function(format!("{} points, {cell} m cells", scan.len()), |b| {
            b.iter(|| black_box(reduced_points(&scan.points, cell).expect("reduce")))
        });
    }
    g.finish();
}

fn files(c: &mut Criterion) {
    let cloud = PointCloud::from_points(hall_scan().points);
    let dir = tempfile::tempdir().expect("temp dir");
    let mut g = c.benchmark_group("files");
    g.sample_size(10);
    g.throughput(Throughput::Elements(cloud.len() as u64));
    for (name, format) in [
        ("scan.3d", Format::ThreeDtk),
        ("scan.xyz", Format::Xyz),
        ("scan.ply", Format::Ply(PlyEncoding::BinaryLittleEndian)),
        ("scan.pcd", Format::Pcd(PcdData::Binary)),
        ("scanc.pcd", Format::Pcd(PcdData::BinaryCompressed)),
        ("scan.las", Format::Las),
        ("scan.laz", Format::Laz),
        ("scan.copc.laz", Format::Copc),
        ("scan.e57", Format::E57),
    ] {
        let path = dir.path().join(name);
        g.bench_function(format!("write {name}"), |b| b.iter(|| write(&path, &cloud, format).expect("write")));
        g.bench_function(format!("read {name}"), |b| b.iter(|| black_box(read(&path).expect("read"))));
    }
    g.finish();
}

/// Decoding continuous LMS output (20h 24h): 100 telegrams of 361 values
/// (0.5°, mm; 732 bytes each) arriving in 64-byte reads, each telegram's
/// CRC checked, its values decoded and classified (distance or no-return
/// code). At 500 kBd (10 bits per byte) the line carries 50,000 bytes/s.
fn decode_stream(c: &mut Criterion) {
    use scanner::protocol::sick::{
        Decoder, Direction, Event, Range, STATUS_OK, Unit, decode_measured, distance, encode_measured,
    };
    let words: Vec<u16> = (0..361).map(|i| if i % 50 == 7 { 0x7FF7 } else { 1000 + 37 * i as u16 }).collect();
    let stream: Vec<u8> = (0..100).flat_map(|_| encode_measured(&words, Unit::Mm, STATUS_OK)).collect();
    let mut g = c.benchmark_group("LMS continuous output");
    g.throughput(Throughput::Bytes(stream.len() as u64));
    g.bench_function(format!("{} bytes, 100 scans of 361 values, 64-byte reads", stream.len()), |b| {
        b.iter(|| {
            let mut d = Decoder::new(Direction::FromDevice);
            let mut returns = 0_usize;
            for chunk in stream.chunks(64) {
                d.push(chunk);
                while let Some(e) = d.next_event() {
                    if let Event::Frame(f) = e {
                        let m = decode_measured(&f, false).expect("B0h");
                        returns += m.words.iter().filter(|w| distance(**w, Range::Bits15).is_ok()).count();
                    }
                }
            }
            black_box(returns)
        })
    });
    g.finish();
}

criterion_group!(benches, simulate, reduce, files, decode_stream);
criterion_main!(benches);
