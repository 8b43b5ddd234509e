//! Geometry both views draw: the scene as a triangle mesh and the 1-2-5
//! exaggeration of error ellipses.

use cps::geom::{Primitive, Scene};
use nalgebra::{Point3, Vector3};

fn p32(p: &Point3<f64>) -> [f32; 3] {
    [p.x as f32, p.y as f32, p.z as f32]
}

/// The scene's surfaces as one triangle mesh (cylinders with 32 facets,
/// spheres as 16 × 32 facets).
pub fn scene_mesh(scene: &Scene) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut vertices: Vec<[f32; 3]> = Vec::new();
    let mut triangles = Vec::new();
    let mut quad = |vs: &mut Vec<[f32; 3]>, a: Point3<f64>, b: Point3<f64>, c: Point3<f64>, d: Point3<f64>| {
        let k = vs.len() as u32;
        vs.extend([p32(&a), p32(&b), p32(&c), p32(&d)]);
        triangles.push([k, k + 1, k + 2]);
        triangles.push([k, k + 2, k + 3]);
    };
    for (primitive, _) in scene.bvh().primitives() {
        match primitive {
            Primitive::Triangle([a, b, c]) => quad(&mut vertices, *a, *b, *c, *c),
            Primitive::Cylinder { a, b, radius_m } => {
                let axis = b - a;
                let u = axis.cross(&if axis.x.abs() < 0.9 * axis.norm() { Vector3::x() } else { Vector3::y() });
                let u = u.normalize() * *radius_m;
                let v = axis.normalize().cross(&u);
                let n = 32;
                let ring = |k: usize| {
                    let t = std::f64::consts::TAU * k as f64 / n as f64;
                    u * t.cos() + v * t.sin()
                };
                for k in 0..n {
                    let (r0, r1) = (ring(k), ring(k + 1));
                    quad(&mut vertices, a + r0, a + r1, b + r1, b + r0);
                }
            }
            Primitive::Sphere { center, radius_m } => {
                let (nu, nv) = (32, 16);
                let at = |i: usize, j: usize| {
                    let (phi, theta) =
                        (std::f64::consts::TAU * i as f64 / nu as f64, std::f64::consts::PI * j as f64 / nv as f64);
                    center + *radius_m * Vector3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
                };
                for i in 0..nu {
                    for j in 0..nv {
                        quad(&mut vertices, at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                    }
                }
            }
        }
    }
    (vertices, triangles)
}

/// The exaggeration for ellipses whose largest 95 % semi-major axis is
/// `largest_m`: a 1-2-5 number that draws it at most `room_m` long.
pub fn ellipse_scale(largest_m: f64, room_m: f64) -> f64 {
    if largest_m <= 0.0 || largest_m.is_nan() || room_m <= 0.0 {
        return 1.0;
    }
    let raw = room_m / largest_m;
    let decade = 10f64.powf(raw.log10().floor());
    let step = [5.0, 2.0, 1.0].into_iter().find(|m| m * decade <= raw).unwrap_or(1.0);
    (step * decade).max(f64::MIN_POSITIVE)
}

/// "1000", "20", "0.5".
pub fn ellipse_scale_name(k: f64) -> String {
    if k >= 1.0 { format!("{k:.0}") } else { format!("{k}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_is_a_1_2_5_number_that_fits_the_room() {
        assert_eq!(ellipse_scale(0.004, 1.8), 200.0);
        assert_eq!(ellipse_scale(0.04, 1.8), 20.0);
        assert_eq!(ellipse_scale(0.02, 10.0), 500.0);
        assert_eq!(ellipse_scale(3.0, 1.0), 0.2);
        assert_eq!(ellipse_scale(0.0, 1.0), 1.0);
        for largest in [1e-4, 3.3e-3, 0.07, 2.0] {
            let k = ellipse_scale(largest, 2.0);
            assert!(k * largest <= 2.0 && k * largest > 2.0 / 2.5 - 1e-12, "{largest}: ×{k}");
        }
    }

    #[test]
    fn the_scene_mesh_covers_every_primitive() {
        let scene = cps::geom::builtin("sewer").expect("sewer");
        let (v, t) = scene_mesh(&scene);
        assert!(!t.is_empty());
        assert!(t.iter().flatten().all(|&i| (i as usize) < v.len()));
        // Every vertex lies on the scene's surfaces (facets of a cylinder
        // have their vertices on it).
        for p in v.iter().step_by(7) {
            let d = scene.bvh().distance(&Point3::new(p[0], p[1], p[2]).cast()).0;
            assert!(d < 1e-4, "{p:?} is {d} m off the scene");
        }
    }
}
