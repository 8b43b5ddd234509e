//! The real scans in `data/` (shipped with the repository): point counts as stated in their
//! READMEs, and the 3DTK poses put consecutive scans on top of each other.

use std::collections::HashMap;
use std::path::PathBuf;

use nalgebra::{Isometry3, Point3};
use scanner::io::{from_3dtk_axes, read, read_3dtk_pose, read_matrix4};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data").join(rel)
}

/// Every file a data folder's README lists in its checksum table has that
/// size and SHA-256, and every file in the folder is listed: the scans the
/// tests read are the ones the READMEs describe, byte for byte.
#[test]
fn shipped_scans_match_their_readme_checksums() {
    use sha2::{Digest, Sha256};
    for folder in ["3dtk_dat", "pcl_room_scans", "small_gicp_pair"] {
        let readme = std::fs::read_to_string(data(folder).join("README.md")).expect("README.md");
        let table = &readme[readme.find("## Checksums").unwrap_or_else(|| panic!("{folder}: no checksum table"))..];
        let mut listed = Vec::new();
        for row in table.lines().filter(|l| l.starts_with("| `")) {
            let cells: Vec<&str> = row.split('|').map(|c| c.trim().trim_matches('`')).collect();
            let (name, bytes, sum) = (cells[1], cells[2], cells[3]);
            let content = std::fs::read(data(folder).join(name)).unwrap_or_else(|e| panic!("{folder}/{name}: {e}"));
            assert_eq!(content.len().to_string(), bytes, "{folder}/{name}: size");
            let digest: String = Sha256::digest(&content).iter().map(|b| format!("{b:02x}")).collect();
            assert_eq!(digest, sum, "{folder}/{name}: SHA-256");
            listed.push(name.to_string());
        }
        let mut present: Vec<String> = std::fs::read_dir(data(folder))
            .expect("folder")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .filter(|n| n != "README.md")
            .collect();
        present.sort();
        listed.sort();
        assert_eq!(present, listed, "{folder}: files on disk against the README's table");
        assert!(listed.len() >= 3, "{folder}: {} files listed", listed.len());
    }
}

#[test]
fn point_counts_match_the_readmes() {
    for (file, n, intensity) in [
        ("3dtk_dat/scan000.3d", 81_360, false),
        ("3dtk_dat/scan001.3d", 81_360, false),
        ("3dtk_dat/scan002.3d", 81_360, false),
        ("pcl_room_scans/room_scan1.pcd", 112_586, false),
        ("pcl_room_scans/room_scan2.pcd", 112_624, false),
        ("small_gicp_pair/target.ply", 69_088, true),
        ("small_gicp_pair/source.ply", 69_792, true),
    ] {
        let cloud = read(&data(file)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(cloud.len(), n, "{file}");
        assert_eq!(cloud.intensity.is_some(), intensity, "{file}");
    }
}

/// 3DTK's left-handed centimetres become our right-handed metres: the
/// median range is the README's ~1.5–1.8 m and "up" (3DTK y) is our z.
#[test]
fn threedtk_axes_and_units() {
    let cloud = read(&data("3dtk_dat/scan000.3d")).expect("scan000");
    let mut r: Vec<f32> = cloud.points.iter().map(|p| p.coords.norm()).collect();
    r.sort_by(f32::total_cmp);
    let median = r[r.len() / 2];
    assert!((1.3..2.0).contains(&median), "median range {median} m");
    // ~1480 max-range readings at 3276 cm = 32.76 m.
    let capped = r.iter().filter(|&&x| (x - 32.76).abs() < 0.05).count();
    assert!((1300..1700).contains(&capped), "{capped} capped points");
    // The first raw line is "x y z" in cm: check the conversion on it.
    let text = std::fs::read_to_string(data("3dtk_dat/scan000.3d")).expect("text");
    let v: Vec<f64> =
        text.lines().next().expect("line").split_whitespace().map(|t| t.parse().expect("number")).collect();
    let p = cloud.points[0];
    assert_eq!(p, Point3::new((v[2] / 100.0) as f32, (-v[0] / 100.0) as f32, (v[1] / 100.0) as f32));
}

fn rotation_deg(t: &Isometry3<f64>) -> f64 {
    t.rotation.angle().to_degrees()
}

/// The odometry poses give a relative transform within the README's stated
/// 0.69° / 5.5 cm (0←1) and 0.69° / 1.6 cm (1←2) of the reference.
#[test]
fn threedtk_poses_agree_with_the_reference() {
    let pose = |k: usize| read_3dtk_pose(&data(&format!("3dtk_dat/scan{k:03}.pose"))).expect("pose");
    assert!(rotation_deg(&pose(0)) < 1e-9 && pose(0).translation.vector.norm() < 1e-12);
    for (a, b, deg, cm) in [(0, 1, 0.69, 5.5), (1, 2, 0.69, 1.6)] {
        let odometry = pose(a).inverse() * pose(b);
        let reference = from_3dtk_axes(
            &read_matrix4(&data(&format!("3dtk_dat/reference_T_scan{a:03}_scan{b:03}.txt"))).expect("matrix"),
        );
        let diff = reference.inverse() * odometry;
        assert!((rotation_deg(&diff) - deg).abs() < 0.05, "{a}←{b}: {} deg", rotation_deg(&diff));
        assert!(
            (diff.translation.vector.norm() * 100.0 - cm).abs() < 0.5,
            "{a}←{b}: {} m",
            diff.translation.vector.norm()
        );
        // The robot drives ~1.6–1.8 m forward, which is our +x.
        assert!(odometry.translation.vector.x > 1.5, "{}", odometry.translation.vector);
    }
}

/// Scans placed in the world with their poses lie on each other: the
/// median distance from a point of scan 1 to its nearest neighbour in
/// scan 0 is about the point spacing (3 cm; the odometry is ~5 cm off) and
/// clearly less than when the pose is ignored (5 cm: the scene is a
/// corridor-like space, so the robot's 1.6 m step shifts it along itself).
#[test]
fn consecutive_scans_overlap_in_the_world() {
    const CELL: f64 = 0.1;
    let world = |k: usize, use_pose: bool| -> Vec<Point3<f64>> {
        let cloud = read(&data(&format!("3dtk_dat/scan{k:03}.3d"))).expect("scan");
        let pose = if use_pose {
            read_3dtk_pose(&data(&format!("3dtk_dat/scan{k:03}.pose"))).expect("pose")
        } else {
            Isometry3::identity()
        };
        cloud.points.iter().filter(|p| (0.5..8.0).contains(&p.coords.norm())).map(|p| pose * p.cast::<f64>()).collect()
    };
    let key = |p: &Point3<f64>| ((p.x / CELL).floor() as i32, (p.y / CELL).floor() as i32, (p.z / CELL).floor() as i32);
    let mut grid: HashMap<(i32, i32, i32), Vec<Point3<f64>>> = HashMap::new();
    for p in world(0, true) {
        grid.entry(key(&p)).or_default().push(p);
    }
    // Nearest neighbour within one cell (else CELL): exact below CELL.
    let nn = |p: &Point3<f64>| -> f64 {
        let (x, y, z) = key(p);
        let mut best = CELL;
        for c in (-1..=1).flat_map(|i| (-1..=1).flat_map(move |j| (-1..=1).map(move |k| (x + i, y + j, z + k)))) {
            for q in grid.get(&c).into_iter().flatten() {
                best = best.min((p - q).norm());
            }
        }
        best
    };
    let median = |pts: Vec<Point3<f64>>| {
        let mut d: Vec<f64> = pts.iter().step_by(7).map(nn).collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    };
    let with_pose = median(world(1, true));
    let without = median(world(1, false));
    assert!(with_pose < 0.035, "median nearest-neighbour distance with poses {with_pose:.4} m");
    assert!(without > 1.5 * with_pose, "with poses {with_pose:.4} m, without {without:.4} m");
}
