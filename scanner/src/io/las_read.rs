//! LAS 1.4 and LAZ (and COPC, a LAZ) read through the `las` crate, every
//! claim of the header — the point count, the extended VLRs, LASzip's
//! items and chunk table — checked against the file before the crate
//! sizes anything by it.

use std::path::Path;

use las::{GpsTimeType, Reader};
use nalgebra::Point3;

use super::las::ADJUSTED_GPS_OFFSET_S;
use super::{PointCloud, TimeBase};
use crate::error::{Location, Result, ScannerError};

/// Points read per batch (the header's count is a claim, never a buffer
/// size).
const BATCH: u64 = 1 << 16;

/// The point count and the extended VLRs of a LAS header are claims: each
/// must fit in the file before the `las` crate sizes anything by it (found
/// by the `scan_file` fuzz target: a 400-byte file asked for 5.7 EB through
/// an extended VLR's length; 2^63 points overflow the crate's own
/// arithmetic once LAZ support is compiled in).
fn check_claims(path: &Path) -> Result<()> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    let mut file = std::fs::File::open(path).map_err(|e| ScannerError::io(path, e))?;
    let len = file.metadata().map_err(|e| ScannerError::io(path, e))?.len();
    let mut head = [0u8; 255];
    if len < 227 || file.read_exact(&mut head[..227]).is_err() {
        return Ok(()); // too short for a header: the crate says what is wrong
    }
    let record = u64::from(u16::from_le_bytes([head[105], head[106]]));
    let legacy = u64::from(u32::from_le_bytes(head[107..111].try_into().expect("4 bytes")));
    let extended = if len >= 255 && file.read_exact(&mut head[227..255]).is_ok() && (head[24], head[25]) >= (1, 4) {
        u64::from_le_bytes(head[247..255].try_into().expect("8 bytes"))
    } else {
        0
    };
    let count = legacy.max(extended);
    // LAZ (the format's compression bits) holds fewer bytes than it
    // claims points of: only the arithmetic must not overflow.
    let compressed = head[104] & 0xc0 != 0;
    if count.checked_mul(record).is_none_or(|bytes| bytes > len && !compressed) {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!("the header says {count} points of {record} bytes; the file has {len} bytes in all"),
        ));
    }
    if compressed {
        check_laszip_items(path, &mut file, &head, len, (record, count))?;
    }
    if len < 255 {
        return Ok(());
    }
    let (major, minor) = (head[24], head[25]);
    if (major, minor) < (1, 4) {
        return Ok(());
    }
    let mut at = u64::from_le_bytes(head[235..243].try_into().expect("8 bytes"));
    let count = u32::from_le_bytes(head[243..247].try_into().expect("4 bytes"));
    if at == 0 || count == 0 {
        return Ok(());
    }
    let bad = |at: u64, message: String| ScannerError::file(path, Location::Byte(at), message);
    for k in 0..count {
        let mut record = [0u8; 60];
        let fits = at.checked_add(60).is_some_and(|end| end <= len);
        if !fits || file.seek(SeekFrom::Start(at)).is_err() || file.read_exact(&mut record).is_err() {
            return Err(bad(at, format!("extended VLR {k} of {count} starts beyond the file's {len} bytes")));
        }
        let length = u64::from_le_bytes(record[20..28].try_into().expect("8 bytes"));
        match (at + 60).checked_add(length) {
            Some(end) if end <= len => at = end,
            _ => {
                return Err(bad(
                    at,
                    format!(
                        "extended VLR {k} of {count} claims {length} bytes; the file has {} after its header",
                        len - (at + 60)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// A LAZ file's LASzip VLR (user `laszip encoded`, record 22204) must
/// describe items whose sizes add up to the header's point record length:
/// the `laz` crate's parallel decoder asserts it and panics otherwise
/// (found by mutating a valid LAZ in `hostile.rs`). `(record, points)`:
/// the header's record length and point count.
fn check_laszip_items(
    path: &Path,
    file: &mut std::fs::File,
    head: &[u8; 255],
    len: u64,
    (record, points): (u64, u64),
) -> Result<()> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    let header_size = u64::from(u16::from_le_bytes([head[94], head[95]]));
    let vlrs = u32::from_le_bytes(head[100..104].try_into().expect("4 bytes"));
    let bad = |at: u64, message: String| ScannerError::file(path, Location::Byte(at), message);
    let mut at = header_size;
    for _ in 0..vlrs.min(1 << 16) {
        let mut vlr = [0u8; 54];
        if at + 54 > len || file.seek(SeekFrom::Start(at)).is_err() || file.read_exact(&mut vlr).is_err() {
            return Ok(()); // the crate says what is wrong with the VLRs
        }
        let user = &vlr[2..18];
        let id = u16::from_le_bytes([vlr[18], vlr[19]]);
        let length = u64::from(u16::from_le_bytes([vlr[20], vlr[21]]));
        if user.starts_with(b"laszip encoded") && id == 22204 {
            let mut data = vec![0u8; length as usize];
            if at + 54 + length > len || file.read_exact(&mut data).is_err() || data.len() < 34 {
                return Err(bad(at, format!("the LASzip VLR claims {length} bytes: expected at least 34 in the file")));
            }
            let items = usize::from(u16::from_le_bytes([data[32], data[33]]));
            if data.len() < 34 + 6 * items {
                return Err(bad(at, format!("the LASzip VLR lists {items} items in {length} bytes")));
            }
            let sizes: u64 =
                (0..items).map(|k| u64::from(u16::from_le_bytes([data[36 + 6 * k], data[37 + 6 * k]]))).sum();
            if sizes != record {
                return Err(bad(
                    at,
                    format!(
                        "the LASzip VLR's items are {sizes} bytes a point; the header's point records are {record}: \
                         expected the same (a corrupt LAZ header)"
                    ),
                ));
            }
            return check_chunk_table(path, file, head, len, points);
        }
        at += 54 + length;
    }
    Ok(())
}

/// The LAZ chunk table's chunk count is a claim the `laz` crate sizes a
/// buffer by (a mutated count asked for 68 GB and aborted the process):
/// each chunk holds at least one point and one byte.
fn check_chunk_table(path: &Path, file: &mut std::fs::File, head: &[u8; 255], len: u64, points: u64) -> Result<()> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    let points_at = u64::from(u32::from_le_bytes(head[96..100].try_into().expect("4 bytes")));
    let mut word = [0u8; 8];
    if points_at + 8 > len || file.seek(SeekFrom::Start(points_at)).is_err() || file.read_exact(&mut word).is_err() {
        return Ok(());
    }
    let table_at = i64::from_le_bytes(word);
    // -1: written without seeking back (the offset is then at the end).
    let Ok(table_at) = u64::try_from(table_at) else { return Ok(()) };
    let mut table = [0u8; 8];
    if table_at.checked_add(8).is_none_or(|end| end > len)
        || file.seek(SeekFrom::Start(table_at)).is_err()
        || file.read_exact(&mut table).is_err()
    {
        return Err(ScannerError::file(
            path,
            Location::Byte(points_at),
            format!("the LAZ chunk table is said to start at byte {table_at}; the file has {len} bytes"),
        ));
    }
    let chunks = u64::from(u32::from_le_bytes(table[4..8].try_into().expect("4 bytes")));
    if chunks > len || chunks > points + 1 {
        return Err(ScannerError::file(
            path,
            Location::Byte(table_at),
            format!(
                "the LAZ chunk table claims {chunks} chunks for {points} points in {len} bytes: expected at most one a point"
            ),
        ));
    }
    Ok(())
}

pub(super) fn read(path: &Path) -> Result<PointCloud> {
    check_claims(path)?;
    // The `laz` crate's decoder indexes its tables with what it decodes and
    // panics on corrupt compressed data (index out of bounds in
    // `decoders.rs`, found by mutating a valid LAZ in `hostile.rs`): a
    // panic there is this file's error, not the program's.
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read_checked(path))) {
        Ok(result) => result,
        Err(panic) => {
            let why = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("a panic");
            Err(ScannerError::file(
                path,
                Location::File,
                format!("the LAZ decoder failed on its compressed points ({why}): expected an uncorrupted file"),
            ))
        }
    }
}

/// [`read`] after the header's claims were checked.
fn read_checked(path: &Path) -> Result<PointCloud> {
    let mut reader = Reader::from_path(path).map_err(|e| ScannerError::whole_file(path, e))?;
    let header = reader.header();
    // (Checked against the file's length by `check_claims`.)
    let count = header.number_of_points();
    let t = header.transforms();
    for (axis, tr) in [("x", t.x), ("y", t.y), ("z", t.z)] {
        if !(tr.scale.is_finite() && tr.scale != 0.0 && tr.offset.is_finite()) {
            return Err(ScannerError::file(
                path,
                Location::File,
                format!(
                    "{axis} scale {} and offset {}: expected a finite, non-zero scale and a finite offset",
                    tr.scale, tr.offset
                ),
            ));
        }
    }
    let mut cloud = PointCloud::default();
    let mut intensity = Vec::new();
    let format = *header.point_format();
    let standard_time = header.gps_time_type() == GpsTimeType::Standard;
    let mut color = format.has_color.then(Vec::new);
    let mut time = format.has_gps_time.then(Vec::new);
    let mut data = las::PointDataBuilder::new().for_header(reader.header()).build();
    let mut read = 0u64;
    while read < count {
        let n =
            reader.fill_points(BATCH.min(count - read), &mut data).map_err(|e| ScannerError::whole_file(path, e))?;
        if n == 0 {
            return Err(ScannerError::file(
                path,
                Location::File,
                format!("truncated: {read} points of the {count} the header says"),
            ));
        }
        for (i, p) in data.points().enumerate() {
            let p = p.map_err(|e| ScannerError::whole_file(path, format!("point {}: {e}", read + i as u64)))?;
            let point = Point3::new(p.x as f32, p.y as f32, p.z as f32);
            if !point.iter().all(|v| v.is_finite()) {
                return Err(ScannerError::file(
                    path,
                    Location::File,
                    format!(
                        "point {}: ({}, {}, {}) m overflows a 32-bit float: expected coordinates within ±{:e} \
                         (the header's scales and offsets make them)",
                        read + i as u64,
                        p.x,
                        p.y,
                        p.z,
                        f32::MAX
                    ),
                ));
            }
            cloud.points.push(point);
            intensity.push(f32::from(p.intensity));
            if let (Some(all), Some(c)) = (color.as_mut(), p.color) {
                all.push([c.red, c.green, c.blue]);
            }
            if let (Some(all), Some(t)) = (time.as_mut(), p.gps_time) {
                all.push(if standard_time { t + ADJUSTED_GPS_OFFSET_S } else { t });
            }
        }
        read += n;
    }
    cloud.intensity = Some(intensity);
    cloud.color = color.filter(|c| c.len() == cloud.points.len());
    // A file whose times are all zero (a writer's "none") carries none.
    let zero = if standard_time { ADJUSTED_GPS_OFFSET_S } else { 0.0 };
    cloud.time = time.filter(|t| t.len() == cloud.points.len() && t.iter().any(|&v| v != zero));
    if cloud.time.is_some() && !standard_time {
        cloud.time_base = TimeBase::Relative;
    }
    Ok(cloud)
}
