//! A cloud at national-grid coordinates (E 500 000, N 5 500 000, H 300)
//! through every format: read back in f64 by the format libraries (`las`,
//! `e57`) or by hand (PLY, PCD, XYZ), every point within 0.1 mm of its
//! coordinates — where f32 coordinates would be quantised to 0.5 m.

use std::path::Path;

use nalgebra::{Point3, Vector3};
use scanner::io::{Format, PcdData, PlyEncoding, PointCloud, read, write};

const ORIGIN: [f64; 3] = [500_000.0, 5_500_000.0, 300.0];

/// Points spread over ±60 m around the origin, at odd sub-millimetre offsets.
fn cloud() -> PointCloud {
    let points = (0..500)
        .map(|i| {
            let t = f64::from(i);
            Point3::new(
                (60.0 * (0.37 * t).sin() + 0.000_123 * t) as f32,
                (60.0 * (0.11 * t).cos() - 0.000_077 * t) as f32,
                (3.0 * (0.05 * t).sin()) as f32,
            )
        })
        .collect();
    PointCloud { points, origin: Vector3::from(ORIGIN), ..PointCloud::default() }
}

/// Every (x, y, z) within `tolerance_m` of the cloud's coordinates, in order.
fn assert_coordinates(what: &str, got: &[[f64; 3]], cloud: &PointCloud, tolerance_m: f64) {
    assert_eq!(got.len(), cloud.len(), "{what}: points");
    for (i, g) in got.iter().enumerate() {
        let want = cloud.coordinates(i);
        for k in 0..3 {
            assert!((g[k] - want[k]).abs() <= tolerance_m, "{what}: point {i} axis {k}: {} vs {}", g[k], want[k]);
        }
    }
}

fn text_rows(path: &Path, skip_until: Option<&str>) -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(path).expect("text");
    let body = match skip_until {
        Some(marker) => text.split_once(marker).expect("the header's end").1,
        None => &text,
    };
    body.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().take(3).map(|t| t.parse().expect("a number")).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// The doubles after a binary header ending in `marker`, three per point
/// with `stride` bytes per point.
fn binary_rows(path: &Path, marker: &[u8], n: usize, stride: usize) -> Vec<[f64; 3]> {
    let bytes = std::fs::read(path).expect("bytes");
    let start = bytes.windows(marker.len()).position(|w| w == marker).expect("the header's end") + marker.len();
    (0..n)
        .map(|i| {
            let at = start + i * stride;
            [0, 1, 2].map(|k| {
                let b: [u8; 8] = bytes[at + 8 * k..at + 8 * k + 8].try_into().expect("8 bytes");
                f64::from_le_bytes(b)
            })
        })
        .collect()
}

#[test]
fn a_georeferenced_cloud_keeps_its_coordinates_in_every_format() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = cloud();
    let d = dir.path();

    // LAS: scaled integers on offsets that carry the origin.
    let las = d.join("c.las");
    write(&las, &cloud, Format::Las).expect("LAS");
    let mut reader = las::Reader::from_path(&las).expect("the las crate reads it");
    let data = reader.read_points(cloud.len() as u64).expect("points");
    let got: Vec<[f64; 3]> = data.points().map(|p| p.expect("a point")).map(|p| [p.x, p.y, p.z]).collect();
    assert_coordinates("LAS", &got, &cloud, 0.5e-4 + 1e-9);

    // E57: 64-bit Cartesian records.
    let e57 = d.join("c.e57");
    write(&e57, &cloud, Format::E57).expect("E57");
    let mut reader = e57::E57Reader::from_file(&e57).expect("the e57 crate reads it");
    let pc = reader.pointclouds().remove(0);
    let got: Vec<[f64; 3]> = reader
        .pointcloud_simple(&pc)
        .expect("points")
        .map(|p| match p.expect("a point").cartesian {
            e57::CartesianCoordinate::Valid { x, y, z } => [x, y, z],
            other => panic!("{other:?}"),
        })
        .collect();
    assert_coordinates("E57", &got, &cloud, 1e-6);

    // PLY, binary and ASCII: double x, y, z.
    let ply = d.join("c.ply");
    write(&ply, &cloud, Format::Ply(PlyEncoding::BinaryLittleEndian)).expect("PLY");
    let header = String::from_utf8_lossy(&std::fs::read(&ply).expect("ply")[..400]).into_owned();
    assert!(header.contains("property double x") && header.contains("georeferenced"), "{header}");
    assert_coordinates("PLY", &binary_rows(&ply, b"end_header\n", cloud.len(), 24), &cloud, 1e-6);
    let ply_ascii = d.join("a.ply");
    write(&ply_ascii, &cloud, Format::Ply(PlyEncoding::Ascii)).expect("PLY ascii");
    assert_coordinates("PLY ascii", &text_rows(&ply_ascii, Some("end_header\n")), &cloud, 1e-6);

    // PCD, binary and ASCII: SIZE 8 for x, y, z.
    let pcd = d.join("c.pcd");
    write(&pcd, &cloud, Format::Pcd(PcdData::Binary)).expect("PCD");
    assert_coordinates("PCD", &binary_rows(&pcd, b"DATA binary\n", cloud.len(), 24), &cloud, 1e-6);
    let pcd_ascii = d.join("a.pcd");
    write(&pcd_ascii, &cloud, Format::Pcd(PcdData::Ascii)).expect("PCD ascii");
    assert_coordinates("PCD ascii", &text_rows(&pcd_ascii, Some("DATA ascii\n")), &cloud, 0.5e-4 + 1e-9);

    // XYZ: fixed 0.1 mm decimals.
    let xyz = d.join("c.xyz");
    write(&xyz, &cloud, Format::Xyz).expect("XYZ");
    assert_coordinates("XYZ", &text_rows(&xyz, None), &cloud, 0.5e-4 + 1e-9);

    // Our own readers take every one back (as f32 coordinates).
    for path in [&las, &e57, &ply, &ply_ascii, &pcd, &pcd_ascii, &xyz] {
        let back = read(path).expect("read back");
        assert_eq!(back.len(), cloud.len(), "{}", path.display());
        let (x, y) = (f64::from(back.points[0].x), f64::from(back.points[0].y));
        assert!((x - cloud.coordinates(0)[0]).abs() < 1.0 && (y - cloud.coordinates(0)[1]).abs() < 1.0);
    }
    // What f32 coordinates would have done.
    let quantised = f64::from((ORIGIN[1] + 0.3) as f32) - (ORIGIN[1] + 0.3);
    assert!(quantised.abs() > 0.1, "f32 at N 5 500 000 is off by {quantised} m");
}
