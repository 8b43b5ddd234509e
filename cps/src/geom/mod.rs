//! Scene geometry shared by the planner (line of sight) and the simulator
//! (ray casting): surface primitives, a bounding-volume hierarchy, scene
//! building blocks (polygons, boxes, cylinders, walls with openings), the
//! built-in scenes and the scene file format.
//!
//! Principal types: [`Scene`] (primitives + [`Bvh`]), [`SceneBuilder`],
//! [`Ray`], [`Hit`]. World frame: right-handed, z up, metres.

mod builder;
mod builtin;
mod bvh;
mod shape;
mod spec;

pub use builder::{Opening, SceneBuilder};
pub use builtin::{BUILTIN_SCENES, SEWER_BRICK_CENTER, SEWER_BRICK_SIZE_M, SEWER_RADIUS_M, builtin};
pub use bvh::Bvh;
pub use shape::{Primitive, PrimitiveHit};
pub use spec::{SceneSpec, parse_scene_toml};

use nalgebra::{Point3, Vector3};

use crate::error::{CpsError, Result};

/// A ray with a unit direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Origin, world frame.
    pub origin: Point3<f64>,
    /// Unit direction.
    pub direction: Vector3<f64>,
    inv_direction: Vector3<f64>,
}

impl Ray {
    /// A ray from `origin` along `direction` (normalised here). Fails on a
    /// zero or non-finite direction.
    pub fn new(origin: Point3<f64>, direction: Vector3<f64>) -> Result<Self> {
        let n = direction.norm();
        if !(n.is_finite() && n > 0.0 && origin.coords.iter().all(|c| c.is_finite())) {
            return Err(CpsError::NonFinite { what: "ray origin/direction".into(), value: n });
        }
        let direction = direction / n;
        Ok(Self { origin, direction, inv_direction: direction.map(|c| 1.0 / c) })
    }

    /// The point at distance `t` along the ray.
    pub fn at(&self, t: f64) -> Point3<f64> {
        self.origin + self.direction * t
    }
}

/// An axis-aligned bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Point3<f64>,
    /// Upper corner.
    pub max: Point3<f64>,
}

impl Aabb {
    /// The box holding one point.
    pub fn from_point(p: Point3<f64>) -> Self {
        Self { min: p, max: p }
    }

    /// The empty box (grows from nothing).
    pub fn empty() -> Self {
        Self {
            min: Point3::from(Vector3::repeat(f64::INFINITY)),
            max: Point3::from(Vector3::repeat(f64::NEG_INFINITY)),
        }
    }

    /// This box grown to hold `p`.
    pub fn grown(self, p: &Point3<f64>) -> Self {
        Self { min: self.min.inf(p), max: self.max.sup(p) }
    }

    /// The union of two boxes.
    pub fn union(self, o: &Aabb) -> Self {
        Self { min: self.min.inf(&o.min), max: self.max.sup(&o.max) }
    }

    /// The centre.
    pub fn center(&self) -> Point3<f64> {
        nalgebra::center(&self.min, &self.max)
    }

    /// Edge lengths.
    pub fn extent(&self) -> Vector3<f64> {
        self.max - self.min
    }

    /// Slab test: the entry distance if the ray meets the box within
    /// `(t_min, t_max)`.
    pub fn hit(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<f64> {
        let mut t0 = t_min;
        let mut t1 = t_max;
        for i in 0..3 {
            let a = (self.min[i] - ray.origin[i]) * ray.inv_direction[i];
            let b = (self.max[i] - ray.origin[i]) * ray.inv_direction[i];
            let (near, far) = if a <= b { (a, b) } else { (b, a) };
            // NaN (0·∞ on a slab boundary) compares false and leaves t0/t1 as they are.
            if near > t0 {
                t0 = near;
            }
            if far < t1 {
                t1 = far;
            }
            if t0 > t1 {
                return None;
            }
        }
        Some(t0)
    }

    /// Distance from `p` to the box (0 inside).
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        let d = (self.min - p).sup(&Vector3::zeros()).sup(&(p - self.max));
        d.norm()
    }
}

/// A ray's nearest hit in a scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the ray, metres.
    pub distance_m: f64,
    /// The hit point, world frame.
    pub point: Point3<f64>,
    /// Unit surface normal facing the ray's origin.
    pub normal: Vector3<f64>,
    /// Index of the named scene object the surface belongs to
    /// ([`Scene::object_name`]).
    pub object: usize,
}

/// A scene: named objects made of primitives, with a BVH for ray casting.
#[derive(Debug, Clone)]
pub struct Scene {
    name: String,
    objects: Vec<String>,
    bvh: Bvh,
}

/// Clearance kept at both ends of a line-of-sight query, metres, so that a
/// prism or instrument touching a surface does not block its own sight line.
pub const LINE_OF_SIGHT_CLEARANCE_M: f64 = 1e-4;

impl Scene {
    pub(crate) fn new(name: String, objects: Vec<String>, primitives: Vec<(Primitive, usize)>) -> Self {
        Self { name, objects, bvh: Bvh::build(primitives) }
    }

    /// The scene's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Name of object `i` (as given to the builder or in the scene file).
    pub fn object_name(&self, i: usize) -> &str {
        self.objects.get(i).map_or("?", String::as_str)
    }

    /// Number of primitives.
    pub fn primitive_count(&self) -> usize {
        self.bvh.len()
    }

    /// Bounding box of the whole scene.
    pub fn bounds(&self) -> Aabb {
        self.bvh.bounds()
    }

    /// The BVH (for inspection and benchmarks).
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// The nearest surface along `ray` within `max_m`, if any.
    pub fn cast(&self, ray: &Ray, max_m: f64) -> Option<Hit> {
        self.cast_between(ray, 0.0, max_m)
    }

    fn cast_between(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<Hit> {
        self.bvh.cast(ray, t_min, t_max).map(|(h, object)| Hit {
            distance_m: h.distance_m,
            point: ray.at(h.distance_m),
            normal: h.normal,
            object,
        })
    }

    /// The first surface between `from` and `to`, or `None` when the sight
    /// line is clear (ends excluded by [`LINE_OF_SIGHT_CLEARANCE_M`]).
    pub fn obstruction(&self, from: &Point3<f64>, to: &Point3<f64>) -> Option<Hit> {
        let d = to - from;
        let len = d.norm();
        if len <= 2.0 * LINE_OF_SIGHT_CLEARANCE_M {
            return None;
        }
        let ray = Ray::new(*from, d).ok()?;
        self.cast_between(&ray, LINE_OF_SIGHT_CLEARANCE_M, len - LINE_OF_SIGHT_CLEARANCE_M)
    }

    /// True when nothing lies between `from` and `to`.
    pub fn line_of_sight(&self, from: &Point3<f64>, to: &Point3<f64>) -> bool {
        self.obstruction(from, to).is_none()
    }

    /// Unsigned distance from `p` to the nearest surface, with that surface's
    /// object index.
    pub fn distance(&self, p: &Point3<f64>) -> (f64, usize) {
        self.bvh.distance(p)
    }

    /// The objects whose closed surface encloses `p` (by the parity of the
    /// crossings of a ray from `p` out of the scene, per object), sorted.
    /// The free space a team works in is inside the room of an indoor scene
    /// and outside everything outdoors: compare with a point known free.
    pub fn enclosing(&self, p: &Point3<f64>) -> Vec<usize> {
        // An oblique direction, so that the ray does not run along a face.
        let Ok(ray) = Ray::new(*p, Vector3::new(0.2134, 0.4471, 0.8688)) else { return Vec::new() };
        let far = (self.bounds().extent().norm() + (p - self.bounds().center()).norm()) * 2.0 + 1.0;
        let mut crossings: std::collections::BTreeMap<usize, usize> = std::collections::BTreeMap::new();
        let mut t = 0.0;
        // Each cast moves past one crossing; a scene has finitely many.
        for _ in 0..10_000 {
            let Some(hit) = self.cast_between(&ray, t + 1e-7, far) else { break };
            *crossings.entry(hit.object).or_default() += 1;
            t = hit.distance_m;
        }
        crossings.into_iter().filter(|(_, n)| n % 2 == 1).map(|(o, _)| o).collect()
    }
}
