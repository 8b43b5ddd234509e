//! Scan files. Every reader returns a [`PointCloud`] in our frame and
//! units (metres, x forward, y left, z up); every error names the file and
//! the line or byte offset. Writers write to a temporary file and rename it,
//! so a file that exists is complete.
//!
//! | format | read | write | notes |
//! |---|---|---|---|
//! | 3DTK `.3d` + `.pose` | ✓ | ✓ | cm, left-handed; (x, y, z)_ours = (z, −x, y)_3dtk / 100 |
//! | PLY | ✓ ascii, binary LE/BE | ✓ ascii, binary LE | optional intensity |
//! | XYZ text | ✓ | ✓ | `x y z [intensity]` per line |
//! | PCD | ✓ ascii, binary, binary_compressed | ✓ all three | F4/F8/U/I fields |
//! | LAS 1.4 | ✓ | ✓ | 0.1 mm scale |
//! | E57 | ✓ | ✓ | f32 Cartesian |

mod e57;
mod las;
mod pcd;
mod ply;
mod text;

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};

pub use pcd::PcdData;
pub use ply::PlyEncoding;
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
}

impl PointCloud {
    /// A cloud of points without intensity, at the zero origin.
    pub fn from_points(points: Vec<Point3<f32>>) -> Self {
        Self { points, intensity: None, origin: Vector3::zeros(), source: None }
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
    /// E57.
    E57,
}

impl Format {
    /// The format for a file name's extension (`.3d`, `.ply`, `.xyz`/`.txt`,
    /// `.pcd`, `.las`, `.e57`); writing uses binary PLY and
    /// binary_compressed PCD.
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        Ok(match ext.as_deref() {
            Some("3d") => Format::ThreeDtk,
            Some("ply") => Format::Ply(PlyEncoding::BinaryLittleEndian),
            Some("xyz" | "txt") => Format::Xyz,
            Some("pcd") => Format::Pcd(PcdData::BinaryCompressed),
            Some("las") => Format::Las,
            Some("e57") => Format::E57,
            _ => {
                return Err(ScannerError::file(
                    path,
                    Location::File,
                    format!(
                        "unknown scan file extension {:?}: expected .3d, .ply, .xyz, .txt, .pcd, .las or .e57",
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
        Format::Las => las::read(path),
        Format::E57 => e57::read(path),
    }
}

/// Writes `points` with one named float field per point (e.g. a deviation
/// map) as binary little-endian PLY (via a temporary file and rename); viewers
/// such as CloudCompare show the field as a scalar field.
pub fn write_ply_with_field(path: &Path, points: &[Point3<f32>], field: &str, values: &[f32]) -> Result<()> {
    if values.len() != points.len() || ["x", "y", "z"].contains(&field) || field.is_empty() {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!(
                "field `{field}` with {} values for {} points: expected a name other than x, y, z and one value per point",
                values.len(),
                points.len()
            ),
        ));
    }
    let tmp = temporary(path);
    let result =
        with_writer(&tmp, |w| ply::write_scalar(w, points, Some((field, values)), PlyEncoding::BinaryLittleEndian));
    finish_write(path, &tmp, result)
}

/// Writes `cloud` to `path` in `format` (via a temporary file and rename).
pub fn write(path: &Path, cloud: &PointCloud, format: Format) -> Result<()> {
    if let Some(i) = &cloud.intensity
        && i.len() != cloud.points.len()
    {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!("{} intensities for {} points: expected one per point", i.len(), cloud.points.len()),
        ));
    }
    if let Some(s) = &cloud.source
        && s.len() != cloud.points.len()
    {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!("{} scan indices for {} points: expected one per point", s.len(), cloud.points.len()),
        ));
    }
    if !cloud.origin.iter().all(|v| v.is_finite()) {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!("origin {:?}: expected finite coordinates", cloud.origin.as_slice()),
        ));
    }
    let tmp = temporary(path);
    let result = match format {
        Format::ThreeDtk => with_writer(&tmp, |w| text::write_3dtk(w, cloud)),
        Format::Ply(e) => with_writer(&tmp, |w| ply::write(w, cloud, e)),
        Format::Xyz => with_writer(&tmp, |w| text::write_xyz(w, cloud)),
        Format::Pcd(d) => with_writer(&tmp, |w| pcd::write(w, cloud, d)),
        Format::Las => las::write(&tmp, cloud),
        Format::E57 => e57::write(&tmp, cloud),
    };
    finish_write(path, &tmp, result)
}

/// Renames the written temporary file into place, or removes it after an
/// error (reported against `path`).
fn finish_write(path: &Path, tmp: &Path, result: Result<()>) -> Result<()> {
    match result {
        Ok(()) => std::fs::rename(tmp, path).map_err(|e| ScannerError::io(path, e)),
        Err(e) => {
            let _ = std::fs::remove_file(tmp);
            Err(match e {
                ScannerError::Io { source, .. } => ScannerError::io(path, source),
                ScannerError::File { location, message, .. } => ScannerError::file(path, location, message),
                other => other,
            })
        }
    }
}

fn temporary(path: &Path) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".partial");
    path.with_file_name(name)
}

fn with_writer(path: &Path, f: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>) -> Result<()> {
    let file = File::create(path).map_err(|e| ScannerError::io(path, e))?;
    let mut w = BufWriter::with_capacity(1 << 20, file);
    f(&mut w).and_then(|()| w.flush()).map_err(|e| ScannerError::io(path, e))?;
    w.get_ref().sync_all().map_err(|e| ScannerError::io(path, e))
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
