//! Text formats: XYZ and 3DTK "uos" (`scanNNN.3d` + `scanNNN.pose`), and
//! the 4×4 row-major matrix files that come with the reference data.
//!
//! 3DTK is left-handed (x right, y up, z forward) in centimetres; we convert
//! at the boundary with (x, y, z)_ours = (z, −x, y)_3dtk / 100. A pose file
//! holds `x y z` (cm) and `θx θy θz` (degrees) for M = T·Rx·Ry·Rz.

use std::io::Write;
use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Matrix4, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::{PointCloud, read_text};
use crate::error::{Location, Result, ScannerError};

/// Parses whitespace- or comma-separated numbers of one line.
fn numbers(path: &Path, line_no: usize, line: &str, out: &mut Vec<f64>) -> Result<()> {
    out.clear();
    for tok in line.split(|c: char| c.is_whitespace() || c == ',').filter(|t| !t.is_empty()) {
        let v: f64 = tok.parse().map_err(|_| {
            ScannerError::file(
                path,
                Location::Line(line_no),
                format!("'{tok}' is not a number: expected x y z [intensity]"),
            )
        })?;
        if !v.is_finite() {
            return Err(ScannerError::file(path, Location::Line(line_no), format!("'{tok}' is not finite")));
        }
        out.push(v);
    }
    Ok(())
}

/// Reads `x y z [intensity]` lines; `#` starts a comment line. `map`
/// converts each file point to ours.
fn read_columns(path: &Path, map: impl Fn(f64, f64, f64) -> Point3<f32>) -> Result<PointCloud> {
    let text = read_text(path)?;
    let mut cloud = PointCloud::default();
    let mut row = Vec::with_capacity(4);
    let mut columns = None;
    for (k, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        numbers(path, k + 1, t, &mut row)?;
        let expected = *columns.get_or_insert(row.len());
        if !(3..=4).contains(&row.len()) || row.len() != expected {
            return Err(ScannerError::file(
                path,
                Location::Line(k + 1),
                format!(
                    "{} values: expected {} (x y z{})",
                    row.len(),
                    expected.clamp(3, 4),
                    if expected == 4 { " intensity" } else { "" }
                ),
            ));
        }
        let p = map(row[0], row[1], row[2]);
        let intensity = row.get(3).map(|&i| i as f32);
        if !p.iter().chain(intensity.as_ref()).all(|v| v.is_finite()) {
            return Err(ScannerError::file(
                path,
                Location::Line(k + 1),
                format!("'{t}' overflows a 32-bit float: expected values within ±{:e}", f32::MAX),
            ));
        }
        cloud.points.push(p);
        if let Some(i) = intensity {
            cloud.intensity.get_or_insert_with(Vec::new).push(i);
        }
    }
    Ok(cloud)
}

fn write_columns(
    w: &mut impl Write,
    cloud: &PointCloud,
    map: impl Fn(&Point3<f32>) -> [f64; 3],
) -> std::io::Result<()> {
    for (i, p) in cloud.points.iter().enumerate() {
        let [a, b, c] = map(p);
        match &cloud.intensity {
            Some(v) => writeln!(w, "{a} {b} {c} {}", v[i])?,
            None => writeln!(w, "{a} {b} {c}")?,
        }
    }
    Ok(())
}

pub(super) fn read_xyz(path: &Path) -> Result<PointCloud> {
    read_columns(path, |x, y, z| Point3::new(x as f32, y as f32, z as f32))
}

pub(super) fn write_xyz(w: &mut impl Write, cloud: &PointCloud) -> std::io::Result<()> {
    if cloud.georeferenced() {
        // origin + p in f64, to 0.1 mm.
        for i in 0..cloud.points.len() {
            let [x, y, z] = cloud.coordinates(i);
            match &cloud.intensity {
                Some(v) => writeln!(w, "{x:.4} {y:.4} {z:.4} {}", v[i])?,
                None => writeln!(w, "{x:.4} {y:.4} {z:.4}")?,
            }
        }
        return Ok(());
    }
    // f32 → f64 is exact, and Display prints the shortest string that reads back exactly.
    write_columns(w, cloud, |p| [f64::from(p.x), f64::from(p.y), f64::from(p.z)])
}

pub(super) fn read_3dtk(path: &Path) -> Result<PointCloud> {
    read_columns(path, |x, y, z| Point3::new((z / 100.0) as f32, (-x / 100.0) as f32, (y / 100.0) as f32))
}

pub(super) fn write_3dtk(w: &mut impl Write, cloud: &PointCloud) -> std::io::Result<()> {
    // 100·f32 is exact in f64, so reading divides back to the same f32.
    let o = cloud.origin;
    write_columns(w, cloud, |p| {
        [-(o.y + f64::from(p.y)) * 100.0, (o.z + f64::from(p.z)) * 100.0, (o.x + f64::from(p.x)) * 100.0]
    })
}

/// C: 3DTK axes → ours, (x, y, z)_ours = C · (x, y, z)_3dtk.
fn c_ours_from_3dtk() -> Matrix3<f64> {
    Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
}

/// A transform given in 3DTK axes (metres) expressed in ours: C·M·Cᵀ.
pub fn from_3dtk_axes(m: &Matrix4<f64>) -> Isometry3<f64> {
    let c = c_ours_from_3dtk();
    let r = c * m.fixed_view::<3, 3>(0, 0) * c.transpose();
    let t = c * m.fixed_view::<3, 1>(0, 3);
    Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_matrix(&r))
}

/// A transform in our axes expressed in 3DTK axes (metres): Cᵀ·T·C.
pub fn to_3dtk_axes(iso: &Isometry3<f64>) -> Matrix4<f64> {
    let c = c_ours_from_3dtk();
    let r = c.transpose() * iso.rotation.to_rotation_matrix().matrix() * c;
    let t = c.transpose() * iso.translation.vector;
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&t);
    m
}

/// Reads a 3DTK `.pose` file as `world_from_scan` in our axes and metres.
pub fn read_3dtk_pose(path: &Path) -> Result<Isometry3<f64>> {
    let text = read_text(path)?;
    let mut rows = Vec::new();
    let mut row = Vec::new();
    for (k, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        numbers(path, k + 1, line.trim(), &mut row)?;
        if row.len() != 3 {
            return Err(ScannerError::file(path, Location::Line(k + 1), format!("{} values: expected 3", row.len())));
        }
        rows.push([row[0], row[1], row[2]]);
    }
    if rows.len() != 2 {
        return Err(ScannerError::file(
            path,
            Location::File,
            format!("{} lines: expected 2 (x y z in cm, then θx θy θz in degrees)", rows.len()),
        ));
    }
    let [ax, ay, az] = rows[1].map(f64::to_radians);
    let r = Rotation3::from_axis_angle(&Vector3::x_axis(), ax)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), ay)
        * Rotation3::from_axis_angle(&Vector3::z_axis(), az);
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(r.matrix());
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&(Vector3::from(rows[0]) / 100.0));
    Ok(from_3dtk_axes(&m))
}

/// Writes `world_from_scan` (our axes, metres) as a 3DTK `.pose` file.
pub fn write_3dtk_pose(path: &Path, world_from_scan: &Isometry3<f64>) -> Result<()> {
    let m = to_3dtk_axes(world_from_scan);
    // R = Rx(a)·Ry(b)·Rz(c): R02 = sin b, R12 = −sin a cos b, R22 = cos a cos b,
    // R01 = −cos b sin c, R00 = cos b cos c.
    let b = m[(0, 2)].clamp(-1.0, 1.0).asin();
    let a = (-m[(1, 2)]).atan2(m[(2, 2)]);
    let c = (-m[(0, 1)]).atan2(m[(0, 0)]);
    let t = m.fixed_view::<3, 1>(0, 3) * 100.0;
    let text = format!("{} {} {}\n{} {} {}\n", t[0], t[1], t[2], a.to_degrees(), b.to_degrees(), c.to_degrees());
    let tmp = super::temporary(path);
    std::fs::write(&tmp, text).and_then(|()| std::fs::rename(&tmp, path)).map_err(|e| ScannerError::io(path, e))
}

/// Writes `world_from_scan` (our axes, metres) as a 3DTK `.frames` file:
/// one line of the 4×4 transform in 3DTK axes, column-major (OpenGL
/// order), translation in cm, then the algorithm type (1: ICP) — the line
/// slam6d's `show` takes (the last of the file) to place the scan.
pub fn write_3dtk_frames(path: &Path, world_from_scan: &Isometry3<f64>) -> Result<()> {
    let mut m = to_3dtk_axes(world_from_scan);
    for r in 0..3 {
        m[(r, 3)] *= 100.0;
    }
    let values: Vec<String> =
        (0..4).flat_map(|c| (0..4).map(move |r| (r, c))).map(|(r, c)| m[(r, c)].to_string()).collect();
    let text = format!("{} 1\n", values.join(" "));
    // A new file renamed into place: a link at `path` is replaced, never
    // written through.
    super::replace_file(path, text.as_bytes())
}

/// Reads a 3DTK `.frames` file: the transform of its last line (16
/// column-major values in 3DTK axes, cm; a 17th, the algorithm type, is
/// ignored) in our axes, metres.
pub fn read_3dtk_frames(path: &Path) -> Result<Isometry3<f64>> {
    let text = read_text(path)?;
    let mut row = Vec::new();
    let mut last = None;
    for (k, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        numbers(path, k + 1, line.trim(), &mut row)?;
        if !(16..=17).contains(&row.len()) {
            let message = format!("{} values: expected 16 (a 4×4 transform, column-major) and a type", row.len());
            return Err(ScannerError::file(path, Location::Line(k + 1), message));
        }
        last = Some((k + 1, Matrix4::from_column_slice(&row[..16])));
    }
    let Some((line, mut m)) = last else {
        return Err(ScannerError::file(path, Location::File, "no frame: expected a line of 16 values"));
    };
    if (m.fixed_view::<1, 4>(3, 0) - nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0)).norm() > 1e-9 {
        return Err(ScannerError::file(path, Location::Line(line), "the last row is not 0 0 0 1"));
    }
    for r in 0..3 {
        m[(r, 3)] /= 100.0;
    }
    Ok(from_3dtk_axes(&m))
}

/// Reads a 4×4 row-major matrix from text (16 numbers on 4 lines).
pub fn read_matrix4(path: &Path) -> Result<Matrix4<f64>> {
    let text = read_text(path)?;
    let mut values = Vec::with_capacity(16);
    let mut row = Vec::new();
    for (k, line) in text.lines().enumerate() {
        if line.trim().is_empty() || line.trim().starts_with('#') {
            continue;
        }
        numbers(path, k + 1, line.trim(), &mut row)?;
        if row.len() != 4 {
            return Err(ScannerError::file(
                path,
                Location::Line(k + 1),
                format!("{} values: expected 4 per matrix row", row.len()),
            ));
        }
        values.extend_from_slice(&row);
    }
    if values.len() != 16 {
        return Err(ScannerError::file(path, Location::File, format!("{} rows: expected 4", values.len() / 4)));
    }
    Ok(Matrix4::from_row_slice(&values))
}
