//! A merged survey cloud — three scans with poses and times, at
//! national-grid coordinates in ETRS89 / UTM 32N — written as LAS, LAZ,
//! COPC, E57 and PLY and read back by the format libraries (`las` with its
//! own LAZ and COPC readers, `e57`): the CRS, each point's scan and time,
//! each scan's pose, name and GUID, and every coordinate to 0.1 mm.

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use scanner::io::{Crs, Format, PointCloud, ScanInfo, gps_time_of_unix, write};

const ORIGIN: [f64; 3] = [500_000.0, 5_500_000.0, 300.0];

/// 2023-06-01 08:00 UTC and the two scans after it, GPS seconds.
fn scan_time(k: usize) -> f64 {
    gps_time_of_unix(1_685_606_400.0) + 95.5 * k as f64
}

/// Three scans of 400 points each, taken at three poses, merged relative
/// to the origin.
fn survey() -> PointCloud {
    let mut cloud = PointCloud {
        origin: Vector3::from(ORIGIN),
        crs: Some(Crs::parse("EPSG:25832").expect("UTM 32N")),
        source: Some(Vec::new()),
        intensity: Some(Vec::new()),
        ..PointCloud::default()
    };
    for k in 0..3 {
        let world_from_scan = Isometry3::from_parts(
            Translation3::new(ORIGIN[0] + 12.5 * k as f64, ORIGIN[1] - 3.25 * k as f64, ORIGIN[2] + 0.5),
            UnitQuaternion::from_euler_angles(0.01 * k as f64, -0.02, 0.7 * k as f64 - 1.0),
        );
        let start = cloud.len();
        for i in 0..400 {
            let t = i as f64;
            let local = Point3::new(8.0 * (0.3 * t).sin() + 1e-4 * t, 6.0 * (0.17 * t).cos(), 2.0 * (0.05 * t).sin());
            let world = world_from_scan * local;
            cloud.points.push((world - Vector3::from(ORIGIN)).cast::<f32>());
            cloud.source.as_mut().expect("sources").push(k as u16 + 4);
            cloud.intensity.as_mut().expect("intensity").push((100 * k + i) as f32);
        }
        cloud.scans.push(ScanInfo {
            name: format!("scan{:03}", k + 4),
            points: start..cloud.len(),
            world_from_scan,
            gps_time_s: Some(scan_time(k)),
        });
    }
    cloud
}

fn close(a: [f64; 3], b: [f64; 3], tolerance_m: f64) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= tolerance_m)
}

/// Reads a LAS/LAZ file with the `las` crate and checks it against `cloud`.
fn check_las(path: &std::path::Path, cloud: &PointCloud, compressed: bool) {
    let mut reader = las::Reader::from_path(path).expect("the las crate reads it");
    let header = reader.header().clone();
    assert_eq!(header.version(), las::Version::new(1, 4));
    assert_eq!(header.point_format().to_u8().expect("a format"), 6);
    assert_eq!(header.point_format().is_compressed, compressed);
    assert!(header.has_wkt_crs(), "global encoding's WKT bit");
    assert_eq!(header.gps_time_type(), las::GpsTimeType::Standard);
    let wkt = header.vlrs().iter().find(|v| v.user_id == "LASF_Projection" && v.record_id == 2112).expect("WKT VLR");
    let text = String::from_utf8(wkt.data.clone()).expect("UTF-8");
    assert_eq!(text.trim_end_matches('\0'), cloud.crs.as_ref().expect("crs").wkt);
    let data = reader.read_all().expect("points");
    let points: Vec<las::Point> = data.points().map(|p| p.expect("a point")).collect();
    assert_eq!(points.len(), cloud.len());
    for (i, p) in points.iter().enumerate() {
        let scan = i / 400;
        assert!(close([p.x, p.y, p.z], cloud.coordinates(i), 1e-4), "point {i}: {p:?}");
        assert_eq!(p.point_source_id, scan as u16 + 4);
        let t = p.gps_time.expect("format 6 has a time");
        assert!((t - (scan_time(scan) - 1e9)).abs() < 1e-6, "point {i}: adjusted GPS time {t}");
        assert_eq!((p.return_number, p.number_of_returns), (1, 1));
        assert_eq!(p.intensity, (100 * scan + i % 400) as u16);
    }
}

#[test]
fn las_and_laz_carry_crs_scan_and_time() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = survey();
    let (las_path, laz_path) = (dir.path().join("c.las"), dir.path().join("c.laz"));
    write(&las_path, &cloud, Format::from_path(&las_path).expect("las")).expect("LAS");
    write(&laz_path, &cloud, Format::from_path(&laz_path).expect("laz")).expect("LAZ");
    check_las(&las_path, &cloud, false);
    check_las(&laz_path, &cloud, true);
    // Our own reader takes both (f32, relative to nothing: within 0.1 m here).
    for path in [&las_path, &laz_path] {
        let back = scanner::io::read(path).expect("read back");
        assert_eq!(back.len(), cloud.len());
        assert!(close(back.coordinates(7), cloud.coordinates(7), 1.0), "{:?}", back.coordinates(7));
    }
    let (las_bytes, laz_bytes) = (file_len(&las_path), file_len(&laz_path));
    assert!(laz_bytes * 2 < las_bytes, "LAZ {laz_bytes} B vs LAS {las_bytes} B: expected compression");
}

fn file_len(path: &std::path::Path) -> u64 {
    std::fs::metadata(path).expect("metadata").len()
}

#[test]
fn copc_is_a_laz_octree_with_every_point() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = survey();
    let path = dir.path().join("c.copc.laz");
    assert_eq!(Format::from_path(&path).expect("copc"), Format::Copc);
    write(&path, &cloud, Format::Copc).expect("COPC");
    // Nothing left beside it (the LAZ it was made from, the spill file).
    let names: Vec<_> = std::fs::read_dir(dir.path()).expect("dir").map(|e| e.expect("entry").file_name()).collect();
    assert_eq!(names, vec![std::ffi::OsString::from("c.copc.laz")]);
    // The las crate's own COPC reader: the octree holds every point once.
    let mut reader = las::CopcReader::from_path(&path).expect("the las crate reads COPC");
    let data = reader.query(las::LodSelection::All, las::BoundsSelection::All).expect("points");
    let points: Vec<las::Point> = data.points().map(|p| p.expect("a point")).collect();
    assert_eq!(points.len(), cloud.len());
    let header = reader.header().clone();
    assert!(header.vlrs().iter().any(|v| v.user_id == "copc" && v.record_id == 1), "COPC info VLR");
    let wkt = header.all_vlrs().find(|v| v.user_id == "LASF_Projection" && v.record_id == 2112).expect("WKT VLR");
    assert_eq!(String::from_utf8_lossy(&wkt.data).trim_end_matches('\0'), cloud.crs.as_ref().expect("crs").wkt);
    // Octree order: match each point by (scan, intensity), which is unique.
    let by_key: HashMap<(u16, u16), usize> = (0..cloud.len())
        .map(|i| ((cloud.source.as_ref().expect("s")[i], cloud.intensity.as_ref().expect("i")[i] as u16), i))
        .collect();
    for p in &points {
        let i = by_key[&(p.point_source_id, p.intensity)];
        assert!(close([p.x, p.y, p.z], cloud.coordinates(i), 1e-4), "point {i}: {p:?}");
        assert!((p.gps_time.expect("time") - (scan_time(i / 400) - 1e9)).abs() < 1e-6);
    }
}

#[test]
fn e57_has_one_data3d_per_scan_with_pose_name_time_and_guid() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = survey();
    let path = dir.path().join("c.e57");
    write(&path, &cloud, Format::E57).expect("E57");
    let mut reader = e57::E57Reader::from_file(&path).expect("the e57 crate reads it");
    assert_eq!(reader.coordinate_metadata(), Some(cloud.crs.as_ref().expect("crs").wkt.as_str()));
    let clouds = reader.pointclouds();
    assert_eq!(clouds.len(), 3);
    let mut guids: Vec<String> = clouds.iter().map(|pc| pc.guid.clone().expect("a GUID")).collect();
    guids.push(reader.guid().to_string());
    for (k, (pc, scan)) in clouds.iter().zip(&cloud.scans).enumerate() {
        assert_eq!(pc.name.as_deref(), Some(scan.name.as_str()));
        assert_eq!(pc.records, 400);
        let t = pc.acquisition_start.as_ref().expect("acquisition time").gps_time;
        assert!((t - scan_time(k)).abs() < 1e-6);
        let pose = pc.transform.as_ref().expect("pose");
        let want = scan.world_from_scan.translation.vector;
        assert!(close([pose.translation.x, pose.translation.y, pose.translation.z], want.into(), 1e-9));
        // With the pose applied (in f64), every point at its coordinates.
        let mut points = reader.pointcloud_simple(pc).expect("points");
        points.apply_pose(true);
        for (j, p) in points.enumerate() {
            let p = p.expect("a point");
            let e57::CartesianCoordinate::Valid { x, y, z } = p.cartesian else { panic!("point {j}: invalid") };
            let i = scan.points.start + j;
            assert!(close([x, y, z], cloud.coordinates(i), 1e-4), "scan {k} point {j}: {:?}", [x, y, z]);
        }
    }
    // A second file's GUIDs are all new.
    let again = dir.path().join("d.e57");
    write(&again, &cloud, Format::E57).expect("E57");
    let reader = e57::E57Reader::from_file(&again).expect("reads");
    guids.extend(reader.pointclouds().iter().map(|pc| pc.guid.clone().expect("a GUID")));
    guids.push(reader.guid().to_string());
    let n = guids.len();
    guids.sort();
    guids.dedup();
    assert_eq!(guids.len(), n, "every GUID unique: {guids:?}");
    assert!(guids.iter().all(|g| g.len() == 38 && g.as_bytes()[15] == b'4'), "version-4 GUIDs: {guids:?}");
}

#[test]
fn ply_names_its_crs_in_comments() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = survey();
    let path = dir.path().join("c.ply");
    write(&path, &cloud, Format::from_path(&path).expect("ply")).expect("PLY");
    let bytes = std::fs::read(&path).expect("bytes");
    let end = bytes.windows(10).position(|w| w == b"end_header").expect("header");
    let header = String::from_utf8_lossy(&bytes[..end]);
    assert!(header.contains("comment crs EPSG:25832\n"), "{header}");
    let wkt = cloud.crs.as_ref().expect("crs").wkt.as_str();
    assert!(header.contains(&format!("comment crs_wkt {wkt}\n")), "{header}");
}

#[test]
fn scans_outside_the_cloud_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut cloud = survey();
    cloud.scans[2].points = 800..1300;
    let path = dir.path().join("c.e57");
    let error = write(&path, &cloud, Format::E57).expect_err("a scan beyond the points").to_string();
    assert!(
        error.contains("scan \"scan006\"") && error.contains("800..1300") && error.contains("1200 points"),
        "{error}"
    );
    assert!(!path.exists());
    cloud.scans[2].points = 700..1200;
    let error = write(&path, &cloud, Format::Las).expect_err("two scans sharing points").to_string();
    assert!(error.contains("\"scan005\" (points 400..800) and \"scan006\" (points 700..1200) share points"), "{error}");
    assert!(!path.exists());
}

/// More points than one encoding batch (2^20) and many LAZ chunks: every
/// point read back by the `las` crate where it was, in order, in LAS and
/// in LAZ alike.
#[test]
fn las_and_laz_keep_every_point_across_batches() {
    let dir = tempfile::tempdir().expect("tempdir");
    let n = (1 << 20) + 54_321;
    let points: Vec<Point3<f32>> =
        (0..n).map(|i| Point3::new((i % 1000) as f32 * 0.01, (i / 1000) as f32 * 0.01, (i % 7) as f32)).collect();
    let cloud =
        PointCloud { source: Some((0..n).map(|i| (i / 100_000) as u16).collect()), ..PointCloud::from_points(points) };
    for name in ["big.las", "big.laz"] {
        let path = dir.path().join(name);
        write(&path, &cloud, Format::from_path(&path).expect("format")).expect("written");
        let mut reader = las::Reader::from_path(&path).expect("the las crate reads it");
        assert_eq!(reader.header().number_of_points(), n as u64, "{name}");
        let data = reader.read_all().expect("points");
        let mut i = 0;
        for p in data.points() {
            let p = p.expect("a point");
            assert!(close([p.x, p.y, p.z], cloud.coordinates(i), 1e-4), "{name} point {i}: {p:?}");
            assert_eq!(p.point_source_id, (i / 100_000) as u16, "{name} point {i}");
            i += 1;
        }
        assert_eq!(i, n, "{name}");
    }
}

/// A cloud wider than the 32-bit scaled integers reach (±214 km at 0.1 mm
/// from the offset) is refused, naming the point, not wrapped around.
#[test]
fn las_refuses_coordinates_beyond_its_integers() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = PointCloud::from_points(vec![Point3::new(0.0, 0.0, 0.0), Point3::new(300_000.0, 0.0, 0.0)]);
    let path = dir.path().join("wide.las");
    let e = write(&path, &cloud, Format::Las).expect_err("too wide").to_string();
    assert!(e.contains("wide.las") && e.contains("point 1") && e.contains("does not fit"), "{e}");
}

/// `survey()`'s scans as parts, each with its own points, fields and scan.
fn parts(cloud: &PointCloud) -> Vec<PointCloud> {
    cloud
        .scans
        .iter()
        .map(|s| PointCloud {
            points: cloud.points[s.points.clone()].to_vec(),
            intensity: cloud.intensity.as_ref().map(|v| v[s.points.clone()].to_vec()),
            source: cloud.source.as_ref().map(|v| v[s.points.clone()].to_vec()),
            scans: vec![ScanInfo { points: 0..s.points.len(), ..s.clone() }],
            ..cloud.clone()
        })
        .collect()
}

/// A cloud written a scan at a time is the cloud written whole: the same
/// bytes where a format is one stream, the same points, scans, times and
/// poses where the file carries dates or GUIDs.
#[test]
fn a_cloud_written_scan_by_scan_is_the_cloud_written_whole() {
    use scanner::io::{CloudHeader, CloudWriter, PcdData, PlyEncoding};
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = survey();
    let streamed = |name: &str, format: Format| {
        let path = dir.path().join(format!("s-{name}"));
        let mut writer = CloudWriter::create(&path, format, CloudHeader::of(&cloud)).expect("created");
        for part in parts(&cloud) {
            writer.push(&part).expect("pushed");
        }
        writer.finish().expect("finished");
        path
    };
    for (name, format) in [
        ("c.3d", Format::ThreeDtk),
        ("c.xyz", Format::Xyz),
        ("c.ply", Format::Ply(PlyEncoding::BinaryLittleEndian)),
        ("a.ply", Format::Ply(PlyEncoding::Ascii)),
        ("c.pcd", Format::Pcd(PcdData::Binary)),
        ("a.pcd", Format::Pcd(PcdData::Ascii)),
        ("z.pcd", Format::Pcd(PcdData::BinaryCompressed)),
    ] {
        let whole = dir.path().join(format!("w-{name}"));
        write(&whole, &cloud, format).expect("whole");
        let bytes = std::fs::read(&whole).expect("read");
        assert!(bytes.len() > 1000, "{name}");
        assert_eq!(std::fs::read(streamed(name, format)).expect("read"), bytes, "{name}");
    }
    check_las(&streamed("c.las", Format::Las), &cloud, false);
    check_las(&streamed("c.laz", Format::Laz), &cloud, true);
    let mut reader = las::CopcReader::from_path(streamed("c.copc.laz", Format::Copc)).expect("COPC");
    let data = reader.query(las::LodSelection::All, las::BoundsSelection::All).expect("points");
    assert_eq!(data.len(), cloud.len());
    let reader = e57::E57Reader::from_file(streamed("c.e57", Format::E57)).expect("E57");
    let clouds = reader.pointclouds();
    assert_eq!(clouds.len(), 3);
    for (pc, scan) in clouds.iter().zip(&cloud.scans) {
        assert_eq!((pc.name.as_deref(), pc.records), (Some(scan.name.as_str()), 400));
    }
    // Without the count up front (a run writing scans as they come), PLY
    // and PCD get it, zero-padded, when finished: readers take it.
    for (name, format) in [
        ("u.ply", Format::Ply(PlyEncoding::BinaryLittleEndian)),
        ("ua.ply", Format::Ply(PlyEncoding::Ascii)),
        ("u.pcd", Format::Pcd(PcdData::Binary)),
        ("ua.pcd", Format::Pcd(PcdData::Ascii)),
        ("uz.pcd", Format::Pcd(PcdData::BinaryCompressed)),
    ] {
        let path = dir.path().join(name);
        let header = CloudHeader { points: None, ..CloudHeader::of(&cloud) };
        let mut writer = CloudWriter::create(&path, format, header).expect("created");
        for part in parts(&cloud) {
            writer.push(&part).expect("pushed");
        }
        writer.finish().expect("finished");
        let text = String::from_utf8_lossy(&std::fs::read(&path).expect("read")).into_owned();
        let stated = ["element vertex 00000000000000001200", "POINTS 00000000000000001200"];
        assert!(name == "uz.pcd" || stated.iter().any(|s| text.contains(s)), "{name}: the count, zero-padded");
        // Our reader takes it (in f32: within a metre at these coordinates)…
        let back = scanner::io::read(&path).expect("our reader takes it");
        assert_eq!(back.len(), cloud.len(), "{name}");
        for i in [0, 399, 400, 1199] {
            assert!(close(back.coordinates(i), cloud.coordinates(i), 1.0), "{name} point {i}");
        }
        // … and after the header the bytes are the whole cloud's.
        let whole = dir.path().join(format!("w-{name}"));
        write(&whole, &cloud, format).expect("whole");
        let (a, b) = (std::fs::read(&path).expect("read"), std::fs::read(&whole).expect("read"));
        let end = |bytes: &[u8]| {
            let marker: &[u8] = if name.ends_with(".ply") { b"end_header\n" } else { b"\nDATA " };
            let at = bytes.windows(marker.len()).position(|w| w == marker).expect("a header") + marker.len();
            at + bytes[at..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(0, |k| if name.ends_with(".pcd") { k + 1 } else { 0 })
        };
        assert_eq!(a[end(&a)..], b[end(&b)..], "{name}: the points");
    }
    // Only the finished files are there.
    let mut names: Vec<String> = std::fs::read_dir(dir.path())
        .expect("dir")
        .map(|e| e.expect("entry").file_name().into_string().expect("utf-8"))
        .collect();
    names.retain(|n| n.ends_with(".partial") || n.contains(".laz."));
    assert!(names.is_empty(), "left behind: {names:?}");
}

/// A part that is not what the header said, a count that does not add up,
/// and a writer dropped unfinished: refused naming the file, nothing left.
#[test]
fn a_streamed_cloud_refuses_parts_it_was_not_promised() {
    use scanner::io::{CloudHeader, CloudWriter};
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud = survey();
    let parts = parts(&cloud);
    let path = dir.path().join("c.las");
    let header = CloudHeader::of(&cloud);

    let mut w = CloudWriter::create(&path, Format::Las, header.clone()).expect("created");
    let moved = PointCloud { origin: Vector3::zeros(), ..parts[0].clone() };
    let e = w.push(&moved).expect_err("another origin").to_string();
    assert!(e.contains("c.las") && e.contains("expected the cloud's origin"), "{e}");
    let bare = PointCloud { intensity: None, ..parts[0].clone() };
    let e = w.push(&bare).expect_err("no intensity").to_string();
    assert!(e.contains("without intensities"), "{e}");
    w.push(&parts[0]).expect("a good part");
    let e = w.finish().expect_err("two scans missing").to_string();
    assert!(e.contains("400 points written: expected 1200"), "{e}");
    assert!(!path.exists());

    let mut w =
        CloudWriter::create(&path, Format::Las, CloudHeader { points: Some(500), ..header.clone() }).expect("created");
    w.push(&parts[0]).expect("400 of 500");
    let e = w.push(&parts[1]).expect_err("800 > 500").to_string();
    assert!(e.contains("800 points after this part: expected 500"), "{e}");
    drop(w);
    // COPC writes a LAZ beside it first: a short count leaves neither.
    let copc = dir.path().join("c.copc.laz");
    let mut w = CloudWriter::create(&copc, Format::Copc, header.clone()).expect("created");
    w.push(&parts[0]).expect("a good part");
    let e = w.finish().expect_err("two scans missing").to_string();
    assert!(e.contains("400 points written: expected 1200"), "{e}");
    let left: Vec<_> = std::fs::read_dir(dir.path()).expect("dir").collect();
    assert!(left.is_empty(), "an unfinished writer leaves nothing: {left:?}");
}
