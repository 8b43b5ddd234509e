//! A survey at national-grid coordinates (E 500 000, N 5 500 000, H 300):
//! the same room, route and seed as at the local origin, so every estimate
//! and every point must be the local run's shifted by the offset. The cloud
//! files keep 0.1 mm (read back in f64: LAS by the `las` crate, PLY and XYZ
//! by hand), where f32 world coordinates would be quantised to 0.5 m. The
//! georeferenced run names its CRS (`[site] crs = "EPSG:25832"`) in the
//! report, LAS/LAZ/COPC and E57, and its LAS and E57 say which scan each
//! point came from, when, and (E57) from where.

use std::path::Path;
use tests::Edit;

use serde_json::Value;
use tests::{example, run_mission};

const OFFSET: [f64; 3] = [500_000.0, 5_500_000.0, 300.0];

const LOCAL_FORMATS: &str = r#"["ply", "las", "xyz"]"#;
const GEO_FORMATS: &str = r#"["ply", "las", "laz", "copc", "e57", "xyz"]"#;

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

/// The hall's team and instruments in the room, at `o`, without control;
/// `extra` appended (a `[site]` table).
fn mission(dir: &Path, o: [f64; 3], formats: &str, extra: &str) -> std::path::PathBuf {
    std::fs::write(dir.join("room.toml"), scene(o)).expect("scene");
    let hall = std::fs::read_to_string(example("hall.toml")).expect("hall");
    let route = "[[1.5, 4.2, 1.5], [37.5, 4.2, 1.5], [37.5, 7.8, 1.5], [1.5, 7.8, 1.5]]";
    assert!(hall.contains(route) && hall.contains("scene = \"hall\""), "hall.toml changed: update this test");
    let text = hall
        .edit(
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
        .edit("control_at = [0, 10, 21]", "")
        .edit("scene = \"hall\"", "scene_file = \"room.toml\"")
        .edit("slices = 180", "slices = 12")
        .edit("formats = [\"ply\"]", &format!("formats = {formats}"));
    let text = text.split("[[control]]").next().expect("before the control");
    let path = dir.join("m.toml");
    std::fs::write(&path, format!("{text}\n{extra}")).expect("mission");
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
    let local = run_mission(&mission(&local_dir, [0.0; 3], LOCAL_FORMATS, ""), &local_dir.join("run"));
    assert_eq!(local.code, 0, "{}", local.stderr);
    let site = "[site]\ncrs = \"EPSG:25832\"\n";
    let geo = run_mission(&mission(&geo_dir, OFFSET, GEO_FORMATS, site), &geo_dir.join("run"));
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

    deliverables(&gr, &g);
    // Without `[site]`, a local frame named after the mission.
    let crs = &l["crs"];
    assert_eq!((crs["local"].as_bool(), crs["epsg"].is_null()), (Some(true), true), "{crs}");
    assert!(crs["wkt"].as_str().expect("wkt").starts_with("LOCAL_CS[\"hall local frame\""), "{crs}");
}

/// The georeferenced run's deliverables: its CRS in the report, LAS, LAZ,
/// COPC and E57; each LAS point's time its scan's (journaled); LAZ the
/// LAS's points; COPC all of them; E57 one `data3D` per scan at the
/// report's fused pose, whose points (pose applied) are the LAS's.
fn deliverables(run: &Path, report: &Value) {
    let crs = &report["crs"];
    assert_eq!(
        (crs["name"].as_str(), crs["epsg"].as_u64(), crs["local"].as_bool()),
        (Some("EPSG:25832"), Some(25832), Some(false))
    );
    let wkt = crs["wkt"].as_str().expect("wkt");
    assert!(wkt.starts_with("PROJCS[\"ETRS89 / UTM zone 32N\""), "{wkt}");

    let journal = std::fs::read_to_string(run.join("journal.jsonl")).expect("journal");
    let scans: Vec<Value> = journal
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).expect("a line"))
        .filter(|e| e["event"] == "scan")
        .collect();
    // GPS = UNIX − 315,964,800 s + 18 leap seconds; LAS keeps GPS − 10⁹.
    let adjusted: std::collections::BTreeMap<u16, f64> = scans
        .iter()
        .map(|e| {
            (
                e["station"].as_u64().expect("station") as u16,
                e["data"]["unix_time_s"].as_f64().expect("time") - 315_964_800.0 + 18.0 - 1e9,
            )
        })
        .collect();

    let read_las = |name: &str| {
        let mut reader = las::Reader::from_path(run.join(name)).expect("the las crate reads it");
        let header = reader.header().clone();
        assert_eq!(header.point_format().to_u8().expect("format"), 6, "{name}");
        assert!(header.has_wkt_crs(), "{name}");
        let vlr = header.all_vlrs().find(|v| v.user_id == "LASF_Projection" && v.record_id == 2112).expect("WKT VLR");
        assert_eq!(String::from_utf8_lossy(&vlr.data).trim_end_matches('\0'), wkt, "{name}");
        let data = reader.read_all().expect("points");
        data.points().map(|p| p.expect("a point")).collect::<Vec<las::Point>>()
    };
    let las_points = read_las("cloud.las");
    for p in &las_points {
        let want = adjusted[&p.point_source_id];
        assert!(
            (p.gps_time.expect("time") - want).abs() < 1e-6,
            "scan {}: {:?} vs {want}",
            p.point_source_id,
            p.gps_time
        );
    }
    assert_eq!(read_las("cloud.laz"), las_points, "LAZ holds the LAS's points");
    let mut copc = las::CopcReader::from_path(run.join("cloud.copc.laz")).expect("COPC");
    let octree = copc.query(las::LodSelection::All, las::BoundsSelection::All).expect("COPC points");
    assert_eq!(octree.len(), las_points.len());

    let mut e57 = e57::E57Reader::from_file(run.join("cloud.e57")).expect("the e57 crate reads it");
    assert_eq!(e57.coordinate_metadata(), Some(wkt));
    let clouds = e57.pointclouds();
    let fused = report["fusion"]["scans"].as_array().expect("fused scans");
    assert_eq!(clouds.len(), scans.len());
    assert_eq!(clouds.len(), fused.len());
    let mut at = 0;
    for (pc, f) in clouds.iter().zip(fused) {
        let station = f["station"].as_u64().expect("station");
        assert_eq!(pc.name.as_deref(), Some(format!("scan{station:03}").as_str()));
        let t = &pc.transform.as_ref().expect("pose").translation;
        for (v, key) in [t.x, t.y, t.z].into_iter().zip(["x_m", "y_m", "z_m"]) {
            assert!((v - f["pose"][key].as_f64().expect("pose")).abs() < 1e-6, "{key}: {v} vs {}", f["pose"][key]);
        }
        let mut points = e57.pointcloud_simple(pc).expect("points");
        points.apply_pose(true);
        for p in points {
            let e57::CartesianCoordinate::Valid { x, y, z } = p.expect("a point").cartesian else { panic!("invalid") };
            let l = &las_points[at];
            assert_eq!(u64::from(l.point_source_id), station);
            assert!([x - l.x, y - l.y, z - l.z].iter().all(|d| d.abs() < 1.5e-4), "{:?} vs {l:?}", [x, y, z]);
            at += 1;
        }
    }
    assert_eq!(at, las_points.len());
}

/// A compound CRS (ETRS89 / UTM 32N + DHHN92 height, `EPSG:25832+5783`)
/// says which heights the deliverables carry: the same `COMPD_CS` in the
/// report, the LAS and COPC WKT VLR, E57's `coordinateMetadata` and the PLY
/// comments.
#[test]
fn a_compound_crs_states_the_heights_datum_in_every_deliverable() {
    let dir = tempfile::tempdir().expect("tempdir");
    let site = "[site]\ncrs = \"EPSG:25832+5783\"\n";
    let path = mission(dir.path(), OFFSET, r#"["ply", "las", "copc", "e57"]"#, site);
    let run = run_mission(&path, &dir.path().join("run"));
    assert_eq!(run.code, 0, "{}", run.stderr);
    let out = dir.path().join("run");
    let crs = &report(&out)["crs"];
    assert_eq!(
        (crs["name"].as_str(), crs["epsg"].is_null(), crs["local"].as_bool()),
        (Some("EPSG:25832+5783"), true, Some(false)),
        "{crs}"
    );
    let wkt = crs["wkt"].as_str().expect("wkt");
    assert!(wkt.starts_with("COMPD_CS[\"ETRS89 / UTM zone 32N + DHHN92 height\",PROJCS["), "{wkt}");
    assert!(wkt.contains(",VERT_CS[\"DHHN92 height\"") && !wkt.contains("TOWGS84"), "{wkt}");
    for name in ["cloud.las", "cloud.copc.laz"] {
        let header = las::Reader::from_path(out.join(name)).expect("las").header().clone();
        let vlr = header.all_vlrs().find(|v| v.user_id == "LASF_Projection" && v.record_id == 2112).expect("WKT VLR");
        assert_eq!(String::from_utf8_lossy(&vlr.data).trim_end_matches('\0'), wkt, "{name}");
    }
    let e57 = e57::E57Reader::from_file(out.join("cloud.e57")).expect("e57");
    assert_eq!(e57.coordinate_metadata(), Some(wkt));
    let ply = std::fs::read(out.join("cloud.ply")).expect("ply");
    let end = ply.windows(10).position(|w| w == b"end_header").expect("header");
    let header = String::from_utf8_lossy(&ply[..end]);
    assert!(header.contains("comment crs EPSG:25832+5783\n"), "{header}");
    assert!(header.contains(&format!("comment crs_wkt {wkt}\n")), "{header}");
    assert!(header.contains("x east, y north, z up"), "{header}");
}

/// Every fusion mode gives at national-grid coordinates what it gives at
/// the origin, shifted, to 0.1 mm: `icp` and `cps-icp` failed there ("0
/// correspondences within 0.5 m", "the normal equations are singular")
/// while they fused the same survey at the origin.
#[test]
fn every_fusion_mode_fuses_at_national_grid_coordinates_as_at_the_origin() {
    for mode in ["direct", "icp", "cps-icp"] {
        let dir = tempfile::tempdir().expect("tempdir");
        let (local_dir, geo_dir) = (dir.path().join("local"), dir.path().join("geo"));
        std::fs::create_dir_all(&local_dir).expect("local");
        std::fs::create_dir_all(&geo_dir).expect("geo");
        let fusion = format!("[fusion]\nmode = \"{mode}\"\n");
        let local = run_mission(&mission(&local_dir, [0.0; 3], r#"["las"]"#, &fusion), &local_dir.join("run"));
        // (The room's acceptance thresholds are the hall's: whether they
        // pass does not matter here, only that both runs agree.)
        assert!(local.code <= 1, "{mode} at the origin: {}", local.stderr);
        let site = format!("{fusion}[site]\ncrs = \"EPSG:25832\"\n");
        let geo = run_mission(&mission(&geo_dir, OFFSET, r#"["las"]"#, &site), &geo_dir.join("run"));
        assert_eq!(geo.code, local.code, "{mode} at UTM: {}", geo.stderr);
        let (l, g) = (report(&local_dir.join("run")), report(&geo_dir.join("run")));
        let (ls, gs) =
            (l["fusion"]["scans"].as_array().expect("scans"), g["fusion"]["scans"].as_array().expect("scans"));
        assert_eq!(l["fusion"]["mode"], mode);
        assert_eq!(ls.len(), gs.len(), "{mode}");
        for (a, b) in ls.iter().zip(gs) {
            let (ma, mb) = (&a["world_from_body"], &b["world_from_body"]);
            for r in 0..3 {
                for c in 0..3 {
                    let (x, y) = (ma[r][c].as_f64().expect("a"), mb[r][c].as_f64().expect("b"));
                    assert!((x - y).abs() < 1e-6, "{mode}, station {}: rotation [{r}][{c}] {x} vs {y}", a["station"]);
                }
                let (x, y) = (ma[r][3].as_f64().expect("a"), mb[r][3].as_f64().expect("b"));
                assert!((y - OFFSET[r] - x).abs() < 1e-4, "{mode}, station {}: {y} − offset vs {x}", a["station"]);
            }
            // Covariances about the first scan's station: the same at UTM.
            if let (Some(ca), Some(cb)) = (a["covariance"].as_array(), b["covariance"].as_array()) {
                for (ra, rb) in ca.iter().zip(cb) {
                    for (x, y) in ra.as_array().expect("row").iter().zip(rb.as_array().expect("row")) {
                        let (x, y) = (x.as_f64().expect("x"), y.as_f64().expect("y"));
                        assert!((x - y).abs() <= 1e-6 * x.abs().max(1e-12), "{mode}: covariance {x} vs {y}");
                    }
                }
            }
        }
        assert_shifted(
            &format!("{mode} LAS"),
            &las_points(&geo_dir.join("run/cloud.las")),
            &las_points(&local_dir.join("run/cloud.las")),
            1.5e-4,
        );
    }
}
