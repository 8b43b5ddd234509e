//! Surface primitives: triangles, finite open cylinders and spheres. Every
//! surface is two-sided, so a box seen from inside (a hall) and from outside
//! (a pillar) is the same six rectangles, and a cylinder is a pipe's inside
//! wall as well as a column's outside.

use nalgebra::{Point3, Vector3};

use super::{Aabb, Ray};

/// One surface primitive in world coordinates (metres).
#[derive(Debug, Clone, PartialEq)]
pub enum Primitive {
    /// A triangle with vertices `[a, b, c]`.
    Triangle([Point3<f64>; 3]),
    /// The lateral surface of a finite cylinder with axis from `a` to `b`
    /// (no end caps; add discs as polygons if needed).
    Cylinder {
        /// Start of the axis.
        a: Point3<f64>,
        /// End of the axis.
        b: Point3<f64>,
        /// Radius, metres.
        radius_m: f64,
    },
    /// A sphere.
    Sphere {
        /// Centre.
        center: Point3<f64>,
        /// Radius, metres.
        radius_m: f64,
    },
}

/// A ray's hit on one primitive: distance along the (unit) ray and the
/// surface normal, oriented against the ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrimitiveHit {
    /// Distance from the ray origin, metres.
    pub distance_m: f64,
    /// Unit normal at the hit, facing the ray's origin.
    pub normal: Vector3<f64>,
}

fn facing(normal: Vector3<f64>, direction: &Vector3<f64>) -> Vector3<f64> {
    if normal.dot(direction) > 0.0 { -normal } else { normal }
}

impl Primitive {
    /// The primitive's bounding box.
    pub fn bounds(&self) -> Aabb {
        match self {
            Primitive::Triangle([a, b, c]) => Aabb::from_point(*a).grown(b).grown(c),
            Primitive::Cylinder { a, b, radius_m } => {
                // Tight per-axis extent of the two end circles: r·√(1 − u_i²).
                let u = (b - a).normalize();
                let e = Vector3::new(
                    radius_m * (1.0 - u.x * u.x).max(0.0).sqrt(),
                    radius_m * (1.0 - u.y * u.y).max(0.0).sqrt(),
                    radius_m * (1.0 - u.z * u.z).max(0.0).sqrt(),
                );
                Aabb { min: a.inf(b) - e, max: a.sup(b) + e }
            }
            Primitive::Sphere { center, radius_m } => {
                let e = Vector3::repeat(*radius_m);
                Aabb { min: center - e, max: center + e }
            }
        }
    }

    /// The centre used to sort primitives into the BVH.
    pub fn centroid(&self) -> Point3<f64> {
        self.bounds().center()
    }

    /// The nearest intersection with `t_min < t < t_max`, if any.
    pub fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<PrimitiveHit> {
        match self {
            Primitive::Triangle(v) => intersect_triangle(v, ray, t_min, t_max),
            Primitive::Cylinder { a, b, radius_m } => intersect_cylinder(a, b, *radius_m, ray, t_min, t_max),
            Primitive::Sphere { center, radius_m } => intersect_sphere(center, *radius_m, ray, t_min, t_max),
        }
    }

    /// Unsigned distance from `p` to the surface, metres.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        match self {
            Primitive::Triangle(v) => (p - closest_on_triangle(v, p)).norm(),
            Primitive::Cylinder { a, b, radius_m } => {
                let axis = b - a;
                let h = axis.norm();
                let u = axis / h;
                let ap = p - a;
                let s = ap.dot(&u);
                let rho = (ap - u * s).norm();
                let along = s - s.clamp(0.0, h);
                (along * along + (rho - radius_m) * (rho - radius_m)).sqrt()
            }
            Primitive::Sphere { center, radius_m } => ((p - center).norm() - radius_m).abs(),
        }
    }
}

/// Möller–Trumbore ray–triangle intersection.
fn intersect_triangle(v: &[Point3<f64>; 3], ray: &Ray, t_min: f64, t_max: f64) -> Option<PrimitiveHit> {
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let p = ray.direction.cross(&e2);
    let det = e1.dot(&p);
    if det.abs() < 1e-14 {
        return None;
    }
    let inv = 1.0 / det;
    let s = ray.origin - v[0];
    let u = s.dot(&p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(&e1);
    let w = ray.direction.dot(&q) * inv;
    if w < 0.0 || u + w > 1.0 {
        return None;
    }
    let t = e2.dot(&q) * inv;
    (t > t_min && t < t_max)
        .then(|| PrimitiveHit { distance_m: t, normal: facing(e1.cross(&e2).normalize(), &ray.direction) })
}

/// Ray against the lateral surface |x⊥| = r, 0 ≤ (x − a)·u ≤ h.
fn intersect_cylinder(
    a: &Point3<f64>,
    b: &Point3<f64>,
    r: f64,
    ray: &Ray,
    t_min: f64,
    t_max: f64,
) -> Option<PrimitiveHit> {
    let axis = b - a;
    let h = axis.norm();
    let u = axis / h;
    let o = ray.origin - a;
    let d_perp = ray.direction - u * ray.direction.dot(&u);
    let o_perp = o - u * o.dot(&u);
    let qa = d_perp.norm_squared();
    if qa < 1e-18 {
        return None; // ray parallel to the axis
    }
    let qb = o_perp.dot(&d_perp);
    let qc = o_perp.norm_squared() - r * r;
    let disc = qb * qb - qa * qc;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    for t in [(-qb - sq) / qa, (-qb + sq) / qa] {
        if t <= t_min || t >= t_max {
            continue;
        }
        let s = (o + ray.direction * t).dot(&u);
        if (0.0..=h).contains(&s) {
            let normal = (o_perp + d_perp * t) / r;
            return Some(PrimitiveHit { distance_m: t, normal: facing(normal, &ray.direction) });
        }
    }
    None
}

fn intersect_sphere(c: &Point3<f64>, r: f64, ray: &Ray, t_min: f64, t_max: f64) -> Option<PrimitiveHit> {
    let oc = ray.origin - c;
    let qb = oc.dot(&ray.direction);
    let qc = oc.norm_squared() - r * r;
    let disc = qb * qb - qc;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    [-qb - sq, -qb + sq]
        .into_iter()
        .find(|t| *t > t_min && *t < t_max)
        .map(|t| PrimitiveHit { distance_m: t, normal: facing((oc + ray.direction * t) / r, &ray.direction) })
}

/// Closest point on a triangle (Ericson, Real-Time Collision Detection §5.1.5).
fn closest_on_triangle(v: &[Point3<f64>; 3], p: &Point3<f64>) -> Point3<f64> {
    let (a, b, c) = (v[0], v[1], v[2]);
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: [f64; 3], d: [f64; 3]) -> Ray {
        Ray::new(Point3::from(o), Vector3::from(d)).expect("valid ray")
    }

    #[test]
    fn triangle_hit_and_miss() {
        let t =
            Primitive::Triangle([Point3::new(0.0, 0.0, 1.0), Point3::new(2.0, 0.0, 1.0), Point3::new(0.0, 2.0, 1.0)]);
        let hit = t.intersect(&ray([0.5, 0.5, 0.0], [0.0, 0.0, 1.0]), 0.0, f64::INFINITY).expect("hit");
        assert!((hit.distance_m - 1.0).abs() < 1e-12);
        assert!((hit.normal - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        assert!(t.intersect(&ray([1.5, 1.5, 0.0], [0.0, 0.0, 1.0]), 0.0, f64::INFINITY).is_none());
        assert!(t.intersect(&ray([0.5, 0.5, 0.0], [0.0, 0.0, 1.0]), 0.0, 0.9).is_none());
        assert!((t.distance(&Point3::new(0.5, 0.5, 3.0)) - 2.0).abs() < 1e-12);
        assert!((t.distance(&Point3::new(-1.0, 0.0, 1.0)) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn cylinder_from_inside_and_outside() {
        let c = Primitive::Cylinder { a: Point3::new(0.0, 0.0, 0.0), b: Point3::new(10.0, 0.0, 0.0), radius_m: 0.5 };
        // From the axis, any perpendicular ray hits at r.
        let d = Vector3::new(0.3, 0.4, -0.5).normalize();
        let hit = c.intersect(&ray([5.0, 0.0, 0.0], d.into()), 0.0, f64::INFINITY).expect("hit");
        let p = Point3::new(5.0, 0.0, 0.0) + d * hit.distance_m;
        assert!(((p.y * p.y + p.z * p.z).sqrt() - 0.5).abs() < 1e-12);
        // From outside, the near wall is hit first.
        let hit = c.intersect(&ray([5.0, 0.0, 3.0], [0.0, 0.0, -1.0]), 0.0, f64::INFINITY).expect("hit");
        assert!((hit.distance_m - 2.5).abs() < 1e-12);
        assert!((hit.normal - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-12);
        // Beyond the end it misses.
        assert!(c.intersect(&ray([11.0, 0.0, 3.0], [0.0, 0.0, -1.0]), 0.0, f64::INFINITY).is_none());
        assert!((c.distance(&Point3::new(5.0, 0.2, 0.0)) - 0.3).abs() < 1e-12);
        assert!((c.distance(&Point3::new(13.0, 0.0, 4.5)) - 5.0).abs() < 1e-12);
        let b = c.bounds();
        assert!((b.min - Point3::new(0.0, -0.5, -0.5)).norm() < 1e-12);
        assert!((b.max - Point3::new(10.0, 0.5, 0.5)).norm() < 1e-12);
    }

    #[test]
    fn sphere_hit_from_outside_and_inside() {
        let s = Primitive::Sphere { center: Point3::new(0.0, 0.0, 0.0), radius_m: 1.0 };
        let out = s.intersect(&ray([-3.0, 0.0, 0.0], [1.0, 0.0, 0.0]), 0.0, f64::INFINITY).expect("hit");
        assert!((out.distance_m - 2.0).abs() < 1e-12);
        let inside = s.intersect(&ray([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]), 0.0, f64::INFINITY).expect("hit");
        assert!((inside.distance_m - 1.0).abs() < 1e-12);
        assert!((s.distance(&Point3::new(0.0, 0.0, 0.25)) - 0.75).abs() < 1e-12);
    }

    /// The closest point is really closest: no random point on the triangle
    /// is nearer.
    #[test]
    fn closest_point_beats_samples() {
        let v = [Point3::new(0.0, 0.0, 0.0), Point3::new(3.0, 0.5, 0.2), Point3::new(1.0, 2.0, -0.4)];
        let t = Primitive::Triangle(v);
        for k in 0..50 {
            let f = k as f64;
            let p = Point3::new((f * 0.37).sin() * 4.0, (f * 0.91).cos() * 4.0, (f * 1.3).sin() * 2.0);
            let d = t.distance(&p);
            for i in 0..=20 {
                for j in 0..=(20 - i) {
                    let (u, w) = (i as f64 / 20.0, j as f64 / 20.0);
                    let q = v[0] + (v[1] - v[0]) * u + (v[2] - v[0]) * w;
                    assert!(d <= (p - q).norm() + 1e-12);
                }
            }
        }
    }
}
