//! Per-point colour and time survive every format that carries them:
//! written, read back, value for value (8-bit formats to their 8 bits),
//! with their time base; written part by part as `match` writes them.

use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scanner::PointCloud;
use scanner::io::{CloudHeader, CloudWriter, Format, PcdData, PlyEncoding, ScanInfo, TimeBase, read, write};

/// A scan of `n` points with intensities, 16-bit colours (`eight_bit`:
/// multiples of 257, exact in 8 bits) and times of `base`.
fn coloured(n: usize, eight_bit: bool, base: TimeBase) -> PointCloud {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let points = (0..n)
        .map(|_| Point3::new(rng.random_range(-20.0..20.0f32), rng.random_range(-8.0..8.0), rng.random_range(0.0..5.0)))
        .collect();
    let color = (0..n)
        .map(|_| {
            std::array::from_fn(|_| if eight_bit { u16::from(rng.random::<u8>()) * 257 } else { rng.random::<u16>() })
        })
        .collect();
    // GPS time in 2026 (1.45e9 s) or a GPS week's seconds, 10 µs apart.
    let t0 = if base == TimeBase::Gps { 1_448_000_000.0 } else { 345_600.0 };
    let time = (0..n).map(|i| t0 + i as f64 * 1e-5 + rng.random_range(0.0..1e-6)).collect();
    PointCloud {
        points,
        intensity: Some((0..n).map(|_| f32::from(rng.random::<u16>() >> 4)).collect()),
        color: Some(color),
        time: Some(time),
        time_base: base,
        ..PointCloud::default()
    }
}

/// Every format with colour and time: 16 bits in LAS, LAZ, COPC and E57,
/// 8 in PLY and PCD.
fn formats() -> [(&'static str, Format); 9] {
    [
        ("a.ply", Format::Ply(PlyEncoding::Ascii)),
        ("b.ply", Format::Ply(PlyEncoding::BinaryLittleEndian)),
        ("c.pcd", Format::Pcd(PcdData::Ascii)),
        ("d.pcd", Format::Pcd(PcdData::Binary)),
        ("e.pcd", Format::Pcd(PcdData::BinaryCompressed)),
        ("f.las", Format::Las),
        ("g.laz", Format::Laz),
        ("h.copc.laz", Format::Copc),
        ("i.e57", Format::E57),
    ]
}

fn eight_bit(format: Format) -> bool {
    matches!(format, Format::Ply(_) | Format::Pcd(_))
}

#[test]
fn colour_and_time_round_trip_through_every_format_with_their_base() {
    let dir = tempfile::tempdir().expect("temp dir");
    for (name, format) in formats() {
        // 16-bit colour where the format holds it, and 8-bit colour (E57
        // then writes 8-bit records) with the other base.
        for (base, eight) in [(TimeBase::Gps, eight_bit(format)), (TimeBase::Relative, true)] {
            let original = coloured(3000, eight, base);
            let path = dir.path().join(name);
            write(&path, &original, format).unwrap_or_else(|e| panic!("{name}: {e}"));
            let back = read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(back.len(), original.len(), "{name}");
            // COPC re-orders the points: pair them by their (unique) times.
            let order: Vec<usize> = if format == Format::Copc {
                let times = original.time.as_ref().expect("times");
                let back_times = back.time.as_ref().unwrap_or_else(|| panic!("{name}: no times read"));
                back_times
                    .iter()
                    .map(|t| {
                        times.iter().position(|u| u == t).unwrap_or_else(|| panic!("{name}: time {t} not written"))
                    })
                    .collect()
            } else {
                (0..original.len()).collect()
            };
            let colours = back.color.as_ref().unwrap_or_else(|| panic!("{name}: no colours read"));
            let times = back.time.as_ref().unwrap_or_else(|| panic!("{name}: no times read"));
            for (k, &i) in order.iter().enumerate() {
                assert_eq!(colours[k], original.color.as_ref().expect("colours")[i], "{name} point {i}");
                assert_eq!(times[k], original.time.as_ref().expect("times")[i], "{name} point {i} ({base:?})");
            }
            assert_eq!(back.time_base, base, "{name}");
        }
    }
}

#[test]
fn sixteen_bit_colour_is_rounded_to_eight_bits_in_ply_and_pcd() {
    let dir = tempfile::tempdir().expect("temp dir");
    let original = coloured(2000, false, TimeBase::Gps);
    for (name, format) in formats().into_iter().filter(|(_, f)| eight_bit(*f)) {
        let path = dir.path().join(name);
        write(&path, &original, format).unwrap_or_else(|e| panic!("{name}: {e}"));
        let back = read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        for (a, b) in original.color.as_ref().expect("colours").iter().zip(back.color.as_ref().expect("colours")) {
            for k in 0..3 {
                // v / 257 rounded, back × 257: within half a step of 257.
                assert!((i32::from(a[k]) - i32::from(b[k])).abs() <= 128, "{name}: {a:?} read as {b:?}");
                assert_eq!(b[k] % 257, 0, "{name}: {b:?} is not an 8-bit value scaled by 257");
            }
        }
    }
}

#[test]
fn las_writes_colour_as_point_format_7_and_states_the_time_base() {
    let dir = tempfile::tempdir().expect("temp dir");
    for (base, standard) in [(TimeBase::Gps, true), (TimeBase::Relative, false)] {
        let path = dir.path().join("c.las");
        write(&path, &coloured(100, false, base), Format::Las).expect("written");
        let bytes = std::fs::read(&path).expect("read");
        // LAS 1.4 R15 table 3: global encoding (u16 at 6), point data
        // record format (u8 at 104) and length (u16 at 105).
        let global = u16::from_le_bytes([bytes[6], bytes[7]]);
        assert_eq!(global & 1 == 1, standard, "{base:?}: the GPS time type bit");
        assert_eq!(bytes[104] & 0x3f, 7);
        assert_eq!(u16::from_le_bytes([bytes[105], bytes[106]]), 36);
    }
    // Without colour: format 6, 30 bytes.
    let path = dir.path().join("plain.las");
    write(&path, &PointCloud { color: None, ..coloured(100, false, TimeBase::Gps) }, Format::Las).expect("written");
    let bytes = std::fs::read(&path).expect("read");
    assert_eq!((bytes[104] & 0x3f, u16::from_le_bytes([bytes[105], bytes[106]])), (6, 30));
}

#[test]
fn e57_scans_keep_their_points_times_after_their_acquisition_start() {
    // A georeferenced cloud of two scans written part by part, as `match`
    // writes its clouds: each data3D in its own frame, its timeStamps
    // after its acquisitionStart.
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("two.e57");
    let origin = Vector3::new(500_000.0, 5_500_000.0, 0.0);
    let mut header = CloudHeader {
        origin,
        points: Some(2000),
        intensity: true,
        color: true,
        time: Some(TimeBase::Gps),
        ..CloudHeader::default()
    };
    header.source = true;
    let mut writer = CloudWriter::create(&path, Format::E57, header).expect("created");
    let mut whole = Vec::new();
    for k in 0..2u16 {
        let mut part = coloured(1000, false, TimeBase::Gps);
        for t in part.time.as_mut().expect("times") {
            *t += f64::from(k) * 60.0;
        }
        part.origin = origin;
        part.source = Some(vec![k; 1000]);
        let pose =
            Isometry3::from_parts(Translation3::new(500_010.0 * f64::from(k), 5_500_000.0, 1.0), Default::default());
        part.scans = vec![ScanInfo {
            name: format!("scan{k}"),
            points: 0..1000,
            world_from_scan: pose,
            gps_time_s: Some(part.time.as_ref().expect("times")[0] - 0.5),
        }];
        writer.push(&part).expect("pushed");
        whole.push(part);
    }
    writer.finish().expect("finished");
    let scans = scanner::io::read_e57_scans(&path).expect("read");
    assert_eq!(scans.len(), 2);
    for (scan, part) in scans.iter().zip(&whole) {
        assert_eq!(scan.time_base, TimeBase::Gps);
        assert_eq!(scan.gps_time_s, part.scans[0].gps_time_s);
        assert_eq!(scan.color, part.color, "{}", scan.name);
        let (a, b) = (scan.time.as_ref().expect("times"), part.time.as_ref().expect("times"));
        for (x, y) in a.iter().zip(b) {
            // timeStamp = t − acquisitionStart, in f64: exact to ~1e-7 s.
            assert!((x - y).abs() < 1e-6, "{}: {x} vs {y}", scan.name);
        }
    }
}

#[test]
fn a_part_without_the_clouds_colours_or_times_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cloud = coloured(10, true, TimeBase::Gps);
    let header = CloudHeader::of(&cloud);
    let mut writer =
        CloudWriter::create(&dir.path().join("x.ply"), Format::Ply(PlyEncoding::Ascii), header).expect("created");
    let e = writer.push(&PointCloud { color: None, ..cloud.clone() }).expect_err("refused").to_string();
    assert!(e.contains("colours false") && e.contains("expected the cloud's"), "{e}");
    let e = writer.push(&PointCloud { time_base: TimeBase::Relative, ..cloud.clone() }).expect_err("refused");
    assert!(e.to_string().contains("Relative"), "{e}");
    let e = writer.push(&PointCloud { time: Some(vec![f64::NAN; 10]), ..cloud }).expect_err("refused");
    assert!(e.to_string().contains("not finite"), "{e}");
}
