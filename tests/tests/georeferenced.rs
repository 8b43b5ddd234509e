//! A survey at national-grid coordinates (E 500 000, N 5 500 000, H 300):
//! the same room, route and seed as at the local origin, so every estimate
//! and every point must be the local run's shifted by the offset. The cloud
//! files keep 0.1 mm (read back in f64: LAS by the `las` crate, PLY and XYZ
//! by hand), where f32 world coordinates would be quantised to 0.5 m.

use std::path::Path;

use serde_json::Value;
use tests::{example, run_mission};

const OFFSET: [f64; 3] = [500_000.0, 5_500_000.0, 300.0];

/// A 20 × 12 × 3 m room with a few objects, shifted by `o`.
fn scene(o: [f64; 3]) -> String {
    let p = |x: f64, y: f64| format!("[{}, {}]", x + o[0], y + o[1]);
    let q = |x: f64, y: f64, z: f64| format!("[{}, {}, {}]", x + o[0], y + o[1], z + o[2]);
    format!(
        "name = \"room\"\n\
         [[wall]]\nname = \"walls\"\npath_m = [{}, {}, {}, {}]\nclosed = true\nz_min_m = {}\nz_max_m = {}\n\
         [[polygon]]\nname = \"floor\"\nvertices_m = [{}, {}, {}, {}]\n\
         [[polygon]]\nname = \"ceiling\"\nvertices_m = [{}, {}, {}, {}]\n\
         [[box]]\nname = \"crate\"\ncenter_m = {}\nsize_m = [1, 1, 1]\nyaw_deg = 30\n\
         [[cylinder]]\nname = \"column\"\na_m = {}\nb_m = {}\nradius_m = 0.3\n",
        p(0.0, 0.0),
        p(20.0, 0.0),
        p(20.0, 12.0),
        p(0.0, 12.0),
        o[2],
        o[2] + 3.0,
        q(0.0, 0.0, 0.0),
        q(20.0, 0.0, 0.0),
        q(20.0, 12.0, 0.0),
        q(0.0, 12.0, 0.0),
        q(0.0, 0.0, 3.0),
        q(20.0, 0.0, 3.0),
        q(20.0, 12.0, 3.0),
        q(0.0, 12.0, 3.0),
        q(8.0, 9.0, 0.5),
        q(14.0, 8.5, 0.0),
        q(14.0, 8.5, 3.0),
    )
}

/// The hall's team and instruments in the room, at `o`, without control.
fn mission(dir: &Path, o: [f64; 3]) -> std::path::PathBuf {
    std::fs::write(dir.join("room.toml"), scene(o)).expect("scene");
    let hall = std::fs::read_to_string(example("hall.toml")).expect("hall");
    let route = "[[1.5, 4.2, 1.5], [37.5, 4.2, 1.5], [37.5, 7.8, 1.5], [1.5, 7.8, 1.5]]";
    assert!(hall.contains(route) && hall.contains("scene = \"hall\""), "hall.toml changed: update this test");
    let text = hall
        .replace(
            route,
            &format!(
                "[[{}, {}, {}], [{}, {}, {}]]",
                2.0 + o[0],
                4.0 + o[1],
                1.5 + o[2],
                12.8 + o[0],
                4.0 + o[1],
                1.5 + o[2]
            ),
        )
        .replace("control_at = [0, 10, 21]", "")
        .replace("scene = \"hall\"", "scene_file = \"room.toml\"")
        .replace("slices = 180", "slices = 12")
        .replace("formats = [\"ply\"]", "formats = [\"ply\", \"las\", \"xyz\"]");
    let text = text.split("[[control]]").next().expect("before the control");
    let path = dir.join("m.toml");
    std::fs::write(&path, text).expect("mission");
    path
}

fn report(dir: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).expect("report")).expect("json")
}

/// x, y, z of a binary little-endian PLY whose vertices are three doubles
/// (or floats) and nothing else.
fn ply_points(path: &Path) -> Vec<[f64; 3]> {
    let bytes = std::fs::read(path).expect("ply");
    let end = bytes.windows(11).position(|w| w == b"end_header\n").expect("a header") + 11;
    let header = String::from_utf8_lossy(&bytes[..end]);
    let double = header.contains("property double x");
    let size = if double { 8 } else { 4 };
    bytes[end..]
        .chunks_exact(3 * size)
        .map(|c| {
            [0, 1, 2].map(|k| {
                let b = &c[k * size..(k + 1) * size];
                if double {
                    f64::from_le_bytes(b.try_into().expect("8"))
                } else {
                    f64::from(f32::from_le_bytes(b.try_into().expect("4")))
                }
            })
        })
        .collect()
}

fn las_points(path: &Path) -> Vec<[f64; 3]> {
    let mut reader = las::Reader::from_path(path).expect("the las crate reads it");
    let n = reader.header().number_of_points();
    let data = reader.read_points(n).expect("points");
    data.points().map(|p| p.expect("a point")).map(|p| [p.x, p.y, p.z]).collect()
}

fn xyz_points(path: &Path) -> Vec<[f64; 3]> {
    std::fs::read_to_string(path)
        .expect("xyz")
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().take(3).map(|t| t.parse().expect("number")).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// Every point of `geo` is `local`'s shifted by OFFSET, within `tol_m`.
fn assert_shifted(what: &str, geo: &[[f64; 3]], local: &[[f64; 3]], tol_m: f64) {
    assert_eq!(geo.len(), local.len(), "{what}: points");
    assert!(!geo.is_empty());
    let worst = geo
        .iter()
        .zip(local)
        .flat_map(|(g, l)| (0..3).map(move |k| (g[k] - OFFSET[k] - l[k]).abs()))
        .fold(0.0, f64::max);
    assert!(worst <= tol_m, "{what}: worst difference {worst} m");
}

#[test]
fn a_survey_at_national_grid_coordinates_keeps_its_millimetres() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (local_dir, geo_dir) = (dir.path().join("local"), dir.path().join("geo"));
    std::fs::create_dir_all(&local_dir).expect("local");
    std::fs::create_dir_all(&geo_dir).expect("geo");
    let local = run_mission(&mission(&local_dir, [0.0; 3]), &local_dir.join("run"));
    assert_eq!(local.code, 0, "{}", local.stderr);
    let geo = run_mission(&mission(&geo_dir, OFFSET), &geo_dir.join("run"));
    assert_eq!(geo.code, 0, "{}", geo.stderr);

    // The estimates: the local run's, shifted.
    let (l, g) = (report(&local_dir.join("run")), report(&geo_dir.join("run")));
    let (ls, gs) = (l["stations"].as_array().expect("stations"), g["stations"].as_array().expect("stations"));
    assert_eq!(ls.len(), gs.len());
    for (a, b) in ls.iter().zip(gs) {
        for (k, key) in ["x_m", "y_m", "z_m"].iter().enumerate() {
            let (a, b) = (a["pose"][key].as_f64().expect("a"), b["pose"][key].as_f64().expect("b"));
            assert!((b - OFFSET[k] - a).abs() < 1e-6, "{key}: {b} vs {a}");
        }
    }

    // The clouds: every point the local one's shifted, to 0.1 mm (the
    // local cloud itself is f32 within 20 m of its origin: ~2 µm).
    let (lr, gr) = (local_dir.join("run"), geo_dir.join("run"));
    assert_shifted("PLY", &ply_points(&gr.join("cloud.ply")), &ply_points(&lr.join("cloud.ply")), 1e-4);
    assert_shifted("LAS", &las_points(&gr.join("cloud.las")), &las_points(&lr.join("cloud.las")), 1.5e-4);
    assert_shifted("XYZ", &xyz_points(&gr.join("cloud.xyz")), &xyz_points(&lr.join("cloud.xyz")), 1.5e-4);

    // The LAS knows which scan each point came from (`point_source_id` =
    // the station), as many points as the journal recorded for that scan,
    // and says what wrote it and when.
    let mut reader = las::Reader::from_path(gr.join("cloud.las")).expect("las");
    let header = reader.header().clone();
    assert_eq!(header.generating_software(), "cps-survey");
    assert!(header.system_identifier().starts_with("cps-survey"), "{}", header.system_identifier());
    assert!(header.date().is_some_and(|d| d.format("%Y").to_string().parse::<i32>().expect("year") >= 2026));
    let data = reader.read_points(header.number_of_points()).expect("points");
    let mut per_scan = std::collections::BTreeMap::new();
    for p in data.points() {
        *per_scan.entry(p.expect("a point").point_source_id).or_insert(0usize) += 1;
    }
    let journal = std::fs::read_to_string(gr.join("journal.jsonl")).expect("journal");
    let recorded: std::collections::BTreeMap<u16, usize> = journal
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).expect("a line"))
        .filter(|e| e["event"] == "scan")
        .map(|e| (e["station"].as_u64().expect("station") as u16, e["data"]["points"].as_u64().expect("n") as usize))
        .collect();
    assert_eq!(per_scan, recorded);
}
