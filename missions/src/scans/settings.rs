//! Settings shared by `register` and `match`: a coarse-to-fine schedule
//! "VOXEL/DISTANCE,…" and a 4×4 matrix that must be a rigid transform.

use anyhow::{Result, bail};
use fusion::icp::Stage;
use nalgebra::{Isometry3, Matrix4, Rotation3, Translation3, UnitQuaternion};

/// Parses `--schedule`: stages "VOXEL/DISTANCE" in metres, comma separated,
/// each value finite and > 0.
pub fn schedule(text: &str) -> Result<Vec<Stage>> {
    text.split(',')
        .map(|s| {
            let parse =
                |v: Option<&str>| v.and_then(|v| v.trim().parse::<f64>().ok()).filter(|v| v.is_finite() && *v > 0.0);
            let mut parts = s.split('/');
            match (parse(parts.next()), parse(parts.next()), parts.next()) {
                (Some(voxel_m), Some(max_correspondence_m), None) => Ok(Stage { voxel_m, max_correspondence_m }),
                _ => bail!("--schedule stage \"{s}\": expected VOXEL/MAXDIST in metres (> 0), e.g. 0.1/0.5"),
            }
        })
        .collect()
}

/// A rigid transform from a 4×4 matrix, which must be one (orthonormal
/// rotation within 1e-6, last row 0 0 0 1, finite).
pub fn rigid(m: &Matrix4<f64>) -> Result<Isometry3<f64>> {
    if !m.iter().all(|v| v.is_finite()) {
        bail!("a value is not finite: expected a rigid 4×4 transform");
    }
    let r = m.fixed_view::<3, 3>(0, 0).into_owned();
    let off = (r.transpose() * r - nalgebra::Matrix3::identity()).amax();
    if !(off < 1e-6 && r.determinant() > 0.0) {
        bail!("the upper-left 3×3 is not a rotation (|RᵀR − I| = {off:.2e}, det = {:.6})", r.determinant());
    }
    if m.fixed_view::<1, 4>(3, 0) != nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0) {
        bail!("the last row is {:?}: expected 0 0 0 1", m.fixed_view::<1, 4>(3, 0).iter().collect::<Vec<_>>());
    }
    Ok(Isometry3::from_parts(
        Translation3::from(m.fixed_view::<3, 1>(0, 3).into_owned()),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    ))
}

/// Keeps the points between `min_m` and `max_m` from their scan's origin.
pub fn within_range(points: Vec<nalgebra::Point3<f32>>, min_m: f64, max_m: f64) -> Vec<nalgebra::Point3<f32>> {
    let keep = in_range(&points, min_m, max_m);
    points.into_iter().zip(keep).filter_map(|(p, k)| k.then_some(p)).collect()
}

/// Whether each point lies between `min_m` and `max_m` from its scan's origin.
pub fn in_range(points: &[nalgebra::Point3<f32>], min_m: f64, max_m: f64) -> Vec<bool> {
    let (min2, max2) = ((min_m * min_m) as f32, (max_m * max_m) as f32);
    points.iter().map(|p| (min2..=max2).contains(&p.coords.norm_squared())).collect()
}

/// Checks `--min-range` / `--max-range`.
pub fn check_range(min_m: f64, max_m: f64) -> Result<()> {
    if !(min_m >= 0.0 && max_m > min_m) {
        bail!("--min-range {min_m} / --max-range {max_m}: expected 0 ≤ min < max");
    }
    Ok(())
}
