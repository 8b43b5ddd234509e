//! Reduced points (seed 000 §3): points that fall in the same cubic cell are
//! joined into their mean, which cuts a scan by about an order of magnitude
//! while keeping its surfaces.

use nalgebra::Point3;
use rayon::prelude::*;

use crate::error::{Result, ScannerError};

/// Joins the points in each cubic cell of edge `cell_m` into their mean
/// (accumulated in f64). The output is ordered by cell (x, then y, then z
/// cell index), so it is deterministic. Non-finite points are an error.
pub fn reduced_points(points: &[Point3<f32>], cell_m: f64) -> Result<Vec<Point3<f32>>> {
    if !(cell_m.is_finite() && cell_m > 0.0) {
        return Err(ScannerError::OutOfRange {
            device: "reduced points".into(),
            what: "cell size (m)".into(),
            value: cell_m,
            expected: "> 0".into(),
        });
    }
    let inv = 1.0 / cell_m;
    let limit = f64::from(i32::MAX);
    let mut keyed: Vec<((i32, i32, i32), u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let cell = |c: f32| {
                let k = (f64::from(c) * inv).floor();
                (k.abs() < limit).then_some(k as i32)
            };
            match (cell(p.x), cell(p.y), cell(p.z)) {
                (Some(x), Some(y), Some(z)) => Ok(((x, y, z), i as u32)),
                _ => Err(ScannerError::OutOfRange {
                    device: "reduced points".into(),
                    what: format!("point {i} coordinate (m)"),
                    value: f64::from(p.x.abs().max(p.y.abs()).max(p.z.abs())),
                    expected: format!("finite and within ±{:.3e} m for a {cell_m} m cell", limit * cell_m),
                }),
            }
        })
        .collect::<Result<_>>()?;
    keyed.par_sort_unstable();
    let mut out = Vec::with_capacity(points.len() / 4);
    let mut start = 0;
    while start < keyed.len() {
        let key = keyed[start].0;
        let mut end = start;
        let mut sum = nalgebra::Vector3::<f64>::zeros();
        while end < keyed.len() && keyed[end].0 == key {
            sum += points[keyed[end].1 as usize].coords.cast::<f64>();
            end += 1;
        }
        out.push(Point3::from(sum / (end - start) as f64).cast());
        start = end;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn means_per_cell() {
        let pts = [
            Point3::new(0.1f32, 0.1, 0.1),
            Point3::new(0.3, 0.2, 0.4),
            Point3::new(1.2, 0.1, 0.1),
            Point3::new(-0.1, 0.0, 0.0),
        ];
        let r = reduced_points(&pts, 0.5).expect("reduce");
        assert_eq!(r, vec![Point3::new(-0.1, 0.0, 0.0), Point3::new(0.2, 0.15, 0.25), Point3::new(1.2, 0.1, 0.1)]);
        assert!(reduced_points(&pts, 0.0).is_err());
        let bad = [Point3::new(f32::NAN, 0.0, 0.0)];
        assert!(reduced_points(&bad, 0.1).expect_err("NaN").to_string().contains("point 0"));
    }
}
