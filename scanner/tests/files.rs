//! Scan files: write → read round trips, and clear errors for bad files.

use std::path::Path;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scanner::io::{Format, PcdData, PlyEncoding, read, read_3dtk_pose, write, write_3dtk_pose};
use scanner::{Location, PointCloud, ScannerError};

fn cloud(n: usize, intensity: bool) -> PointCloud {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let points = (0..n)
        .map(|_| {
            Point3::new(rng.random_range(-40.0..40.0f32), rng.random_range(-12.0..12.0), rng.random_range(-1.0..6.0))
        })
        .collect();
    let intensity = intensity.then(|| (0..n).map(|_| rng.random_range(0.0..1000.0f32).round()).collect());
    PointCloud { points, intensity, ..PointCloud::default() }
}

fn round_trip(name: &str, format: Format, intensity: bool) -> (PointCloud, PointCloud) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(name);
    let original = cloud(5000, intensity);
    write(&path, &original, format).unwrap_or_else(|e| panic!("{e}"));
    assert!(!dir.path().join(format!("{name}.partial")).exists(), "temporary file left behind");
    let back = read(&path).unwrap_or_else(|e| panic!("{e}"));
    (original, back)
}

#[test]
fn exact_round_trips() {
    for (name, format) in [
        ("a.ply", Format::Ply(PlyEncoding::Ascii)),
        ("b.ply", Format::Ply(PlyEncoding::BinaryLittleEndian)),
        ("c.xyz", Format::Xyz),
        ("d.pcd", Format::Pcd(PcdData::Ascii)),
        ("e.pcd", Format::Pcd(PcdData::Binary)),
        ("f.pcd", Format::Pcd(PcdData::BinaryCompressed)),
        ("g.e57", Format::E57),
    ] {
        for intensity in [false, true] {
            let (original, back) = round_trip(name, format, intensity);
            assert_eq!(original, back, "{name} with intensity {intensity}");
        }
    }
    // 3DTK has no intensity column in the uos format we write.
    let (original, back) = round_trip("scan000.3d", Format::ThreeDtk, false);
    assert_eq!(original, back);
}

#[test]
fn las_keeps_points_to_its_scale() {
    let (original, back) = round_trip("h.las", Format::Las, true);
    assert_eq!(original.len(), back.len());
    for (a, b) in original.points.iter().zip(&back.points) {
        // 0.1 mm grid: half a step of rounding, plus f32's 4 µm at 40 m.
        assert!((a - b).amax() <= 0.5e-4 + 4e-6, "{a} vs {b}");
    }
    assert_eq!(original.intensity, back.intensity);
}

#[test]
fn threedtk_pose_round_trip() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("scan007.pose");
    let pose = Isometry3::from_parts(
        Translation3::new(12.5, -3.25, 0.75),
        UnitQuaternion::from_euler_angles(0.02, -0.03, 1.2),
    );
    write_3dtk_pose(&path, &pose).expect("write");
    let back = read_3dtk_pose(&path).expect("read");
    assert!((back.translation.vector - pose.translation.vector).norm() < 1e-12);
    assert!(back.rotation.angle_to(&pose.rotation) < 1e-12);
}

fn expect_file_error(path: &Path, location: Location, words: &str) {
    match read(path) {
        Err(ScannerError::File { path: p, location: l, message }) => {
            assert_eq!(p, path);
            assert_eq!(l, location, "{message}");
            assert!(message.contains(words), "'{message}' lacks '{words}'");
        }
        other => panic!("expected a file error for {}, got {other:?}", path.display()),
    }
}

#[test]
fn bad_files_name_the_file_and_where() {
    let dir = tempfile::tempdir().expect("temp dir");
    let p = |name: &str, bytes: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).expect("write");
        path
    };
    expect_file_error(&p("a.xyz", b"1 2 3\n4 5 6\n7 x 9\n"), Location::Line(3), "'x' is not a number");
    expect_file_error(&p("b.xyz", b"1 2 3\n4 5\n"), Location::Line(2), "2 values: expected 3");
    expect_file_error(&p("c.3d", b"# c\n1 2 3\n1 2 nan\n"), Location::Line(3), "not finite");
    expect_file_error(
        &p("d.pcd", b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 1\nDATA ascii\n1 2 3\n"),
        Location::Line(7),
        "same, non-zero length",
    );
    expect_file_error(
        &p(
            "e.pcd",
            b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 2\nDATA ascii\n1 2 3\n4 5 oops\n",
        ),
        Location::Line(9),
        "'oops' is not a number",
    );
    expect_file_error(
        &p("f.pcd", b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 1\nDATA lzma\n"),
        Location::Line(7),
        "expected ascii, binary or binary_compressed",
    );
    // Truncated binary and compressed PCD: the byte offset of the end.
    let header =
        b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA binary\n";
    let mut truncated = header.to_vec();
    truncated.extend_from_slice(&[0u8; 20]);
    expect_file_error(
        &p("g.pcd", &truncated),
        Location::Byte(truncated.len() as u64),
        "truncated: 3 points of 12 bytes",
    );
    let dir2 = tempfile::tempdir().expect("temp dir");
    let good = dir2.path().join("h.pcd");
    write(&good, &cloud(100, false), Format::Pcd(PcdData::BinaryCompressed)).expect("write");
    let bytes = std::fs::read(&good).expect("read");
    let cut = &bytes[..bytes.len() - 50];
    expect_file_error(&p("h.pcd", cut), Location::Byte(cut.len() as u64), "truncated");
    // PLY: a truncated binary body and a broken header.
    let ply = dir2.path().join("i.ply");
    write(&ply, &cloud(100, false), Format::Ply(PlyEncoding::BinaryLittleEndian)).expect("write");
    let bytes = std::fs::read(&ply).expect("read");
    match read(&p("i.ply", &bytes[..bytes.len() - 7])) {
        Err(ScannerError::File { path, .. }) => assert!(path.ends_with("i.ply")),
        other => panic!("truncated PLY: {other:?}"),
    }
    match read(&p("j.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 three\n")) {
        Err(ScannerError::File { location: Location::Line(8), .. }) => {}
        other => panic!("non-numeric PLY: {other:?}"),
    }
    // Missing file and unknown extension.
    match read(&dir.path().join("missing.ply")) {
        Err(e @ ScannerError::Io { .. }) => assert!(e.to_string().contains("missing.ply"), "{e}"),
        other => panic!("missing file: {other:?}"),
    }
    expect_file_error(&p("k.obj", b""), Location::File, "unknown scan file extension");
}

#[test]
fn frames_files_hold_the_transform_slam6d_reads() {
    use nalgebra::{Isometry3, Matrix4, Vector3};
    let dir = tempfile::tempdir().expect("tempdir");
    let iso = Isometry3::new(Vector3::new(12.5, -3.25, 1.5), Vector3::new(0.02, -0.01, 1.1));
    let frames = dir.path().join("scan007.frames");
    scanner::io::write_3dtk_frames(&frames, &iso).expect("frames");
    // By hand: 16 column-major values in 3DTK axes (x = −y, y = z, z = x of
    // ours), translation in cm, then the type; applied to a point in 3DTK cm.
    let text = std::fs::read_to_string(&frames).expect("text");
    let v: Vec<f64> = text.split_whitespace().map(|t| t.parse().expect("number")).collect();
    assert_eq!(v.len(), 17, "{text}");
    let m = Matrix4::from_column_slice(&v[..16]);
    let p = nalgebra::Point3::new(0.7, 2.0, -0.4);
    let to_3dtk_cm = |q: &nalgebra::Point3<f64>| nalgebra::Vector4::new(-q.y * 100.0, q.z * 100.0, q.x * 100.0, 1.0);
    let got = m * to_3dtk_cm(&p);
    let want = to_3dtk_cm(&(iso * p));
    assert!((got - want).norm() < 1e-9, "{got} vs {want}");
    // Read back (the last line wins, as in slam6d), and the .pose agrees.
    std::fs::write(&frames, format!("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2\n{text}")).expect("two frames");
    let back = scanner::io::read_3dtk_frames(&frames).expect("read");
    assert!((back.to_homogeneous() - iso.to_homogeneous()).norm() < 1e-12);
    let pose = dir.path().join("scan007.pose");
    scanner::io::write_3dtk_pose(&pose, &iso).expect("pose");
    let from_pose = scanner::io::read_3dtk_pose(&pose).expect("pose back");
    assert!((from_pose.to_homogeneous() - back.to_homogeneous()).norm() < 1e-9);
    // A line that is not a frame is named.
    std::fs::write(&frames, "1 2 3\n").expect("bad");
    let e = scanner::io::read_3dtk_frames(&frames).expect_err("bad frame").to_string();
    assert!(e.contains("line 1") && e.contains("expected 16"), "{e}");
}

/// CRC-32 (IEEE, reflected 0xEDB88320) bit by bit: an independent
/// derivation of the checksum the writers compute on the way.
fn crc32_bitwise(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

#[test]
fn the_checksum_of_a_written_file_is_that_of_its_bytes() {
    assert_eq!(crc32_bitwise(b"123456789"), 0xCBF4_3926, "the standard check value");
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = cloud(3000, true);
    for (name, format) in [
        ("c.3d", Format::ThreeDtk),
        ("c.ply", Format::Ply(PlyEncoding::BinaryLittleEndian)),
        ("c.xyz", Format::Xyz),
        ("c.pcd", Format::Pcd(PcdData::BinaryCompressed)),
        ("c.las", Format::Las),
        ("c.e57", Format::E57),
    ] {
        let path = dir.path().join(name);
        let crc = scanner::io::write_with_crc32(&path, &cloud, format).expect("written");
        let bytes = std::fs::read(&path).expect("read back");
        assert_eq!(crc, crc32_bitwise(&bytes), "{name}");
        assert_eq!(scanner::io::file_crc32(&path).expect("file"), crc, "{name}");
    }
}
