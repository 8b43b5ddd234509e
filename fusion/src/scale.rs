//! The length scales of a scan set — how far apart its points lie and how
//! large its scans are — measured on the scans, and the voxel cells a scan
//! occupies (what a coarse-to-fine stage has to match): `match` reports
//! them and refuses a schedule that leaves a scan too few cells.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point3;
use rayon::prelude::*;

/// A scan's radius: this quantile of its points' distances from their
/// centroid (a range scan's points crowd near the scanner: the median
/// says little of the scan's size; the largest is one stray return).
const RADIUS_QUANTILE: f64 = 0.9;

/// The grid the spacing is sampled on: cells of the radius / this.
const CELLS_PER_RADIUS: f64 = 50.0;

/// Points per scan whose nearest neighbour is measured.
const SAMPLES: usize = 2000;

/// The length scales of a scan set (medians over its scans).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetScale {
    /// Point spacing over the surfaces: the median distance to the
    /// nearest neighbour of one point per cell of a fiftieth of the
    /// radius, metres.
    pub spacing_m: f64,
    /// Size: the 90th percentile of a scan's points' distances from their
    /// centroid, metres.
    pub radius_m: f64,
}

impl SetScale {
    /// Measures `scans` (each in its own frame). `None` when no scan has
    /// two distinct points.
    pub fn of(scans: &[&[Point3<f32>]]) -> Option<Self> {
        let each: Vec<(f64, f64)> = scans.par_iter().filter_map(|s| scan_scale(s)).collect();
        if each.is_empty() {
            return None;
        }
        let spacing_m = median(each.iter().map(|e| e.0).collect());
        let radius_m = median(each.iter().map(|e| e.1).collect());
        Some(Self { spacing_m, radius_m })
    }
}

/// Voxel cells `points` occupy at `voxel_m` (what a stage matches).
pub fn occupied_cells(points: &[Point3<f32>], voxel_m: f64) -> usize {
    let v = voxel_m as f32;
    let cells: std::collections::HashSet<[i64; 3]> =
        points.iter().map(|p| [p.x, p.y, p.z].map(|c| (c / v).floor() as i64)).collect();
    cells.len()
}

/// (spacing, radius) of one scan, or `None` with fewer than two distinct
/// points.
fn scan_scale(points: &[Point3<f32>]) -> Option<(f64, f64)> {
    let finite: Vec<[f32; 3]> =
        points.iter().filter(|p| p.iter().all(|v| v.is_finite())).map(|p| [p.x, p.y, p.z]).collect();
    if finite.len() < 2 {
        return None;
    }
    let n = finite.len() as f64;
    let centroid = finite.iter().fold([0.0f64; 3], |c, p| std::array::from_fn(|k| c[k] + f64::from(p[k]) / n));
    let radius = quantile(
        finite.iter().map(|p| (0..3).map(|k| (f64::from(p[k]) - centroid[k]).powi(2)).sum::<f64>().sqrt()).collect(),
        RADIUS_QUANTILE,
    );
    let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&finite).ok()?;
    // One point per cell of a coarse grid (a fiftieth of the radius): the
    // spacing over the surface, not per return — a range scan's returns
    // crowd near the scanner.
    let cell = (radius / CELLS_PER_RADIUS) as f32;
    let mut seen = std::collections::HashSet::new();
    let representatives: Vec<&[f32; 3]> =
        finite.iter().filter(|p| cell <= 0.0 || seen.insert(p.map(|v| (v / cell).floor() as i64))).collect();
    let step = (representatives.len() / SAMPLES).max(1);
    let gaps: Vec<f64> = representatives
        .iter()
        .step_by(step)
        .filter_map(|p| {
            // The nearest point at a distance (duplicates say nothing of
            // the spacing).
            let k = std::num::NonZero::new(8.min(finite.len()))?;
            tree.query(p)
                .nearest_n::<SquaredEuclidean<f32>>(k)
                .execute()
                .into_iter()
                .map(|nn| f64::from(nn.distance))
                .find(|&d2| d2 > 0.0)
                .map(f64::sqrt)
        })
        .collect();
    (!gaps.is_empty() && radius > 0.0).then(|| (median(gaps), radius))
}

fn median(values: Vec<f64>) -> f64 {
    quantile(values, 0.5)
}

/// The `q` quantile of `values` (not empty).
fn quantile(mut values: Vec<f64>, q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * q).round() as usize]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of `n`×`n` points `spacing` apart on a plane, plus a wall.
    fn grid(n: usize, spacing: f32) -> Vec<Point3<f32>> {
        let mut points = Vec::new();
        for i in 0..n {
            for j in 0..n {
                points.push(Point3::new(i as f32 * spacing, j as f32 * spacing, 0.0));
                points.push(Point3::new(i as f32 * spacing, 0.0, j as f32 * spacing));
            }
        }
        points
    }

    #[test]
    fn a_grid_measures_its_spacing_and_scales_with_it() {
        let scale = SetScale::of(&[&grid(100, 0.05)]).expect("a scale");
        assert!((scale.spacing_m - 0.05).abs() < 1e-6, "{scale:?}");
        for factor in [0.01f32, 100.0] {
            let scaled: Vec<Point3<f32>> = grid(100, 0.05).iter().map(|p| p * factor).collect();
            let other = SetScale::of(&[&scaled]).expect("a scale");
            let f = f64::from(factor);
            assert!((other.spacing_m / (scale.spacing_m * f) - 1.0).abs() < 1e-5, "{other:?}");
            assert!((other.radius_m / (scale.radius_m * f) - 1.0).abs() < 1e-5, "{other:?}");
        }
    }

    #[test]
    fn cells_are_counted_once() {
        let points = [[0.01, 0.01, 0.01], [0.02, 0.03, 0.04], [0.11, 0.0, 0.0], [-0.01, 0.0, 0.0]]
            .map(|p: [f32; 3]| Point3::from(p));
        assert_eq!(occupied_cells(&points, 0.1), 3);
    }

    #[test]
    fn nothing_to_measure_is_none() {
        assert_eq!(SetScale::of(&[]), None);
        let one = [Point3::new(1.0f32, 2.0, 3.0)];
        assert_eq!(SetScale::of(&[&one, &[one[0], one[0]]]), None);
    }
}
