//! LAS 1.4 R15 and COPC 1.0 conformance of what we write, checked on the
//! bytes against the specifications' tables (not through the writer's
//! crates): a survey of 300,000 points at national-grid coordinates (E
//! 500 000, N 5 500 000) in four scans, written as LAS, LAZ and COPC.
//! Independent readers (LASzip, copc-lib, PROJ, GDAL) read the same files
//! in CI (`.ci/check_readers.py`).

use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use nalgebra::{Isometry3, Point3, Vector3};
use scanner::io::{Crs, Format, PointCloud, ScanInfo, write};

const ORIGIN: [f64; 3] = [500_000.0, 5_500_000.0, 300.0];
const POINTS: usize = 300_000;

/// A hall-sized cloud (40 × 12 × 6 m) at UTM coordinates: points on a
/// pseudo-random walk, so that the octree has several levels.
fn survey() -> PointCloud {
    let mut cloud = PointCloud {
        origin: Vector3::from(ORIGIN),
        crs: Some(Crs::parse("EPSG:25832").expect("UTM 32N")),
        source: Some(Vec::new()),
        intensity: Some(Vec::new()),
        ..PointCloud::default()
    };
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for k in 0..4 {
        let start = cloud.len();
        for _ in 0..POINTS / 4 {
            let p = Point3::new(40.0 * next() + 0.123_45, 12.0 * next() - 0.067_89, 6.0 * next().powi(3) + 0.011);
            cloud.points.push(p.cast::<f32>());
            cloud.source.as_mut().expect("sources").push(k);
            cloud.intensity.as_mut().expect("intensity").push((next() * 4000.0).floor() as f32);
        }
        cloud.scans.push(ScanInfo {
            name: format!("scan{k:03}"),
            points: start..cloud.len(),
            world_from_scan: Isometry3::translation(ORIGIN[0] + 10.0 * f64::from(k), ORIGIN[1], ORIGIN[2]),
            gps_time_s: Some(1.4e9 + 60.0 * f64::from(k)),
        });
    }
    cloud
}

fn written(format: Format, name: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join(name);
    write(&path, &survey(), format).expect("written");
    (dir, path)
}

/// The public header block's fields we check (LAS 1.4 R15, table 3).
struct Header {
    global_encoding: u16,
    version: (u8, u8),
    offset_to_points: u32,
    format: u8,
    record_length: u16,
    legacy_count: u32,
    legacy_by_return: [u32; 5],
    scale: [f64; 3],
    offset: [f64; 3],
    /// max x, min x, max y, min y, max z, min z.
    bounds: [f64; 6],
    count: u64,
}

fn header(path: &Path) -> Header {
    let mut b = [0u8; 375];
    std::fs::File::open(path).expect("open").read_exact(&mut b).expect("375 bytes");
    let u16_at = |at: usize| u16::from_le_bytes([b[at], b[at + 1]]);
    let u32_at = |at: usize| u32::from_le_bytes(b[at..at + 4].try_into().expect("4"));
    let f64_at = |at: usize| f64::from_le_bytes(b[at..at + 8].try_into().expect("8"));
    assert_eq!(&b[0..4], b"LASF");
    Header {
        global_encoding: u16_at(6),
        version: (b[24], b[25]),
        offset_to_points: u32_at(96),
        format: b[104] & 0x3f,
        record_length: u16_at(105),
        legacy_count: u32_at(107),
        legacy_by_return: std::array::from_fn(|k| u32_at(111 + 4 * k)),
        scale: std::array::from_fn(|k| f64_at(131 + 8 * k)),
        offset: std::array::from_fn(|k| f64_at(155 + 8 * k)),
        bounds: std::array::from_fn(|k| f64_at(179 + 8 * k)),
        count: u64::from_le_bytes(b[247..255].try_into().expect("8")),
    }
}

/// The raw X, Y, Z of every record of an uncompressed LAS file.
fn raw_records(path: &Path, h: &Header) -> Vec<[i32; 3]> {
    let bytes = std::fs::read(path).expect("bytes");
    let start = h.offset_to_points as usize;
    let len = usize::from(h.record_length);
    (0..h.count as usize)
        .map(|i| {
            let r = &bytes[start + i * len..start + (i + 1) * len];
            [0, 4, 8].map(|at| i32::from_le_bytes(r[at..at + 4].try_into().expect("4")))
        })
        .collect()
}

/// R15: "for point formats 6–10 the legacy point count and legacy number
/// of points by return fields must be zero"; the extended count holds them.
#[test]
fn las_legacy_point_counts_are_zero_for_format_6() {
    for (format, name) in [(Format::Las, "c.las"), (Format::Laz, "c.laz"), (Format::Copc, "c.copc.laz")] {
        let (_dir, path) = written(format, name);
        let h = header(&path);
        assert_eq!(h.version, (1, 4), "{name}");
        assert_eq!(h.format, 6, "{name}");
        assert_eq!((h.legacy_count, h.legacy_by_return), (0, [0; 5]), "{name}: legacy counts");
        assert_eq!(h.count, POINTS as u64, "{name}: extended count");
        // Global encoding: adjusted standard GPS time (bit 0) and WKT (bit 4,
        // required for formats 6–10); nothing else.
        assert_eq!(h.global_encoding, 0b1_0001, "{name}: global encoding");
    }
}

/// R15: the bounds are "the actual unscaled extents of the LAS point file
/// data": exactly the records' extremes, raw · scale + offset, not rounded
/// outwards (at UTM the float noise of the inverse made them a quantum wider).
#[test]
fn las_header_bounds_are_the_records_extremes() {
    let (_dir, path) = written(Format::Las, "c.las");
    let h = header(&path);
    let raw = raw_records(&path, &h);
    let mut expected = [0.0; 6];
    for k in 0..3 {
        let lo = raw.iter().map(|r| r[k]).min().expect("points");
        let hi = raw.iter().map(|r| r[k]).max().expect("points");
        expected[2 * k] = h.scale[k] * f64::from(hi) + h.offset[k];
        expected[2 * k + 1] = h.scale[k] * f64::from(lo) + h.offset[k];
    }
    assert_eq!(h.bounds, expected, "header bounds against the records' extremes");
    assert!(h.bounds[0] > ORIGIN[0] + 39.0 && h.bounds[1] < ORIGIN[0] + 0.2, "{:?}", h.bounds);
    // LAZ and COPC hold the same records: the same bounds.
    for (format, name) in [(Format::Laz, "c.laz"), (Format::Copc, "c.copc.laz")] {
        let (_dir, other) = written(format, name);
        assert_eq!(header(&other).bounds, expected, "{name}");
    }
}

/// The COPC info VLR (COPC 1.0, first VLR): the octree's cube and the
/// root hierarchy page.
struct CopcInfo {
    center: [f64; 3],
    halfsize: f64,
    root_hier_offset: u64,
    root_hier_size: u64,
}

fn copc_info(path: &Path) -> CopcInfo {
    let bytes = std::fs::read(path).expect("bytes");
    let vlr = 375;
    assert_eq!(&bytes[vlr + 2..vlr + 6], b"copc", "the first VLR is COPC's");
    assert_eq!(u16::from_le_bytes([bytes[vlr + 18], bytes[vlr + 19]]), 1, "record 1: COPC info");
    let info = vlr + 54;
    let f64_at = |at: usize| f64::from_le_bytes(bytes[info + at..info + at + 8].try_into().expect("8"));
    let u64_at = |at: usize| u64::from_le_bytes(bytes[info + at..info + at + 8].try_into().expect("8"));
    CopcInfo {
        center: [f64_at(0), f64_at(8), f64_at(16)],
        halfsize: f64_at(24),
        root_hier_offset: u64_at(40),
        root_hier_size: u64_at(48),
    }
}

/// Hierarchy entries `(key, offset, byte size, point count)` of every page.
fn hierarchy(path: &Path, info: &CopcInfo) -> Vec<([i32; 4], u64, i32, i32)> {
    let bytes = std::fs::read(path).expect("bytes");
    let mut pages = vec![(info.root_hier_offset, info.root_hier_size)];
    let mut entries = Vec::new();
    while let Some((offset, size)) = pages.pop() {
        for e in bytes[offset as usize..(offset + size) as usize].chunks(32) {
            let i32_at = |at: usize| i32::from_le_bytes(e[at..at + 4].try_into().expect("4"));
            let entry = (
                [i32_at(0), i32_at(4), i32_at(8), i32_at(12)],
                u64::from_le_bytes(e[16..24].try_into().expect("8")),
                i32_at(24),
                i32_at(28),
            );
            if entry.3 == -1 {
                pages.push((entry.1, entry.2 as u64));
            } else if entry.3 > 0 {
                entries.push(entry);
            }
        }
    }
    entries.sort_by_key(|e| e.1);
    entries
}

/// A COPC file is a LAZ 1.4 file that any LAZ reader opens sequentially:
/// its chunk table lists exactly the hierarchy's nodes, in file order —
/// copc-writer's sequential writer added an empty (N + 1)-th entry, and
/// LASzip failed at point 0.
#[test]
fn copc_chunk_table_has_one_entry_per_hierarchy_node() {
    let (_dir, path) = written(Format::Copc, "c.copc.laz");
    let info = copc_info(&path);
    let nodes = hierarchy(&path, &info);
    assert!(nodes.len() >= 3, "an octree of several nodes: {}", nodes.len());
    let mut file = std::fs::File::open(&path).expect("open");
    let (vlr, points_at) = {
        let reader = las::Reader::from_path(&path).expect("LAZ header");
        let h = reader.header();
        let vlr = h.vlrs().iter().find(|v| v.user_id == "laszip encoded").expect("LASzip VLR").clone();
        (laz::LazVlr::read_from(vlr.data.as_slice()).expect("LASzip VLR"), u64::from(header(&path).offset_to_points))
    };
    file.seek(SeekFrom::Start(points_at)).expect("seek");
    let table = laz::laszip::ChunkTable::read_from(&mut file, &vlr).expect("chunk table");
    assert_eq!(table.len(), nodes.len(), "chunk table entries against hierarchy nodes");
    let mut at = points_at + 8;
    for (entry, node) in table.as_ref().iter().zip(&nodes) {
        assert!(entry.point_count > 0 && entry.byte_count > 0, "an empty chunk: {entry:?}");
        assert_eq!((at, entry.byte_count, entry.point_count), (node.1, node.2 as u64, node.3 as u64), "{node:?}");
        at += entry.byte_count;
    }
    assert_eq!(table.as_ref().iter().map(|e| e.point_count).sum::<u64>(), POINTS as u64);
}

/// COPC's cube is laid out as PDAL lays it out and copc-lib assumes:
/// anchored at the header's minimum, its side the largest extent. (The
/// centred cube made copc-lib's box queries lose points.)
#[test]
fn copc_cube_is_anchored_at_the_header_minimum() {
    let (_dir, path) = written(Format::Copc, "c.copc.laz");
    let h = header(&path);
    let info = copc_info(&path);
    let min = [h.bounds[1], h.bounds[3], h.bounds[5]];
    let extent = (0..3).map(|k| h.bounds[2 * k] - h.bounds[2 * k + 1]).fold(0.0, f64::max);
    assert!((2.0 * info.halfsize - extent).abs() < 1e-9, "side {} against extent {extent}", 2.0 * info.halfsize);
    for (k, (centre, min)) in info.center.iter().zip(min).enumerate() {
        assert!((centre - info.halfsize - min).abs() < 1e-9, "axis {k}: cube min against header min");
    }
    // Every node's points lie in the node's cube (so that a box query that
    // skips a node skips none of its points).
    let mut reader = las::CopcReader::from_path(&path).expect("COPC");
    let points = reader.query(las::LodSelection::All, las::BoundsSelection::All).expect("points");
    let n = points.points().filter(|p| p.is_ok()).count();
    assert_eq!(n, POINTS);
    let nodes = hierarchy(&path, &info);
    let bytes = std::fs::read(&path).expect("bytes");
    assert!(nodes.iter().all(|n| (n.1 as usize) < bytes.len()));
    let deepest = nodes.iter().map(|n| n.0[0]).max().expect("nodes");
    assert!(deepest >= 1, "the cloud is split below the root");
}

/// Every output is a new file's mode (0644 with the usual umask): COPC,
/// meant to be served over HTTP, was renamed into place from a private
/// temporary file (0600).
#[cfg(unix)]
#[test]
fn copc_is_written_with_a_new_files_permissions() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().expect("tempdir");
    let reference = dir.path().join("reference");
    std::fs::write(&reference, b"").expect("a new file");
    let expected = std::fs::metadata(&reference).expect("metadata").permissions().mode() & 0o777;
    for (format, name) in [(Format::Copc, "c.copc.laz"), (Format::Las, "c.las"), (Format::Laz, "c.laz")] {
        let path = dir.path().join(name);
        write(&path, &survey(), format).expect("written");
        let mode = std::fs::metadata(&path).expect("metadata").permissions().mode() & 0o777;
        assert_eq!(mode, expected, "{name}: mode {mode:o}, a new file's {expected:o}");
    }
    assert_eq!(expected & 0o044, 0o044, "the umask leaves others read access: {expected:o}");
}

/// A world cloud's PLY says the world's axes (east, north, up); a scan in
/// its scanner's frame (no CRS) says the body's.
#[test]
fn ply_comment_names_the_clouds_axes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let comment = |cloud: &PointCloud, name: &str| {
        let path = dir.path().join(name);
        write(&path, cloud, Format::from_path(&path).expect("ply")).expect("PLY");
        let bytes = std::fs::read(&path).expect("bytes");
        let end = bytes.windows(10).position(|w| w == b"end_header").expect("header");
        String::from_utf8_lossy(&bytes[..end]).lines().find(|l| l.starts_with("comment written by")).map(String::from)
    };
    let world = survey();
    assert_eq!(
        comment(&world, "w.ply").as_deref(),
        Some("comment written by cps-survey; metres, x east, y north, z up")
    );
    let scan = PointCloud { points: world.points[..100].to_vec(), ..PointCloud::default() };
    assert_eq!(
        comment(&scan, "s.ply").as_deref(),
        Some("comment written by cps-survey; metres, x forward, y left, z up")
    );
}
