//! LAS 1.4 and LAZ through the `las` crate: point format 6, or 7 with
//! colour (each point's scan in `point_source_id`; its own time, else its
//! scan's, as adjusted standard GPS time — or GPS week time for times of an
//! unstated epoch; intensity; return 1 of 1), scale 0.1 mm, offset at the cloud's
//! lower corner (rounded to metres) plus its origin, the CRS as an OGC WKT
//! VLR. Records are encoded in parallel and handed to the crate in batches
//! (LAZ chunks compressed in parallel). COPC is that LAZ re-ordered into an octree by `copc-writer`,
//! streaming through a spill file beside the output.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use las::{Builder, GpsTimeType, PointDataBuilder, Transform, Vector, Vlr, Writer};
use rayon::prelude::*;

use super::{CloudHeader, PointCloud, TimeBase};
use crate::error::{Result, ScannerError};

/// Coordinate resolution of the LAS files we write, metres.
pub const LAS_SCALE_M: f64 = 1e-4;

/// The LAS record id of an OGC WKT coordinate system (user `LASF_Projection`).
pub const WKT_RECORD_ID: u16 = 2112;

/// Adjusted standard GPS time: GPS seconds minus 10⁹ (LAS 1.4).
pub(super) const ADJUSTED_GPS_OFFSET_S: f64 = 1e9;

/// Points encoded and written at a time: about 30 MB of records.
const BATCH_POINTS: usize = 1 << 20;

/// The length of a point format 6 record (LAS 1.4 R15, table 16): X, Y, Z
/// (i32, scaled), intensity (u16), return number | number of returns << 4,
/// flags, classification, user data (u8 each), scan angle (i16), point
/// source id (u16), GPS time (f64), little-endian. The `las` crate checks
/// the length against the format and reads the records back for the
/// header's bounds and counts.
const FORMAT_6_LEN: usize = 30;

/// Format 7 (table 17): format 6 and red, green, blue (u16 each).
const FORMAT_7_LEN: usize = 36;

/// A LAS or LAZ file written part by part: the `las` crate's writer,
/// which counts the points and their bounds and writes the header when
/// finished. It is opened at the first part, whose lower corner (rounded
/// to metres) plus the origin becomes the offset.
pub(super) struct LasStream {
    writer: Option<Writer<Disarmable>>,
    /// Set when the file is given up: the writer's remaining writes (its
    /// `Drop` closes it) go nowhere.
    disarmed: Arc<AtomicBool>,
    /// Encoded records not yet written: LAZ writes them [`BATCH_POINTS`]
    /// at a time, so that it compresses many chunks at once in parallel
    /// however small the parts (about 30 MB more than part by part; LAS
    /// writes each part at once).
    pending: Vec<u8>,
    cloud: CloudHeader,
    compressed: bool,
    path: PathBuf,
    /// The records' raw (scaled integer) extremes so far, per axis: the
    /// header's bounds are written from them exactly.
    raw_bounds: Option<([i32; 3], [i32; 3])>,
    /// A record's length: format 6's, or format 7's with colour.
    record_len: usize,
}

impl std::fmt::Debug for LasStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LasStream").field("path", &self.path).finish_non_exhaustive()
    }
}

impl LasStream {
    /// Creates `path` for a cloud of `cloud`'s kind.
    pub(super) fn create(path: &Path, cloud: &CloudHeader, compressed: bool) -> Result<Self> {
        File::create(path).map_err(|e| ScannerError::io(path, e))?;
        Ok(Self {
            writer: None,
            pending: Vec::new(),
            cloud: cloud.clone(),
            compressed,
            path: path.to_path_buf(),
            raw_bounds: None,
            disarmed: Arc::new(AtomicBool::new(false)),
            record_len: if cloud.color { FORMAT_7_LEN } else { FORMAT_6_LEN },
        })
    }

    /// The writer, opened with the offset at the first part's lower
    /// corner (its times, if any, are adjusted standard GPS time, or GPS
    /// week time when the points' own times have no stated epoch).
    fn writer(&mut self, first: &PointCloud) -> Result<&mut Writer<Disarmable>> {
        if self.writer.is_none() {
            let path = &self.path;
            self.cloud.timed |= first.scans.iter().any(|s| s.gps_time_s.is_some());
            let lo = first.points.iter().fold([f64::INFINITY; 3], |m, p| {
                [m[0].min(f64::from(p.x)), m[1].min(f64::from(p.y)), m[2].min(f64::from(p.z))]
            });
            let corner = lo.map(|v| if v.is_finite() { v.floor() } else { 0.0 });
            let header = header(path, &self.cloud, corner, self.compressed)?;
            if usize::from(header.point_format().len()) != self.record_len {
                return Err(ScannerError::whole_file(
                    path,
                    format!("the header's point format is not {}-byte records", self.record_len),
                ));
            }
            let file = File::create(path).map_err(|e| ScannerError::io(path, e))?;
            let stream = Disarmable { inner: BufWriter::with_capacity(1 << 20, file), disarmed: self.disarmed.clone() };
            let writer = Writer::new(stream, header).map_err(|e| ScannerError::whole_file(path, e))?;
            self.writer = Some(writer);
        }
        self.writer.as_mut().ok_or_else(|| ScannerError::whole_file(&self.path, "the LAS writer is not open"))
    }

    /// Appends `part`'s points (each with its own time, else its scan's).
    pub(super) fn push(&mut self, part: &PointCloud) -> Result<()> {
        let path = self.path.clone();
        let path = &path;
        let len = self.record_len;
        let writer = self.writer(part)?;
        let mut scans: Vec<_> = part.scans.iter().filter(|s| !s.points.is_empty()).collect();
        scans.sort_by_key(|s| s.points.start);
        let gps_time = |i: usize| match (&part.time, part.time_base) {
            (Some(t), TimeBase::Gps) => t[i] - ADJUSTED_GPS_OFFSET_S,
            (Some(t), TimeBase::Relative) => t[i],
            (None, _) => {
                let k = scans.partition_point(|s| s.points.end <= i);
                scans
                    .get(k)
                    .filter(|s| s.points.contains(&i))
                    .and_then(|s| s.gps_time_s)
                    .map_or(0.0, |t| t - ADJUSTED_GPS_OFFSET_S)
            }
        };
        let offset = *writer.header().transforms();
        let n = part.points.len();
        for batch in (0..n).step_by(BATCH_POINTS) {
            let end = n.min(batch + BATCH_POINTS);
            // Encoded in parallel at the end of the pending records.
            let start = self.pending.len();
            if self.compressed && self.pending.capacity() == 0 {
                // A batch and a part: no reallocation before the flush.
                self.pending.reserve_exact(2 * BATCH_POINTS * len);
            }
            self.pending.resize(start + (end - batch) * len, 0);
            self.pending[start..]
                .par_chunks_mut(len)
                .enumerate()
                .try_for_each(|(k, record)| {
                    let i = batch + k;
                    let [x, y, z] = part.coordinates(i);
                    let raw = |v: f64, t: &Transform| {
                        let r = ((v - t.offset) / t.scale).round();
                        (r >= f64::from(i32::MIN) && r <= f64::from(i32::MAX)).then_some(r as i32).ok_or(i)
                    };
                    record[0..4].copy_from_slice(&raw(x, &offset.x)?.to_le_bytes());
                    record[4..8].copy_from_slice(&raw(y, &offset.y)?.to_le_bytes());
                    record[8..12].copy_from_slice(&raw(z, &offset.z)?.to_le_bytes());
                    let intensity = part.intensity.as_ref().map_or(0, |v| v[i].clamp(0.0, 65535.0).round() as u16);
                    record[12..14].copy_from_slice(&intensity.to_le_bytes());
                    record[14] = 1 | (1 << 4); // return 1 of 1
                    // 15..20: flags, classification, user data, scan angle: 0.
                    record[20..22].copy_from_slice(&part.source.as_ref().map_or(0, |s| s[i]).to_le_bytes());
                    record[22..30].copy_from_slice(&gps_time(i).to_le_bytes());
                    if len == FORMAT_7_LEN {
                        let rgb = part.color.as_ref().map_or([0; 3], |c| c[i]);
                        for (k, v) in rgb.iter().enumerate() {
                            record[30 + 2 * k..32 + 2 * k].copy_from_slice(&v.to_le_bytes());
                        }
                    }
                    Ok(())
                })
                .map_err(|i: usize| {
                    ScannerError::whole_file(
                        path,
                        format!(
                            "point {i}: {:?} does not fit the LAS offsets {:?} at 0.1 mm",
                            part.coordinates(i),
                            [offset.x.offset, offset.y.offset, offset.z.offset]
                        ),
                    )
                })?;
            self.raw_bounds = raw_extremes(&self.pending[start..], len, self.raw_bounds);
            if self.pending.len() >= BATCH_POINTS * len {
                self.flush()?;
            }
        }
        // LAS has nothing to gain from waiting.
        if !self.compressed {
            self.flush()?;
        }
        Ok(())
    }

    /// Writes the pending records at once (LAZ compresses their 50,000-point
    /// chunks in parallel).
    fn flush(&mut self) -> Result<()> {
        let path = &self.path;
        let writer =
            self.writer.as_mut().ok_or_else(|| ScannerError::whole_file(path, "the LAS writer is not open"))?;
        if self.pending.is_empty() {
            return Ok(());
        }
        let slab = PointDataBuilder::new().for_header(writer.header());
        let points =
            slab.build_from_bytes(std::mem::take(&mut self.pending)).map_err(|e| ScannerError::whole_file(path, e))?;
        writer.write_points(&points).map_err(|e| ScannerError::whole_file(path, e))
    }

    /// Writes the header's counts and bounds and syncs the file.
    pub(super) fn finish(mut self) -> Result<()> {
        self.writer(&PointCloud::default())?;
        self.flush()?;
        let path = &self.path;
        let Some(mut writer) = self.writer.take() else {
            return Err(ScannerError::whole_file(path, "the LAS writer is not open"));
        };
        let transforms = *writer.header().transforms();
        if let Err(e) = writer.close() {
            // Dropped before this stream: disarmed here.
            self.disarmed.store(true, Ordering::Relaxed);
            return Err(ScannerError::whole_file(path, e));
        }
        let stream = writer.into_inner().map_err(|e| ScannerError::whole_file(path, e))?;
        let mut file = stream.inner.into_inner().map_err(|e| ScannerError::io(path, e.into_error()))?;
        patch_header(&mut file, self.raw_bounds, &transforms).map_err(|e| ScannerError::io(path, e))?;
        file.sync_all().map_err(|e| ScannerError::io(path, e))
    }
}

impl Drop for LasStream {
    /// A file given up (an error, a full disk): the `las` crate's writer
    /// closes itself when dropped and panics if that fails, so its writes
    /// are disarmed first. (The unfinished file is removed by its owner.)
    fn drop(&mut self) {
        self.disarmed.store(true, Ordering::Relaxed);
    }
}

/// The file under the `las` crate's writer: once `disarmed`, every write,
/// flush and seek succeeds without touching it.
#[derive(Debug)]
struct Disarmable {
    inner: BufWriter<File>,
    disarmed: Arc<AtomicBool>,
}

impl Disarmable {
    fn live(&self) -> bool {
        !self.disarmed.load(Ordering::Relaxed)
    }
}

impl std::io::Write for Disarmable {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.live() { self.inner.write(buf) } else { Ok(buf.len()) }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if self.live() { self.inner.flush() } else { Ok(()) }
    }
}

impl std::io::Seek for Disarmable {
    fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
        if self.live() { self.inner.seek(to) } else { Ok(0) }
    }
}

/// Header offsets (LAS 1.4 R15, table 3): the legacy point count and
/// legacy points by return (6 × u32), and max X, min X, … min Z (6 × f64).
const LEGACY_COUNTS_AT: u64 = 107;
const BOUNDS_AT: u64 = 179;

/// What the `las` crate's header gets wrong for LAS 1.4 R15: for point
/// formats 6–10 the legacy counts must be 0 (it fills them when they fit),
/// and the bounds must be the records' own extremes, raw · scale + offset
/// (it rounds them outwards from float noise, up to a quantum outside).
fn patch_header(file: &mut File, raw: Option<([i32; 3], [i32; 3])>, t: &Vector<Transform>) -> std::io::Result<()> {
    use std::io::{Seek as _, SeekFrom, Write as _};
    file.seek(SeekFrom::Start(LEGACY_COUNTS_AT))?;
    file.write_all(&[0u8; 24])?;
    if let Some((lo, hi)) = raw {
        let mut bytes = Vec::with_capacity(48);
        for (k, axis) in [t.x, t.y, t.z].iter().enumerate() {
            for v in [hi[k], lo[k]] {
                bytes.extend_from_slice(&axis.direct(v).to_le_bytes());
            }
        }
        file.seek(SeekFrom::Start(BOUNDS_AT))?;
        file.write_all(&bytes)?;
    }
    Ok(())
}

/// Folds the raw X, Y, Z of `records` (`len` bytes each, X, Y, Z first)
/// into `bounds`.
fn raw_extremes(records: &[u8], len: usize, bounds: Option<([i32; 3], [i32; 3])>) -> Option<([i32; 3], [i32; 3])> {
    records
        .par_chunks(len)
        .fold(
            || bounds,
            |b, r| {
                let v = [0, 4, 8].map(|at| i32::from_le_bytes(r[at..at + 4].try_into().expect("4 bytes")));
                Some(match b {
                    None => (v, v),
                    Some((lo, hi)) => {
                        (std::array::from_fn(|k| lo[k].min(v[k])), std::array::from_fn(|k| hi[k].max(v[k])))
                    }
                })
            },
        )
        .reduce(
            || bounds,
            |a, b| match (a, b) {
                (Some((la, ha)), Some((lb, hb))) => {
                    Some((std::array::from_fn(|k| la[k].min(lb[k])), std::array::from_fn(|k| ha[k].max(hb[k]))))
                }
                (a, None) => a,
                (None, b) => b,
            },
        )
}

/// The LAS 1.4 header of a cloud: point format 6 (7 with colour),
/// compressed or not; the
/// offsets at the cloud's origin plus `corner` (whole metres: the scaled
/// integers stay small, the coordinates exact to the scale).
fn header(path: &Path, cloud: &CloudHeader, corner: [f64; 3], compressed: bool) -> Result<las::Header> {
    let mut builder = Builder::from((1, 4));
    let mut format =
        las::point::Format::new(if cloud.color { 7 } else { 6 }).map_err(|e| ScannerError::whole_file(path, e))?;
    format.is_compressed = compressed;
    builder.point_format = format;
    let o = cloud.origin;
    builder.transforms = Vector {
        x: Transform { scale: LAS_SCALE_M, offset: o.x + corner[0] },
        y: Transform { scale: LAS_SCALE_M, offset: o.y + corner[1] },
        z: Transform { scale: LAS_SCALE_M, offset: o.z + corner[2] },
    };
    builder.generating_software = "cps-survey".into();
    builder.system_identifier = "cps-survey CPS team".into(); // at most 32 bytes
    builder.date = Some(today());
    // Points' own times of an unstated epoch are GPS week time to LAS.
    if cloud.time == Some(TimeBase::Gps) || (cloud.timed && cloud.time.is_none()) {
        builder.gps_time_type = GpsTimeType::Standard;
    }
    if let Some(crs) = &cloud.crs {
        builder.has_wkt_crs = true;
        let mut data = crs.wkt.clone().into_bytes();
        data.push(0); // the specification's null terminator
        builder.vlrs.push(Vlr {
            user_id: "LASF_Projection".into(),
            record_id: WKT_RECORD_ID,
            description: "OGC WKT coordinate system".into(),
            data,
        });
    }
    builder.into_header().map_err(|e| ScannerError::whole_file(path, e))
}

/// Re-orders the LAZ file `laz` into the COPC file `path` (an octree of
/// LAZ chunks) with `copc-writer`, which spills to a temporary file in the
/// same directory rather than holding the points. The COPC file gets the
/// LAZ file's permissions (a new file's, as the umask makes them): the
/// crate renames a private temporary file (0600) into place.
pub(super) fn convert_to_copc(laz: &Path, path: &Path) -> Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let permissions = std::fs::metadata(laz).map_err(|e| ScannerError::io(laz, e))?.permissions();
    copc_writer::convert_las_to_copc_streaming(
        laz,
        path,
        &copc_writer::CopcWriterParams::default(),
        dir,
        &copc_core::NeverCancel,
    )
    .map_err(|e| ScannerError::whole_file(path, format!("COPC: {e}")))?;
    std::fs::set_permissions(path, permissions).map_err(|e| ScannerError::io(path, e))
}

/// Today's date (UTC), the file's creation date.
fn today() -> chrono::NaiveDate {
    let days = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() / 86_400);
    // 719,163 days from 0001-01-01 (day 1 of the common era) to 1970-01-01.
    i32::try_from(days).ok().and_then(|d| chrono::NaiveDate::from_num_days_from_ce_opt(719_163 + d)).unwrap_or_default()
}
