//! Reduced points (seed 000 §3): points that fall in the same cubic cell are
//! joined into their mean, which cuts a scan by about an order of magnitude
//! while keeping its surfaces.

use nalgebra::Point3;
use rayon::prelude::*;

use crate::error::{Result, ScannerError};

/// Joins the points in each cubic cell of edge `cell_m` into their mean
/// (accumulated in f64). The output is ordered by the cells' Morton (Z-order)
/// key, so it is deterministic and spatially coherent. Non-finite points and
/// clouds spanning 2²¹ cells or more along an axis are errors.
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
    let cell = |c: f32| (f64::from(c) * inv).floor();
    // Cell indices relative to the lowest cell, 21 bits per axis, interleaved
    // into one u64 Morton key: sorting by it groups the output spatially,
    // which keeps later nearest-neighbour queries cache-friendly.
    let (lo, hi) = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let c = [cell(p.x), cell(p.y), cell(p.z)];
            if c.iter().all(|k| k.abs() < 1e15) {
                Ok((c, c))
            } else {
                Err(ScannerError::OutOfRange {
                    device: "reduced points".into(),
                    what: format!("point {i} coordinate (m)"),
                    value: f64::from(p.x.abs().max(p.y.abs()).max(p.z.abs())),
                    expected: format!("finite and within ±{:.3e} m for a {cell_m} m cell", 1e15 * cell_m),
                })
            }
        })
        .try_reduce(
            || ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
            |(alo, ahi), (blo, bhi)| {
                Ok((std::array::from_fn(|k| alo[k].min(blo[k])), std::array::from_fn(|k| ahi[k].max(bhi[k]))))
            },
        )?;
    const BITS: u32 = 21;
    for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
        if hi[k] - lo[k] >= f64::from(1u32 << BITS) {
            return Err(ScannerError::OutOfRange {
                device: "reduced points".into(),
                what: format!("cloud extent along {axis} in {cell_m} m cells"),
                value: hi[k] - lo[k] + 1.0,
                expected: format!("< {} cells: use a larger cell or split the cloud", 1u32 << BITS),
            });
        }
    }
    let mut keyed: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let key = |c: f32, k: usize| spread((cell(c) - lo[k]) as u64);
            ((key(p.x, 0) << 2) | (key(p.y, 1) << 1) | key(p.z, 2), i as u32)
        })
        .collect();
    keyed.sort_unstable();
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

/// Spreads the low 21 bits of `v` to every third bit (bit i → bit 3i).
fn spread(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | (x << 32)) & 0x1f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x1f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    (x | (x << 2)) & 0x1249_2492_4924_9249
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_moves_bit_i_to_3i() {
        for i in 0..21 {
            assert_eq!(spread(1 << i), 1 << (3 * i));
        }
        assert_eq!(spread(0x1f_ffff), 0x1249_2492_4924_9249);
        assert_eq!(spread(1 << 21), 0, "bits above 21 are dropped");
    }

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
