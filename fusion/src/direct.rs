//! Direct transformation (seed 003): a scan goes straight into the world with
//! the CPS pose (x, y, z, θ), the tilt sensor's roll and pitch and the
//! `body_from_scanner` lever arm:
//! `world_from_scanner = T(x, y, z) · Rz(θ) · Ry(pitch) · Rx(roll) · body_from_scanner`.

use cps::ParentPose;
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use rayon::prelude::*;
use scanner::Tilt;

/// Points per parallel task: big enough to amortise scheduling, small enough
/// to balance two cores on a 10⁵-point scan.
const CHUNK: usize = 16 * 1024;

/// `world_from_scanner` from a CPS pose, the tilt and the lever arm.
pub fn world_from_scanner(pose: &ParentPose, tilt: &Tilt, body_from_scanner: &Isometry3<f64>) -> Isometry3<f64> {
    tilt.world_from_body(pose) * body_from_scanner
}

/// Transforms `points` by `a_from_b` into `out` (same length), in parallel.
/// The rotation is applied in f32 to the (local, short) scanner coordinates;
/// the translation is added in f64 and rounded once, so world coordinates of
/// kilometre-sized sites keep f32's full resolution.
///
/// # Panics
/// Never: `out` is truncated or extended to `points.len()` first.
pub fn transform_into(points: &[Point3<f32>], a_from_b: &Isometry3<f64>, out: &mut Vec<Point3<f32>>) {
    out.resize(points.len(), Point3::origin());
    let r: Matrix3<f32> = a_from_b.rotation.to_rotation_matrix().matrix().cast();
    let t: Vector3<f64> = a_from_b.translation.vector;
    out.par_chunks_mut(CHUNK).zip(points.par_chunks(CHUNK)).for_each(|(dst, src)| {
        for (o, p) in dst.iter_mut().zip(src) {
            let q = r * p.coords;
            *o = Point3::new(
                (f64::from(q.x) + t.x) as f32,
                (f64::from(q.y) + t.y) as f32,
                (f64::from(q.z) + t.z) as f32,
            );
        }
    });
}

/// `points` transformed by `a_from_b` (see [`transform_into`]).
pub fn transform(points: &[Point3<f32>], a_from_b: &Isometry3<f64>) -> Vec<Point3<f32>> {
    let mut out = Vec::with_capacity(points.len());
    transform_into(points, a_from_b, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};

    use super::*;

    /// Against an f64 reference: error within f32 rounding of the result.
    #[test]
    fn matches_f64_reference() {
        let pose = ParentPose::new(812.25, -433.5, 12.75, 2.1);
        let tilt = Tilt { roll_rad: 0.01, pitch_rad: -0.02 };
        let lever =
            Isometry3::from_parts(Translation3::new(0.1, -0.05, 0.4), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3));
        let iso = world_from_scanner(&pose, &tilt, &lever);
        let pts: Vec<Point3<f32>> = (0..100_000)
            .map(|i| {
                let f = i as f32 * 0.001;
                Point3::new(30.0 * f.sin(), 20.0 * (1.3 * f).cos(), 5.0 * (0.7 * f).sin())
            })
            .collect();
        let out = transform(&pts, &iso);
        for (p, o) in pts.iter().zip(&out) {
            let exact = iso * p.cast::<f64>();
            // f32 rotation of ≤ 40 m coordinates (≤ 4 ulp of 40 m ≈ 1.5e-5 m) + one rounding at ~1 km (3e-5 m).
            assert!((exact - o.cast::<f64>()).amax() < 6e-5, "{exact} vs {o}");
        }
        // Composition order: the lever arm is applied in the body frame.
        let body = tilt.world_from_body(&pose);
        assert!((iso.translation.vector - (body * Point3::new(0.1, -0.05, 0.4)).coords).norm() < 1e-12);
    }
}
