//! Scan files. Every reader returns a [`PointCloud`] in our frame and
//! units (metres, x forward, y left, z up); every error names the file and
//! the line or byte offset. Writers write to a temporary file and rename it,
//! so a file that exists is complete.
//!
//! | format | read | write | notes |
//! |---|---|---|---|
//! | 3DTK `.3d` + `.pose` | ✓ | ✓ | cm, left-handed; (x, y, z)_ours = (z, −x, y)_3dtk / 100 |
//! | PLY | ✓ ascii, binary LE/BE | ✓ ascii, binary LE | optional intensity, colour (8-bit), time |
//! | XYZ text | ✓ | ✓ | `x y z [intensity]` per line |
//! | PCD | ✓ ascii, binary, binary_compressed | ✓ all three | F4/F8/U/I fields; intensity, `rgb`, time |
//! | LAS 1.4 | ✓ | ✓ | point format 6 (7 with colour), 0.1 mm scale, WKT CRS, each point's scan and time |
//! | LAZ | ✓ | ✓ | LAS compressed (LASzip) |
//! | COPC `.copc.laz` | ✓ (as LAZ) | ✓ | LAZ chunks in an octree, streamed by `copc-writer` |
//! | E57 | ✓ | ✓ | one `data3D` per scan with its pose, name and time; intensity, colour, `timeStamp`; CRS in `coordinateMetadata` |
//!
//! A cloud can also be written part by part, a scan at a time
//! ([`CloudWriter`]): one part in memory instead of the whole.
//!
//! A georeferenced cloud (non-zero [`PointCloud::origin`]) is written in
//! 64-bit coordinates; its [`Crs`] goes into LAS (WKT VLR), E57
//! (`coordinateMetadata`) and PLY (comments).

mod crs;
mod e57;
mod las;
mod las_read;
mod pcd;
mod ply;
mod stream;
mod text;

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use std::ops::Range;

use nalgebra::{Isometry3, Point3, Vector3};

pub use crs::{Crs, is_bidi_control};
pub use e57::{E57Scan, read_e57_crs, read_e57_scans};
pub use pcd::{PcdData, viewpoint as pcd_viewpoint};
pub use ply::PlyEncoding;
pub use stream::CloudWriter;
pub use text::{
    from_3dtk_axes, read_3dtk_frames, read_3dtk_pose, read_matrix4, to_3dtk_axes, write_3dtk_frames, write_3dtk_pose,
};

use crate::error::{Location, Result, ScannerError};

/// A point cloud: points (metres, f32) and optional per-point intensity,
/// relative to an `origin` (f64; zero unless georeferenced). A point's
/// coordinates are `origin + p`: f32 holds a point to a few micrometres
/// within a kilometre of the origin, where national-grid coordinates
/// (E 500 000, N 5 500 000) would be quantised to 0.5 m.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    /// Points, relative to `origin`.
    pub points: Vec<Point3<f32>>,
    /// Intensity per point (file units), if the file has it.
    pub intensity: Option<Vec<f32>>,
    /// What the points are relative to (the readers give zero; writers
    /// add it in f64).
    pub origin: Vector3<f64>,
    /// The scan each point came from (its station's index), if known:
    /// LAS `point_source_id`.
    pub source: Option<Vec<u16>>,
    /// The coordinate reference system of `origin + p`, if known.
    pub crs: Option<Crs>,
    /// The scans the points came from, each a run of points, when known
    /// (E57 writes one `data3D` each; LAS takes each point's time from it
    /// when the points have none of their own).
    pub scans: Vec<ScanInfo>,
    /// Colour per point, 16 bits a channel (red, green, blue) as LAS holds
    /// it: an 8-bit source's values are scaled by 257 (255 → 65,535), and
    /// 8-bit formats are written with the value / 257, rounded.
    pub color: Option<Vec<[u16; 3]>>,
    /// Acquisition time per point, seconds, counted as `time_base` says.
    pub time: Option<Vec<f64>>,
    /// What `time` counts from (the default when there are no times).
    pub time_base: TimeBase,
}

/// What a cloud's per-point times count from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum TimeBase {
    /// GPS time: seconds since 1980-01-06 00:00 UTC, without leap seconds
    /// (LAS's adjusted standard GPS time + 10⁹; an E57 `timeStamp` plus its
    /// scan's `acquisitionStart`).
    #[default]
    Gps,
    /// Seconds from an epoch the file does not state: LAS's GPS week time,
    /// an E57 `timeStamp` of a scan without `acquisitionStart`, a PLY or
    /// PCD time field without our GPS comment. Written back as it was read
    /// (LAS as GPS week time).
    Relative,
}

impl TimeBase {
    /// The comment PLY and PCD headers carry for times of this base.
    pub(crate) fn comment(self) -> &'static str {
        match self {
            TimeBase::Gps => "time: GPS seconds since 1980-01-06 00:00 UTC",
            TimeBase::Relative => "time: seconds from an unstated epoch",
        }
    }

    /// The base a PLY or PCD header's comments state (relative unless one
    /// says GPS).
    pub(crate) fn from_comments<'a>(comments: impl IntoIterator<Item = &'a str>) -> Self {
        let gps = TimeBase::Gps.comment();
        if comments.into_iter().any(|c| c.trim().trim_start_matches('#').trim() == gps) {
            TimeBase::Gps
        } else {
            TimeBase::Relative
        }
    }
}

/// 8-bit colour to our 16 bits (× 257: 255 → 65,535).
pub(crate) fn color_from_8bit(v: u8) -> u16 {
    u16::from(v) * 257
}

/// Our 16-bit colour to 8 bits (÷ 257, rounded).
pub(crate) fn color_to_8bit(v: u16) -> u8 {
    ((u32::from(v) + 128) / 257) as u8
}

/// What a cloud written part by part ([`CloudWriter`]) is, known before
/// its points: every part has this origin, CRS and fields, and the parts
/// hold `points` points together.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CloudHeader {
    /// The parts' [`PointCloud::origin`].
    pub origin: Vector3<f64>,
    /// Their CRS.
    pub crs: Option<Crs>,
    /// Points in all parts together, when known before they are (PLY and
    /// PCD headers state it first: without it they hold a 20-digit
    /// placeholder, overwritten with the count, zero-padded, when the file
    /// is finished).
    pub points: Option<usize>,
    /// Whether the parts have intensities.
    pub intensity: bool,
    /// Whether the parts have their points' scans (`source`).
    pub source: bool,
    /// Whether the parts' scans carry their times (LAS then says its
    /// times are adjusted standard GPS time).
    pub timed: bool,
    /// Whether the parts have colours.
    pub color: bool,
    /// Whether the parts have per-point times, and their base.
    pub time: Option<TimeBase>,
}

impl CloudHeader {
    /// The header of `cloud` written whole.
    pub fn of(cloud: &PointCloud) -> Self {
        Self {
            origin: cloud.origin,
            crs: cloud.crs.clone(),
            points: Some(cloud.len()),
            intensity: cloud.intensity.is_some(),
            source: cloud.source.is_some(),
            timed: cloud.scans.iter().any(|s| s.gps_time_s.is_some()),
            color: cloud.color.is_some(),
            time: cloud.time.as_ref().map(|_| cloud.time_base),
        }
    }

    /// Whether the coordinates are written in 64 bits (a non-zero origin).
    pub fn georeferenced(&self) -> bool {
        self.origin != Vector3::zeros()
    }
}

/// One scan of a merged cloud.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanInfo {
    /// Its name (the scan file's stem, e.g. `scan003`).
    pub name: String,
    /// Its points in the cloud.
    pub points: Range<usize>,
    /// Where it was taken: `world_from_scan` in the CRS's coordinates
    /// (absolute, not relative to the cloud's origin).
    pub world_from_scan: Isometry3<f64>,
    /// When it was taken: GPS seconds since 1980-01-06 00:00 UTC, if known.
    pub gps_time_s: Option<f64>,
}

/// GPS time (seconds since 1980-01-06 00:00 UTC, without leap seconds) of
/// a UNIX time: 315,964,800 s between the epochs, and the 18 leap seconds
/// UTC has inserted since (none announced after 2016-12-31).
pub fn gps_time_of_unix(unix_s: f64) -> f64 {
    unix_s - 315_964_800.0 + 18.0
}

impl PointCloud {
    /// A cloud of points without intensity, at the zero origin.
    pub fn from_points(points: Vec<Point3<f32>>) -> Self {
        Self { points, ..Self::default() }
    }

    /// Whether the points are relative to a non-zero origin (the writers
    /// then write 64-bit coordinates).
    pub fn georeferenced(&self) -> bool {
        self.origin != Vector3::zeros()
    }

    /// Point `i`'s coordinates, `origin + p`, in f64.
    pub fn coordinates(&self, i: usize) -> [f64; 3] {
        let p = &self.points[i];
        [self.origin.x + f64::from(p.x), self.origin.y + f64::from(p.y), self.origin.z + f64::from(p.z)]
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// A scan file format (with its encoding, for writing).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// 3DTK "uos" `.3d` (points only; the pose is a separate `.pose`).
    ThreeDtk,
    /// PLY.
    Ply(PlyEncoding),
    /// XYZ text.
    Xyz,
    /// PCD.
    Pcd(PcdData),
    /// LAS 1.4.
    Las,
    /// LAZ: LAS 1.4 compressed.
    Laz,
    /// COPC: LAZ 1.4 in octree-ordered chunks (`.copc.laz`).
    Copc,
    /// E57.
    E57,
}

impl Format {
    /// The format for a file name's extension (`.3d`, `.ply`, `.xyz`/`.txt`,
    /// `.pcd`, `.las`, `.laz`, `.copc.laz`, `.e57`); writing uses binary PLY
    /// and binary_compressed PCD.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        let name = path.file_name().and_then(|n| n.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
        if name.ends_with(".copc.laz") {
            return Ok(Format::Copc);
        }
        Ok(match ext.as_deref() {
            Some("3d") => Format::ThreeDtk,
            Some("ply") => Format::Ply(PlyEncoding::BinaryLittleEndian),
            Some("xyz" | "txt") => Format::Xyz,
            Some("pcd") => Format::Pcd(PcdData::BinaryCompressed),
            Some("las") => Format::Las,
            Some("laz") => Format::Laz,
            Some("e57") => Format::E57,
            _ => {
                return Err(ScannerError::file(
                    path,
                    Location::File,
                    format!(
                        "unknown scan file extension {:?}: expected .3d, .ply, .xyz, .txt, .pcd, .las, .laz, .copc.laz or .e57",
                        ext.unwrap_or_default()
                    ),
                ));
            }
        })
    }
}

/// Reads a scan file; the format comes from the extension, the encoding
/// from the file's header.
pub fn read(path: &Path) -> Result<PointCloud> {
    match Format::from_path(path)? {
        Format::ThreeDtk => text::read_3dtk(path),
        Format::Ply(_) => ply::read(path),
        Format::Xyz => text::read_xyz(path),
        Format::Pcd(_) => pcd::read(path),
        Format::Las | Format::Laz | Format::Copc => las_read::read(path),
        Format::E57 => e57::read(path),
    }
}

/// Writes `points` with one float value per point (e.g. a deviation map)
/// under each of `names` as binary little-endian PLY (via a temporary file
/// and rename) — e.g. `deviation_m` and `scalar_deviation_m`, the name
/// CloudCompare loads as a scalar field.
pub fn write_ply_with_field(path: &Path, points: &[Point3<f32>], names: &[&str], values: &[f32]) -> Result<()> {
    let bad_name = names.iter().any(|n| ["x", "y", "z", ""].contains(n));
    if values.len() != points.len() || names.is_empty() || bad_name {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!(
                "fields {names:?} with {} values for {} points: expected names other than x, y, z and one value per point",
                values.len(),
                points.len()
            ),
        ));
    }
    let tmp = temporary(path);
    let result =
        with_writer(&tmp, |w| ply::write_scalar(w, points, Some((names, values)), PlyEncoding::BinaryLittleEndian));
    finish_write(path, &tmp, result).map(|_| ())
}

/// Writes `cloud` to `path` in `format` (via a temporary file and rename).
pub fn write(path: &Path, cloud: &PointCloud, format: Format) -> Result<()> {
    write_file(path, cloud, format).map(|_| ())
}

/// Writes `cloud` as [`write()`] does and returns the CRC-32 (IEEE) of the
/// file's bytes: hashed as they are written for the formats written as one
/// stream (3DTK, PLY, XYZ, PCD), read back for the others.
pub fn write_with_crc32(path: &Path, cloud: &PointCloud, format: Format) -> Result<u32> {
    match write_file(path, cloud, format)? {
        Some(crc) => Ok(crc),
        None => file_crc32(path),
    }
}

/// CRC-32 (IEEE) of a file's bytes.
pub fn file_crc32(path: &Path) -> Result<u32> {
    read_bytes(path).map(|bytes| crc32fast::hash(&bytes))
}

/// [`write`], with the CRC-32 of what was written when it was hashed on
/// the way.
fn write_file(path: &Path, cloud: &PointCloud, format: Format) -> Result<Option<u32>> {
    let mut writer = CloudWriter::create(path, format, CloudHeader::of(cloud))?;
    writer.push(cloud)?;
    writer.finish()
}

/// What a cloud must be to be written: one value per point in each
/// per-point field, a finite origin, scans within the points (no point in
/// two) with finite poses.
pub(crate) fn check(cloud: &PointCloud) -> std::result::Result<(), String> {
    let n = cloud.points.len();
    let per_point = |what: &str, len: Option<usize>| match len {
        Some(len) if len != n => Err(format!("{len} {what} for {n} points: expected one per point")),
        _ => Ok(()),
    };
    per_point("intensities", cloud.intensity.as_ref().map(Vec::len))?;
    per_point("scan indices", cloud.source.as_ref().map(Vec::len))?;
    per_point("colours", cloud.color.as_ref().map(Vec::len))?;
    per_point("times", cloud.time.as_ref().map(Vec::len))?;
    if let Some(i) = cloud.time.as_ref().and_then(|t| t.iter().position(|v| !v.is_finite())) {
        return Err(format!("point {i}'s time is not finite: expected seconds"));
    }
    if !cloud.origin.iter().all(|v| v.is_finite()) {
        return Err(format!("origin {:?}: expected finite coordinates", cloud.origin.as_slice()));
    }
    let mut runs: Vec<&ScanInfo> = cloud.scans.iter().filter(|s| !s.points.is_empty()).collect();
    runs.sort_by_key(|s| s.points.start);
    if let Some(w) = runs.windows(2).find(|w| w[1].points.start < w[0].points.end) {
        return Err(format!(
            "scans \"{}\" (points {:?}) and \"{}\" (points {:?}) share points: expected each point in one scan",
            w[0].name, w[0].points, w[1].name, w[1].points
        ));
    }
    for s in &cloud.scans {
        let pose = s.world_from_scan.to_homogeneous();
        if s.points.start > s.points.end || s.points.end > n || !pose.iter().all(|v| v.is_finite()) {
            return Err(format!(
                "scan \"{}\": points {:?} and pose {:?}: expected a range within the {n} points and a finite pose",
                s.name,
                s.points,
                s.world_from_scan.translation.vector.as_slice()
            ));
        }
    }
    Ok(())
}

/// Renames the written temporary file into place, or removes it after an
/// error (reported against `path`).
pub(crate) fn finish_write<T>(path: &Path, tmp: &Path, result: Result<T>) -> Result<T> {
    match result {
        Ok(value) => std::fs::rename(tmp, path).map(|()| value).map_err(|e| {
            // (A directory in the way, say: no `.partial` left behind.)
            let _ = std::fs::remove_file(tmp);
            ScannerError::io(path, e)
        }),
        Err(e) => {
            let _ = std::fs::remove_file(tmp);
            Err(against(path, e))
        }
    }
}

/// `e`, reported against `path` (the file being written) rather than its
/// temporary file.
pub(crate) fn against(path: &Path, e: ScannerError) -> ScannerError {
    match e {
        ScannerError::Io { source, .. } => ScannerError::io(path, source),
        ScannerError::File { location, message, .. } => ScannerError::file(path, location, message),
        other => other,
    }
}

/// Writes `bytes` as a new file and renames it over `path`: a reader never
/// sees it half-written, a full disk leaves the old file whole, a hard
/// link to the old file (a `cp -al` snapshot) keeps the old bytes, and a
/// symbolic link at `path` is replaced, never written through. The new
/// file is made beside it (`NAME.partial`, created exclusively: a link
/// there is removed first, not followed) and synced before the rename.
pub fn replace_file(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write as _;
    let tmp = temporary(path);
    remove_entry(&tmp)?;
    let written = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .and_then(|mut f| f.write_all(bytes).and_then(|()| f.sync_all()));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(ScannerError::io(path, e));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        ScannerError::io(path, e)
    })
}

/// Removes whatever is at `path` — a file or a symbolic link, never
/// followed — so that a file can be created there anew; nothing there is
/// fine.
pub fn remove_entry(path: &Path) -> Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(_) => std::fs::remove_file(path).map_err(|e| ScannerError::io(path, e)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(ScannerError::io(path, e)),
    }
}

pub(crate) fn temporary(path: &Path) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".partial");
    path.with_file_name(name)
}

/// Writes `path` through `f`, synced to the disk; returns the CRC-32 of
/// the bytes written.
pub(crate) fn with_writer(
    path: &Path,
    f: impl FnOnce(&mut BufWriter<Hashed<File>>) -> std::io::Result<()>,
) -> Result<u32> {
    let mut w = create_hashed(path)?;
    f(&mut w).map_err(|e| ScannerError::io(path, e))?;
    finish_hashed(path, w)
}

/// Creates `path` for writing through a buffer that hashes the bytes.
pub(crate) fn create_hashed(path: &Path) -> Result<BufWriter<Hashed<File>>> {
    let file = File::create(path).map_err(|e| ScannerError::io(path, e))?;
    Ok(BufWriter::with_capacity(1 << 20, Hashed { inner: file, crc: crc32fast::Hasher::new() }))
}

/// Flushes and syncs `w` (writing `path`); the CRC-32 of its bytes.
pub(crate) fn finish_hashed(path: &Path, mut w: BufWriter<Hashed<File>>) -> Result<u32> {
    w.flush().map_err(|e| ScannerError::io(path, e))?;
    let hashed = w.get_ref();
    hashed.inner.sync_all().map_err(|e| ScannerError::io(path, e))?;
    Ok(hashed.crc.clone().finalize())
}

/// A writer that hashes (CRC-32) the bytes it passes on.
#[derive(Debug)]
pub(crate) struct Hashed<W> {
    pub(crate) inner: W,
    pub(crate) crc: crc32fast::Hasher,
}

impl<W: Write> Write for Hashed<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Reads a whole file.
fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| ScannerError::io(path, e))
}

/// Reads a whole text file.
fn read_text(path: &Path) -> Result<String> {
    let bytes = read_bytes(path)?;
    String::from_utf8(bytes)
        .map_err(|e| ScannerError::file(path, Location::Byte(e.utf8_error().valid_up_to() as u64), "not UTF-8 text"))
}
