//! LAS 1.4 through the `las` crate: point format 0 with intensity, scale
//! 0.1 mm, offset at the cloud's lower corner (rounded to metres).

use std::path::Path;

use las::{Builder, Point, Reader, Transform, Vector, Writer};
use nalgebra::Point3;

use super::PointCloud;
use crate::error::{Location, Result, ScannerError};

/// Coordinate resolution of the LAS files we write, metres.
pub const LAS_SCALE_M: f64 = 1e-4;

/// Points read per batch (the header's count is a claim, never a buffer
/// size).
const BATCH: u64 = 1 << 16;

/// The extended VLRs of a LAS 1.4 header are claims too: each one's 64-bit
/// length must lie within the file before the `las` crate sizes a buffer by
/// it (found by the `scan_file` fuzz target: a 400-byte file asked for
/// 5.7 EB).
fn check_evlrs(path: &Path) -> Result<()> {
    use std::io::{Read as _, Seek as _, SeekFrom};
    let mut file = std::fs::File::open(path).map_err(|e| ScannerError::io(path, e))?;
    let len = file.metadata().map_err(|e| ScannerError::io(path, e))?.len();
    let mut head = [0u8; 247];
    if len < head.len() as u64 || file.read_exact(&mut head).is_err() {
        return Ok(()); // too short for EVLRs: the crate says what is wrong
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

pub(super) fn read(path: &Path) -> Result<PointCloud> {
    check_evlrs(path)?;
    let mut reader = Reader::from_path(path).map_err(|e| ScannerError::whole_file(path, e))?;
    let header = reader.header();
    let count = header.number_of_points();
    let record = u64::from(header.point_format().len());
    let len = std::fs::metadata(path).map_err(|e| ScannerError::io(path, e))?.len();
    if count.checked_mul(record).is_none_or(|bytes| bytes > len) {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!("the header says {count} points of {record} bytes; the file has {len} bytes in all"),
        ));
    }
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
        }
        read += n;
    }
    cloud.intensity = Some(intensity);
    Ok(cloud)
}

pub(super) fn write(path: &Path, cloud: &PointCloud) -> Result<()> {
    let mut builder = Builder::from((1, 4));
    let lo = cloud.points.iter().fold([f64::INFINITY; 3], |m, p| {
        [m[0].min(f64::from(p.x)), m[1].min(f64::from(p.y)), m[2].min(f64::from(p.z))]
    });
    // The offsets carry the origin: the scaled integers stay small and the
    // coordinates exact to the scale.
    let o = [cloud.origin.x, cloud.origin.y, cloud.origin.z];
    let offset = [0, 1, 2].map(|k| o[k] + if lo[k].is_finite() { lo[k].floor() } else { 0.0 });
    builder.transforms = Vector {
        x: Transform { scale: LAS_SCALE_M, offset: offset[0] },
        y: Transform { scale: LAS_SCALE_M, offset: offset[1] },
        z: Transform { scale: LAS_SCALE_M, offset: offset[2] },
    };
    builder.generating_software = "cps-survey".into();
    builder.system_identifier = "cps-survey CPS team".into(); // at most 32 bytes
    builder.date = Some(today());
    let header = builder.into_header().map_err(|e| ScannerError::whole_file(path, e))?;
    let mut writer = Writer::from_path(path, header).map_err(|e| ScannerError::whole_file(path, e))?;
    for i in 0..cloud.points.len() {
        let intensity = cloud.intensity.as_ref().map_or(0, |v| v[i].clamp(0.0, 65535.0).round() as u16);
        let [x, y, z] = cloud.coordinates(i);
        let point_source_id = cloud.source.as_ref().map_or(0, |s| s[i]);
        let point =
            Point { x, y, z, intensity, point_source_id, return_number: 1, number_of_returns: 1, ..Default::default() };
        writer.write_point(point).map_err(|e| ScannerError::whole_file(path, format!("point {i}: {e}")))?;
    }
    writer.close().map_err(|e| ScannerError::whole_file(path, e))
}

/// Today's date (UTC), the file's creation date.
fn today() -> chrono::NaiveDate {
    let days = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() / 86_400);
    // 719,163 days from 0001-01-01 (day 1 of the common era) to 1970-01-01.
    i32::try_from(days).ok().and_then(|d| chrono::NaiveDate::from_num_days_from_ce_opt(719_163 + d)).unwrap_or_default()
}
