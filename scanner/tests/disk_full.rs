//! A LAS, LAZ or COPC file that cannot be written — a full disk; a
//! file-size limit (`ulimit -f`, writes past it fail with EFBIG) stands in
//! for it — is an error naming the file, never a panic in the `las`
//! crate's writer, which closes itself when dropped and panicked when that
//! failed. The test runs itself again under the limit.
#![cfg(unix)]

use std::process::Command;

use nalgebra::{Point3, Vector3};
use scanner::io::{Crs, Format, PointCloud, write};

const TEST: &str = "las_laz_and_copc_files_that_cannot_be_written_are_errors_not_panics";
const INNER: &str = "CPS_SURVEY_FILE_SIZE_LIMITED";

/// 300,000 points: 9 MB as LAS, over a megabyte as LAZ.
fn cloud() -> PointCloud {
    let points = (0..300_000u32)
        .map(|i| {
            let t = f64::from(i);
            Point3::new((40.0 * (0.37 * t).sin()) as f32, (12.0 * (0.11 * t).cos()) as f32, (t * 2e-5) as f32)
        })
        .collect();
    PointCloud {
        points,
        origin: Vector3::new(500_000.0, 5_500_000.0, 300.0),
        crs: Some(Crs::parse("EPSG:25832").expect("UTM")),
        ..PointCloud::default()
    }
}

// The run under the limit tells the outer one what it refused on stdout.
#[allow(clippy::print_stdout)]
#[test]
fn las_laz_and_copc_files_that_cannot_be_written_are_errors_not_panics() {
    if std::env::var_os(INNER).is_some() {
        let dir = tempfile::tempdir().expect("tempdir");
        let cloud = cloud();
        for (format, name) in [(Format::Las, "c.las"), (Format::Laz, "c.laz"), (Format::Copc, "c.copc.laz")] {
            let path = dir.path().join(name);
            let error = write(&path, &cloud, format).expect_err("past the file-size limit");
            assert!(error.to_string().contains(name), "{name}: {error}");
            assert!(!path.exists(), "{name}: nothing left under its name");
            println!("refused: {name}: {error}");
        }
        let left: Vec<_> = std::fs::read_dir(dir.path()).expect("dir").collect();
        assert!(left.is_empty(), "temporary files left: {left:?}");
        return;
    }
    let exe = std::env::current_exe().expect("the test binary");
    // 200 blocks: 100 or 200 KB, as the shell counts them.
    let script = format!("ulimit -f 200; trap '' XFSZ; exec \"$0\" --exact {TEST} --nocapture --test-threads 1");
    let output = Command::new("sh").args(["-c", &script]).arg(exe).env(INNER, "1").output().expect("sh runs");
    let (stdout, stderr) = (String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "exit {:?}\n{stdout}\n{stderr}", output.status.code());
    for name in ["c.las", "c.laz", "c.copc.laz"] {
        assert!(stdout.contains(&format!("refused: {name}")), "{name} not refused:\n{stdout}\n{stderr}");
    }
}
