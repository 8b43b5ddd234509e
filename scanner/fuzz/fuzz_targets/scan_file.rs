//! Every scan-file reader from arbitrary bytes: the first byte picks the
//! format (PLY, PCD, LAS, E57, XYZ, 3DTK scan, 3DTK pose), the rest is the
//! file. Never a panic, an abort or an allocation beyond the bytes' worth;
//! an accepted cloud has finite points, intensities for every point or none,
//! and — for the formats without compression — no more points than bytes.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

const EXTENSIONS: [&str; 7] = ["ply", "pcd", "las", "e57", "xyz", "3d", "pose"];

fn dir() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("scan-file-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&d).expect("a scratch directory");
        d
    })
}

fuzz_target!(|data: &[u8]| {
    let Some((&pick, bytes)) = data.split_first() else { return };
    let ext = EXTENSIONS[pick as usize % EXTENSIONS.len()];
    let path = dir().join(format!("input.{ext}"));
    std::fs::write(&path, bytes).expect("the scratch file");
    if ext == "pose" {
        if let Ok(pose) = scanner::io::read_3dtk_pose(&path) {
            assert!(pose.translation.vector.iter().all(|v| v.is_finite()));
        }
        return;
    }
    let Ok(cloud) = scanner::io::read(&path) else { return };
    assert!(cloud.points.iter().all(|p| p.iter().all(|v| v.is_finite())), "{ext}: a point not finite");
    if let Some(i) = &cloud.intensity {
        assert_eq!(i.len(), cloud.points.len(), "{ext}: intensities for some points only");
    }
    // PCD (LZF) and E57 (bit-packed, constant fields in no bits) compress.
    if !matches!(ext, "pcd" | "e57") {
        assert!(cloud.points.len() <= bytes.len(), "{ext}: {} points from {} bytes", cloud.points.len(), bytes.len());
    }
});
