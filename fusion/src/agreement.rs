//! How well a set's scans agree at given poses, as one number that two
//! registrations of the same scans can be compared by: every reduced point
//! of every scan pays its squared point-to-plane distance to the nearest
//! point of the other scans, truncated at the correspondence distance τ,
//! and a point with no other scan's point within τ pays τ² (the truncated
//! least-squares cost of TEASER++ and of robust registration's
//! evaluation). Overlap counts, and so does fit.
//!
//! Measured on small_gicp's outdoor frame cut into four 150° wedges
//! (issue 38: narrow overlaps along a street), registered from starts
//! 0.1 m / 2° off: right registrations cost 0.0148–0.0150 m² a point,
//! those the coarse stage dragged 1.6–27 m off 0.033–0.046 m² (2.2–3.1×),
//! where two right registrations agree to the sixth digit
//! ([`crate::scanset::RESTART_RATIO`]).

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use crate::candidates::Occupancy;
use crate::multiview::Prepared;

/// Scans each scan's points are compared with: the best-ranked by the
/// cells they share with it.
const PARTNERS: usize = 8;

/// The mean truncated cost of every reduced point of `prepared` at `poses`
/// against the other scans' models within `tau_m` (see the module docs),
/// square metres. Zero for fewer than two scans.
pub(crate) fn disagreement(prepared: &[Prepared], poses: &[Isometry3<f64>], tau_m: f64) -> f64 {
    if prepared.len() < 2 {
        return 0.0;
    }
    let sources: Vec<&[Point3<f32>]> = prepared.iter().map(|p| p.source.as_slice()).collect();
    let occupancy = Occupancy::new(&sources, poses, 2.0 * tau_m);
    let cap = tau_m * tau_m;
    let (cost, points) = (0..prepared.len())
        .into_par_iter()
        .map(|i| {
            let partners: Vec<(usize, Isometry3<f32>)> = occupancy
                .ranked(i, |_| true, PARTNERS)
                .into_iter()
                .map(|j| (j, (poses[j].inverse() * poses[i]).cast::<f32>()))
                .collect();
            let cost: f64 = prepared[i]
                .source
                .iter()
                .map(|p| {
                    partners
                        .iter()
                        .map(|(j, j_from_i)| {
                            let target = &prepared[*j].local;
                            let q = j_from_i * p;
                            let (k, d2) = target.nearest_from(&[q.x, q.y, q.z], u32::MAX);
                            if d2 > cap {
                                return cap;
                            }
                            if !target.has_normals() {
                                return d2;
                            }
                            let t = target.points[k];
                            let d = nalgebra::Vector3::new(
                                f64::from(q.x - t[0]),
                                f64::from(q.y - t[1]),
                                f64::from(q.z - t[2]),
                            );
                            d.dot(&target.normal(k)).powi(2).min(cap)
                        })
                        .fold(cap, f64::min)
                })
                .sum();
            (cost, prepared[i].source.len())
        })
        // Summed in scan order, so that a run gives the same cost every
        // time (a parallel reduction's order follows the threads').
        .collect::<Vec<(f64, usize)>>()
        .into_iter()
        .fold((0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    if points == 0 { 0.0 } else { cost / points as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::icp::Target;

    fn prepared(points: Vec<Point3<f32>>) -> Prepared {
        Prepared { local: Target::new(&points, 8).expect("target"), source: points }
    }

    /// A room corner: floor and two walls, 5 cm grid.
    fn corner() -> Vec<Point3<f32>> {
        let mut v = Vec::new();
        for a in 0..40 {
            for b in 0..40 {
                let (a, b) = (a as f32 * 0.05, b as f32 * 0.05);
                v.push(Point3::new(a, b, 0.0));
                v.push(Point3::new(a, 0.0, b + 0.025));
                v.push(Point3::new(0.0, a + 0.025, b + 0.025));
            }
        }
        v
    }

    #[test]
    fn a_right_registration_costs_less_than_a_slid_one() {
        let scans = vec![prepared(corner()), prepared(corner())];
        let right = [Isometry3::identity(), Isometry3::identity()];
        let exact = disagreement(&scans, &right, 0.2);
        assert!(exact < 1e-12, "the same points at the same pose: {exact}");
        // Slid by 0.1 m along the floor and one wall: they still agree;
        // the other wall is 0.1 m off its twin, so a third of the points
        // pay 0.1² each: 0.0033.
        let slid = [Isometry3::identity(), Isometry3::translation(0.1, 0.0, 0.0)];
        let off = disagreement(&scans, &slid, 0.2);
        assert!(off > 0.003 && off < 0.004, "{off}");
        // Truncated: 2 m away, every point pays τ² (no partner cell).
        let apart = [Isometry3::identity(), Isometry3::translation(0.0, 0.0, 5.0)];
        assert!((disagreement(&scans, &apart, 0.2) - 0.04).abs() < 1e-12);
        assert_eq!(disagreement(&scans[..1], &right[..1], 0.2), 0.0);
    }
}
