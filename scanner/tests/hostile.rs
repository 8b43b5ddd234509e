//! Scan files whose headers lie: counts far beyond the bytes, overflowing
//! products, NaN scales. Each is refused with an error naming the file —
//! no panic, no allocation sized from the claim. The files are made here.

use std::path::{Path, PathBuf};

use nalgebra::Point3;
use scanner::ScannerError;
use scanner::io::{Format, PointCloud, read, write};

fn file(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write");
    path
}

fn refused(path: &Path, words: &str) {
    match read(path) {
        Err(e @ ScannerError::File { .. }) => {
            let text = e.to_string();
            assert!(text.contains(&path.display().to_string()), "{text}");
            assert!(text.contains(words), "'{text}' lacks '{words}'");
        }
        other => panic!("{}: expected a file error with '{words}', got {other:?}", path.display()),
    }
}

const PCD_HEAD: &str = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";

#[test]
fn pcd_counts_are_claims() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    // 2^62 binary points in 24 bytes.
    let mut b = format!("{PCD_HEAD}WIDTH 4611686018427387904\nHEIGHT 1\nPOINTS 4611686018427387904\nDATA binary\n")
        .into_bytes();
    b.extend_from_slice(&[0u8; 24]);
    refused(&file(d, "huge-binary.pcd", &b), "truncated");
    // 10^12 ASCII points, one row.
    let a = format!("{PCD_HEAD}WIDTH 1000000000000\nHEIGHT 1\nPOINTS 1000000000000\nDATA ascii\n1 2 3\n");
    refused(&file(d, "huge-ascii.pcd", a.as_bytes()), "the header says 1000000000000");
    // WIDTH × HEIGHT overflows (no POINTS).
    let w = format!("{PCD_HEAD}WIDTH 4294967296\nHEIGHT 4294967296\nDATA ascii\n1 2 3\n");
    refused(&file(d, "overflow.pcd", w.as_bytes()), "overflows");
    // Compressed: the sizes claim 4 GB from 8 bytes.
    let mut c = format!("{PCD_HEAD}WIDTH 357913941\nHEIGHT 1\nPOINTS 357913941\nDATA binary_compressed\n").into_bytes();
    c.extend_from_slice(&8u32.to_le_bytes());
    c.extend_from_slice(&4_294_967_292u32.to_le_bytes());
    c.extend_from_slice(&[0u8; 8]);
    refused(&file(d, "huge-compressed.pcd", &c), "more than LZF can expand");
}

#[test]
fn ply_counts_are_claims() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    // An element of 10^12 items and no properties before the vertices.
    let empty = "ply\nformat binary_little_endian 1.0\nelement junk 1000000000000\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    refused(&file(d, "empty-element.ply", empty.as_bytes()), "no properties");
    // 10^12 vertices of 12 bytes in a 100-byte file.
    let many = "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    refused(&file(d, "many.ply", many.as_bytes()), "the file has");
    let ascii = "ply\nformat ascii 1.0\nelement vertex 1000000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
    refused(&file(d, "many-ascii.ply", ascii.as_bytes()), "the file has");
}

/// A valid LAS of three points, as we write it.
fn las_bytes(dir: &Path) -> Vec<u8> {
    let cloud = PointCloud {
        points: vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.0, 5.0, 6.0), Point3::new(7.0, 8.0, 9.0)],
        ..PointCloud::default()
    };
    let path = dir.join("good.las");
    write(&path, &cloud, Format::Las).expect("write LAS");
    std::fs::read(&path).expect("read back")
}

#[test]
fn las_counts_and_scales_are_claims() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let good = las_bytes(d);
    assert_eq!(read(&d.join("good.las")).expect("the good file reads").len(), 3);
    // LAS 1.4: the legacy count (u32 at 107) and the count (u64 at 247).
    let mut legacy = good.clone();
    legacy[107..111].copy_from_slice(&u32::MAX.to_le_bytes());
    legacy[247..255].copy_from_slice(&u64::from(u32::MAX).to_le_bytes());
    refused(&file(d, "legacy.las", &legacy), "the header says 4294967295 points");
    // 2^63 points in the 64-bit count, the legacy one 0 (as LAS 1.4 writes
    // counts beyond u32).
    let mut huge = good.clone();
    huge[107..111].copy_from_slice(&0u32.to_le_bytes());
    huge[247..255].copy_from_slice(&(1u64 << 63).to_le_bytes());
    refused(&file(d, "huge.las", &huge), "points of");
    // A NaN x scale (f64 at 131).
    let mut nan = good.clone();
    nan[131..139].copy_from_slice(&f64::NAN.to_le_bytes());
    refused(&file(d, "nan-scale.las", &nan), "scale");
    // A finite x scale of 1e300 makes every x overflow f32 (found by the
    // scan_file fuzz target): refused, not an infinite point.
    let mut vast = good.clone();
    vast[131..139].copy_from_slice(&1e300f64.to_le_bytes());
    refused(&file(d, "vast-scale.las", &vast), "overflows a 32-bit float");
    // An extended VLR (LAS 1.4: start u64 at 235, count u32 at 243) whose
    // 64-bit length is 2^62 (found by the fuzz target: 5.7 EB asked of the
    // allocator).
    let mut evlr = good;
    let start = evlr.len() as u64;
    evlr[235..243].copy_from_slice(&start.to_le_bytes());
    evlr[243..247].copy_from_slice(&1u32.to_le_bytes());
    let mut record = vec![0u8; 60];
    record[20..28].copy_from_slice(&(1u64 << 62).to_le_bytes());
    evlr.extend_from_slice(&record);
    refused(&file(d, "evlr.las", &evlr), "extended VLR 0 of 1 claims 4611686018427387904 bytes");
}

#[test]
fn errors_name_the_place_and_say_what_was_expected() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A number beyond f32 on line 2 of an XYZ file: named there, not later.
    let xyz = file(dir.path(), "big.xyz", b"0 0 0\n1e300 0 0\n");
    refused(&xyz, "line 2: '1e300 0 0' overflows a 32-bit float");
    // Random bytes are not a PLY file (not "stream did not contain valid UTF-8").
    let noise: Vec<u8> = (0u32..300).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
    let ply = file(dir.path(), "noise.ply", &noise);
    refused(&ply, "not a PLY file: expected it to begin with 'ply'");
    // Binary data has no lines: the file is named as a whole.
    let mut short = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    short.extend_from_slice(&[0u8; 36]);
    short.truncate(short.len() - 30);
    let ply = file(dir.path(), "short.ply", &short);
    let e = read(&ply).expect_err("truncated binary");
    let text = e.to_string();
    assert!(matches!(e, ScannerError::File { location: scanner::Location::File, .. }), "{text}");
    assert!(text.contains("binary element 'vertex'") && !text.contains(": line "), "{text}");
    // An ASCII row that does not parse: its line, the row, what was expected,
    // and no parser dump.
    let ascii = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n1 2 x\n";
    let ply = file(dir.path(), "bad.ply", ascii);
    refused(&ply, "line 9: '1 2 x' is not a row of element 'vertex': expected x y z");
    assert!(!read(&ply).expect_err("bad row").to_string().contains("String:"));
}

/// An E57 scan whose pose quaternion is w = 1e300 (its norm overflows to
/// ∞, the rotation to NaN): refused naming the data3D and the norm, not an
/// ICP error later (issue 34, U4); a slightly unnormalised one (1 + 1e-5)
/// is read, normalised.
#[test]
fn an_e57_pose_that_is_no_unit_quaternion_is_refused() {
    use e57::{E57Writer, Quaternion, Record, RecordValue, Transform, Translation};
    let dir = tempfile::tempdir().expect("temp dir");
    for (w, ok) in [(1e300, false), (2.0, false), (1.0 + 1e-5, true)] {
        let path = dir.path().join("q.e57");
        let mut writer = E57Writer::from_file(&path, "{a1b2c3d4-0000-4000-8000-000000000001}").expect("writer");
        let prototype = vec![Record::CARTESIAN_X_F64, Record::CARTESIAN_Y_F64, Record::CARTESIAN_Z_F64];
        let mut pc = writer.add_pointcloud("{a1b2c3d4-0000-4000-8000-000000000002}", prototype).expect("pc");
        pc.set_transform(Some(Transform {
            rotation: Quaternion { w, x: 0.0, y: 0.0, z: 0.0 },
            translation: Translation { x: 1.0, y: 2.0, z: 3.0 },
        }));
        for i in 0..10 {
            pc.add_point(vec![RecordValue::Double(f64::from(i)), RecordValue::Double(0.0), RecordValue::Double(1.0)])
                .expect("point");
        }
        pc.finalize().expect("finalised");
        writer.finalize().expect("written");
        match scanner::io::read_e57_scans(&path) {
            Ok(scans) => {
                assert!(ok, "w = {w}: read");
                assert!(scans[0].world_from_scan.rotation.angle() < 1e-12, "normalised to the identity");
            }
            Err(e) => {
                assert!(!ok, "w = {w}: {e}");
                let text = e.to_string();
                assert!(text.contains("data3D[0]") && text.contains("quaternion norm"), "{text}");
            }
        }
    }
}

/// An ASCII PLY row "nan 0 0" (issue 34, U6: "is not a row of element
/// 'vertex'"): its line, the value and that it is not finite.
#[test]
fn a_ply_row_with_a_nan_says_so() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut text = String::from(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
    );
    text.push_str("1 2 3\nnan 0 0\n4 5 6\n");
    let path = file(dir.path(), "nan.ply", text.as_bytes());
    refused(&path, "line 9");
    refused(&path, "'nan 0 0': the value nan is not finite: expected finite numbers");
}

/// Mutation fuzzing of the LAZ, COPC and E57 readers in the test itself
/// (cargo-fuzz is not installed on the build machines; issue 34 asks for
/// these readers fuzzed): valid small files, each mutated 1,500 times —
/// bytes flipped, overwritten with extremes, runs zeroed, the file cut —
/// and read. Every read returns (a cloud or an error), never panics; an
/// accepted cloud has finite points and one colour/time/intensity per
/// point or none. Deterministic (seeded).
#[test]
fn laz_copc_and_e57_readers_survive_mutated_files() {
    use rand::{Rng, SeedableRng};
    let dir = tempfile::tempdir().expect("temp dir");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(34);
    let n = 400;
    let cloud = PointCloud {
        points: (0..n).map(|i| Point3::new(i as f32 * 0.01, (i % 7) as f32, (i % 3) as f32 * 0.5)).collect(),
        intensity: Some((0..n).map(|i| i as f32).collect()),
        color: Some((0..n).map(|i| [i as u16 * 100, 7, 65_000]).collect()),
        time: Some((0..n).map(|i| 1.448e9 + i as f64).collect()),
        ..PointCloud::default()
    };
    let mut executions = 0;
    for (name, format) in [("m.laz", Format::Laz), ("m.copc.laz", Format::Copc), ("m.e57", Format::E57)] {
        let valid = dir.path().join(format!("valid-{name}"));
        write(&valid, &cloud, format).expect("written");
        let bytes = std::fs::read(&valid).expect("read");
        for _ in 0..1500 {
            let mut m = bytes.clone();
            match rng.random_range(0..4) {
                0 => (0..rng.random_range(1..8)).for_each(|_| {
                    let at = rng.random_range(0..m.len());
                    m[at] ^= 1 << rng.random_range(0..8);
                }),
                1 => {
                    let at = rng.random_range(0..m.len().saturating_sub(8));
                    let v: [u8; 8] = if rng.random() { [0xff; 8] } else { 0x7fef_ffff_ffff_ffffu64.to_le_bytes() };
                    m[at..at + 8].copy_from_slice(&v);
                }
                2 => {
                    let at = rng.random_range(0..m.len());
                    let end = m.len().min(at + rng.random_range(1..256));
                    m[at..end].fill(0);
                }
                _ => m.truncate(rng.random_range(0..m.len())),
            }
            let path = dir.path().join(name);
            std::fs::write(&path, &m).expect("mutated");
            executions += 1;
            let Ok(back) = read(&path) else { continue };
            assert!(back.points.iter().all(|p| p.iter().all(|v| v.is_finite())), "{name}: a point not finite");
            for (what, len) in [
                ("intensities", back.intensity.as_ref().map(Vec::len)),
                ("colours", back.color.as_ref().map(Vec::len)),
                ("times", back.time.as_ref().map(Vec::len)),
            ] {
                assert!(len.is_none_or(|l| l == back.len()), "{name}: {what} for some points only");
            }
            if format == Format::E57 {
                let _ = scanner::io::read_e57_scans(&path);
            }
        }
    }
    assert_eq!(executions, 4500);
}
