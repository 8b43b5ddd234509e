//! Reduced points (seed 000 §3): points that fall in the same cubic cell are
//! joined into their mean, which cuts a scan by about an order of magnitude
//! while keeping its surfaces.

use nalgebra::Point3;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

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
    if points.is_empty() {
        return Ok(Vec::new());
    }
    // Every coordinate finite and at most 1e15 cells from the origin (so
    // cell indices are exact in f64).
    let limit = 1e15 * cell_m;
    let bad = |p: &Point3<f32>| !p.coords.iter().all(|c| f64::from(c.abs()) < limit);
    if points.par_iter().any(bad) {
        // (`position_first` would name the first bad point in one parallel
        // pass but is ten times slower than `any` on the good path.)
        let i = points.iter().position(bad).unwrap_or_default();
        let p = points[i];
        return Err(ScannerError::OutOfRange {
            device: "reduced points".into(),
            what: format!("point {i} coordinate (m)"),
            value: f64::from(p.x.abs().max(p.y.abs()).max(p.z.abs())),
            expected: format!("finite and within ±{limit:.3e} m for a {cell_m} m cell"),
        });
    }
    let inv = 1.0 / cell_m;
    // ⌊c / cell⌋ in integers (x86-64's baseline has no rounding
    // instruction, and f64 → u64 conversions are slow); exact for
    // |c / cell| < 2⁶³, which the check above ensures.
    let cell = |c: f32| {
        let v = f64::from(c) * inv;
        let t = v as i64;
        t - i64::from((t as f64) > v)
    };
    // Cell indices relative to the lowest cell, 21 bits per axis, interleaved
    // into one u64 Morton key: sorting by it groups the output spatially,
    // which keeps later nearest-neighbour queries cache-friendly.
    let (min, max) = points
        .par_iter()
        .fold(
            || ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
            |(lo, hi), p| (std::array::from_fn(|k| lo[k].min(p[k])), std::array::from_fn(|k| hi[k].max(p[k]))),
        )
        .reduce(
            || ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
            |(alo, ahi), (blo, bhi)| {
                (std::array::from_fn(|k| alo[k].min(blo[k])), std::array::from_fn(|k| ahi[k].max(bhi[k])))
            },
        );
    let (lo, hi) = (min.map(cell), max.map(cell));
    const BITS: u32 = 21;
    for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
        if hi[k] - lo[k] >= 1 << BITS {
            return Err(ScannerError::OutOfRange {
                device: "reduced points".into(),
                what: format!("cloud extent along {axis} in {cell_m} m cells"),
                value: (hi[k] - lo[k] + 1) as f64,
                expected: format!("< {} cells: use a larger cell or split the cloud", 1u32 << BITS),
            });
        }
    }
    let keys: Vec<u64> = points
        .par_iter()
        .map(|p| {
            let key = |c: f32, k: usize| spread((cell(c) - lo[k]) as u64);
            (key(p.x, 0) << 2) | (key(p.y, 1) << 1) | key(p.z, 2)
        })
        .collect();
    // The points grouped by the top bits of their key — 64 blocks of
    // space, in Morton order — keeping input order within each block. Each
    // block is then one hashed pass in that order (so a cell's sum has a
    // fixed order and the result does not depend on the thread count),
    // and its cells are sorted by key; the blocks' cells concatenated are
    // sorted.
    let used_bits = 3 * (64 - (0..3).map(|k| (hi[k] - lo[k]) as u64).max().unwrap_or(0).leading_zeros());
    let shift = used_bits.saturating_sub(6);
    let block = |key: u64| (key >> shift) as usize;
    let mut starts = vec![0usize; 65];
    for &key in &keys {
        starts[block(key) + 1] += 1;
    }
    for b in 1..starts.len() {
        starts[b] += starts[b - 1];
    }
    let mut order = vec![0u32; points.len()];
    let mut next = starts.clone();
    for (i, &key) in keys.iter().enumerate() {
        order[next[block(key)]] = i as u32;
        next[block(key)] += 1;
    }
    let blocks: Vec<Vec<Point3<f32>>> = starts
        .par_windows(2)
        .map(|w| {
            let members = &order[w[0]..w[1]];
            let mut slot_of: FxHashMap<u64, u32> = FxHashMap::default();
            slot_of.reserve(members.len() / 4);
            let mut cells: Vec<(u64, nalgebra::Vector3<f64>, u32)> = Vec::with_capacity(members.len() / 4);
            for &i in members {
                let key = keys[i as usize];
                let slot = *slot_of.entry(key).or_insert_with(|| {
                    cells.push((key, nalgebra::Vector3::zeros(), 0));
                    (cells.len() - 1) as u32
                });
                let c = &mut cells[slot as usize];
                c.1 += points[i as usize].coords.cast::<f64>();
                c.2 += 1;
            }
            cells.sort_unstable_by_key(|c| c.0);
            cells.iter().map(|(_, sum, n)| Point3::from(sum / f64::from(*n)).cast()).collect()
        })
        .collect();
    Ok(blocks.concat())
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

    /// Against a plain per-cell mean (cells keyed by their integer index,
    /// points summed in input order), on a scattered cloud with up to ~10
    /// points per cell: the same means bit for bit, in Morton order, and
    /// the same result on one thread and on four.
    #[test]
    fn matches_a_plain_mean_whatever_the_threads() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let pts: Vec<Point3<f32>> = (0..20_000)
            .map(|_| Point3::new(rng.random_range(-3.0..5.0), rng.random_range(-1.0..1.0), rng.random_range(0.0..0.3)))
            .collect();
        let cell_m = 0.1;
        let mut plain: std::collections::HashMap<[i64; 3], (nalgebra::Vector3<f64>, u32)> = Default::default();
        for p in &pts {
            let c = p.coords.map(|v| (f64::from(v) / cell_m).floor() as i64);
            let e = plain.entry([c.x, c.y, c.z]).or_default();
            e.0 += p.coords.cast::<f64>();
            e.1 += 1;
        }
        let mut expected: Vec<[u32; 3]> = plain
            .values()
            .map(|(s, n)| Point3::<f64>::from(s / f64::from(*n)).cast::<f32>().coords.map(f32::to_bits).into())
            .collect();
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
            pool.install(|| reduced_points(&pts, cell_m)).expect("reduce")
        };
        let (one, four) = (run(1), run(4));
        assert_eq!(one, four);
        let mut got: Vec<[u32; 3]> = one.iter().map(|p| p.coords.map(f32::to_bits).into()).collect();
        // Morton order: the cells' keys (relative to the lowest cell) never
        // decrease along the output.
        let lo: Vec<f64> = (0..3)
            .map(|k| pts.iter().map(|p| (f64::from(p[k]) / cell_m).floor()).fold(f64::INFINITY, f64::min))
            .collect();
        let key = |p: &Point3<f32>| {
            let c = |k: usize| spread(((f64::from(p[k]) / cell_m).floor() - lo[k]) as u64);
            (c(0) << 2) | (c(1) << 1) | c(2)
        };
        assert!(one.windows(2).all(|w| key(&w[0]) <= key(&w[1])));
        expected.sort_unstable();
        got.sort_unstable();
        assert_eq!(got, expected);
        assert!(reduced_points(&[], 0.1).expect("empty").is_empty());
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
