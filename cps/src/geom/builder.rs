//! Building blocks of a scene: polygons, boxes, cylinders, spheres and
//! vertical walls with rectangular openings, each checked and turned into
//! primitives.

use nalgebra::{Point2, Point3, Rotation3, Vector3};

use super::{Primitive, Scene};
use crate::error::{CpsError, Result};

/// A rectangular opening (door, window) in one segment of a wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Opening {
    /// Index of the wall segment (0 = from path point 0 to 1).
    pub segment: usize,
    /// Start of the opening along the segment, metres from its first point.
    pub from_m: f64,
    /// End of the opening along the segment, metres.
    pub to_m: f64,
    /// Bottom of the opening, metres (world z).
    pub z_min_m: f64,
    /// Top of the opening, metres (world z).
    pub z_max_m: f64,
}

/// Collects named objects and builds a [`Scene`].
#[derive(Debug, Clone, Default)]
pub struct SceneBuilder {
    objects: Vec<String>,
    primitives: Vec<(Primitive, usize)>,
}

fn out_of_range(what: impl Into<String>, value: f64, expected: &str) -> CpsError {
    CpsError::OutOfRange { what: what.into(), value, expected: expected.into() }
}

/// Finite, and within ±[`crate::MAX_COORDINATE_M`] (sizes and positions
/// alike).
fn finite(what: &str, values: &[f64]) -> Result<()> {
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(CpsError::NonFinite { what: what.into(), value: *v });
    }
    match values.iter().find(|v| v.abs() > crate::MAX_COORDINATE_M) {
        Some(v) => Err(out_of_range(what, *v, &format!("within ±{:e} m", crate::MAX_COORDINATE_M))),
        None => Ok(()),
    }
}

fn positive(what: &str, value: f64) -> Result<()> {
    finite(what, &[value])?;
    if value > 0.0 { Ok(()) } else { Err(out_of_range(what, value, "> 0")) }
}

impl SceneBuilder {
    /// An empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of primitives so far.
    pub fn primitive_count(&self) -> usize {
        self.primitives.len()
    }

    fn object(&mut self, name: &str) -> usize {
        self.objects.push(name.to_string());
        self.objects.len() - 1
    }

    fn triangle(&mut self, object: usize, a: Point3<f64>, b: Point3<f64>, c: Point3<f64>) {
        self.primitives.push((Primitive::Triangle([a, b, c]), object));
    }

    fn quad(&mut self, object: usize, q: [Point3<f64>; 4]) {
        self.triangle(object, q[0], q[1], q[2]);
        self.triangle(object, q[0], q[2], q[3]);
    }

    /// A planar polygon (convex or not, no holes), vertices in order.
    pub fn polygon(&mut self, name: &str, vertices: &[Point3<f64>]) -> Result<()> {
        let what = format!("polygon '{name}'");
        if vertices.len() < 3 {
            return Err(out_of_range(format!("{what}: vertex count"), vertices.len() as f64, "≥ 3"));
        }
        for v in vertices {
            finite(&format!("{what}: vertex"), v.coords.as_slice())?;
        }
        // Newell's normal, then planarity.
        let mut n = Vector3::zeros();
        for (i, a) in vertices.iter().enumerate() {
            let b = vertices[(i + 1) % vertices.len()];
            n += Vector3::new((a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y));
        }
        let area2 = n.norm();
        if area2 < 1e-12 {
            return Err(CpsError::DegenerateGeometry {
                what: format!("{what} has zero area"),
                condition: f64::INFINITY,
            });
        }
        let n = n / area2;
        let size = vertices.iter().map(|v| (v - vertices[0]).norm()).fold(0.0, f64::max);
        let off_plane = vertices.iter().map(|v| (v - vertices[0]).dot(&n).abs()).fold(0.0, f64::max);
        if off_plane > 1e-6 * size.max(1.0) {
            return Err(out_of_range(
                format!("{what}: distance of a vertex from the polygon's plane (m)"),
                off_plane,
                "0 (planar polygon)",
            ));
        }
        // Project on the plane's dominant axes, counter-clockwise.
        let drop = n.iamax();
        let (i, j) = match drop {
            0 => (1, 2),
            1 => (2, 0),
            _ => (0, 1),
        };
        let flat: Vec<Point2<f64>> = vertices.iter().map(|v| Point2::new(v[i], v[j])).collect();
        let triangles = ear_clip(&flat).ok_or_else(|| CpsError::DegenerateGeometry {
            what: format!("{what} is self-intersecting"),
            condition: f64::INFINITY,
        })?;
        let object = self.object(name);
        for [a, b, c] in triangles {
            self.triangle(object, vertices[a], vertices[b], vertices[c]);
        }
        Ok(())
    }

    /// A box with centre, full edge lengths and a rotation about z.
    pub fn cuboid(&mut self, name: &str, center: Point3<f64>, size_m: Vector3<f64>, yaw_rad: f64) -> Result<()> {
        self.oriented_cuboid(name, center, size_m, [0.0, 0.0, yaw_rad])
    }

    /// A box with centre, full edge lengths and orientation
    /// `[roll, pitch, yaw]` (rad): `world_from_box = Rz(yaw)·Ry(pitch)·Rx(roll)`.
    pub fn oriented_cuboid(
        &mut self,
        name: &str,
        center: Point3<f64>,
        size_m: Vector3<f64>,
        rpy_rad: [f64; 3],
    ) -> Result<()> {
        finite(&format!("box '{name}': centre"), center.coords.as_slice())?;
        for k in 0..3 {
            positive(&format!("box '{name}': size_m[{k}]"), size_m[k])?;
        }
        finite(&format!("box '{name}': orientation"), &rpy_rad)?;
        let r = Rotation3::from_euler_angles(rpy_rad[0], rpy_rad[1], rpy_rad[2]);
        let h = size_m / 2.0;
        let corner = |sx: f64, sy: f64, sz: f64| center + r * Vector3::new(sx * h.x, sy * h.y, sz * h.z);
        let c: Vec<Point3<f64>> = (0..8)
            .map(|k| {
                corner(
                    if k & 1 == 0 { -1.0 } else { 1.0 },
                    if k & 2 == 0 { -1.0 } else { 1.0 },
                    if k & 4 == 0 { -1.0 } else { 1.0 },
                )
            })
            .collect();
        let object = self.object(name);
        for face in [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]] {
            self.quad(object, face.map(|k| c[k]));
        }
        Ok(())
    }

    /// The lateral surface of a cylinder from `a` to `b` (a pipe's wall or a
    /// round pillar).
    pub fn cylinder(&mut self, name: &str, a: Point3<f64>, b: Point3<f64>, radius_m: f64) -> Result<()> {
        finite(&format!("cylinder '{name}': a"), a.coords.as_slice())?;
        finite(&format!("cylinder '{name}': b"), b.coords.as_slice())?;
        positive(&format!("cylinder '{name}': radius_m"), radius_m)?;
        if (b - a).norm() < 1e-9 {
            return Err(CpsError::CoincidentPoints {
                what: format!("cylinder '{name}' axis ends"),
                separation_m: (b - a).norm(),
            });
        }
        let object = self.object(name);
        self.primitives.push((Primitive::Cylinder { a, b, radius_m }, object));
        Ok(())
    }

    /// A sphere.
    pub fn sphere(&mut self, name: &str, center: Point3<f64>, radius_m: f64) -> Result<()> {
        finite(&format!("sphere '{name}': centre"), center.coords.as_slice())?;
        positive(&format!("sphere '{name}': radius_m"), radius_m)?;
        let object = self.object(name);
        self.primitives.push((Primitive::Sphere { center, radius_m }, object));
        Ok(())
    }

    /// Vertical walls along a 2D path from `z_min_m` to `z_max_m` (closed
    /// back to the first point when `closed`), with rectangular openings.
    pub fn wall(
        &mut self,
        name: &str,
        path: &[Point2<f64>],
        closed: bool,
        z_min_m: f64,
        z_max_m: f64,
        openings: &[Opening],
    ) -> Result<()> {
        let what = format!("wall '{name}'");
        if path.len() < 2 {
            return Err(out_of_range(format!("{what}: path point count"), path.len() as f64, "≥ 2"));
        }
        finite(&format!("{what}: z range"), &[z_min_m, z_max_m])?;
        if z_max_m <= z_min_m {
            return Err(out_of_range(format!("{what}: z_max_m"), z_max_m, &format!("> z_min_m = {z_min_m}")));
        }
        let n_seg = if closed { path.len() } else { path.len() - 1 };
        let mut segments = Vec::with_capacity(n_seg);
        for s in 0..n_seg {
            let (p, q) = (path[s], path[(s + 1) % path.len()]);
            finite(&format!("{what}: path point"), &[p.x, p.y, q.x, q.y])?;
            let len = (q - p).norm();
            if len < 1e-9 {
                return Err(CpsError::CoincidentPoints {
                    what: format!("{what}: segment {s} ends"),
                    separation_m: len,
                });
            }
            segments.push((p, q, len));
        }
        for (k, o) in openings.iter().enumerate() {
            let w = format!("{what}: opening {k}");
            finite(&w, &[o.from_m, o.to_m, o.z_min_m, o.z_max_m])?;
            let Some(&(_, _, len)) = segments.get(o.segment) else {
                return Err(out_of_range(
                    format!("{w}: segment"),
                    o.segment as f64,
                    &format!("< {n_seg} (number of segments)"),
                ));
            };
            if !(0.0 <= o.from_m && o.from_m < o.to_m && o.to_m <= len) {
                return Err(out_of_range(
                    format!("{w}: to_m"),
                    o.to_m,
                    &format!("0 ≤ from_m ({}) < to_m ≤ segment length {len:.3} m", o.from_m),
                ));
            }
            if !(z_min_m <= o.z_min_m && o.z_min_m < o.z_max_m && o.z_max_m <= z_max_m) {
                return Err(out_of_range(
                    format!("{w}: z_max_m"),
                    o.z_max_m,
                    &format!("z_min_m ≤ opening z_min_m ({}) < z_max_m ≤ {z_max_m}", o.z_min_m),
                ));
            }
        }
        let object = self.object(name);
        for (s, &(p, q, len)) in segments.iter().enumerate() {
            let mut ops: Vec<&Opening> = openings.iter().filter(|o| o.segment == s).collect();
            ops.sort_by(|a, b| a.from_m.total_cmp(&b.from_m));
            if let Some(w) = ops.windows(2).find(|w| w[1].from_m < w[0].to_m) {
                return Err(out_of_range(
                    format!("{what}: segment {s}: opening from_m"),
                    w[1].from_m,
                    &format!("≥ {} (openings must not overlap)", w[0].to_m),
                ));
            }
            let dir = (q - p) / len;
            let at = |t: f64, z: f64| Point3::new(p.x + dir.x * t, p.y + dir.y * t, z);
            let mut rect = |t0: f64, t1: f64, z0: f64, z1: f64| {
                if t1 - t0 > 1e-9 && z1 - z0 > 1e-9 {
                    self.quad(object, [at(t0, z0), at(t1, z0), at(t1, z1), at(t0, z1)]);
                }
            };
            let mut t = 0.0;
            for o in ops {
                rect(t, o.from_m, z_min_m, z_max_m);
                rect(o.from_m, o.to_m, z_min_m, o.z_min_m);
                rect(o.from_m, o.to_m, o.z_max_m, z_max_m);
                t = o.to_m;
            }
            rect(t, len, z_min_m, z_max_m);
        }
        Ok(())
    }

    /// The finished scene.
    pub fn build(self, name: &str) -> Scene {
        Scene::new(name.to_string(), self.objects, self.primitives)
    }
}

/// Ear clipping of a simple polygon; `None` if it is not simple.
fn ear_clip(p: &[Point2<f64>]) -> Option<Vec<[usize; 3]>> {
    let cross = |o: Point2<f64>, a: Point2<f64>, b: Point2<f64>| (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
    let signed_area: f64 = (0..p.len()).map(|i| cross(Point2::origin(), p[i], p[(i + 1) % p.len()])).sum();
    let mut idx: Vec<usize> = (0..p.len()).collect();
    if signed_area < 0.0 {
        idx.reverse();
    }
    let mut out = Vec::with_capacity(p.len() - 2);
    let mut guard = 0;
    while idx.len() > 3 {
        let n = idx.len();
        let mut clipped = false;
        for k in 0..n {
            let (a, b, c) = (idx[(k + n - 1) % n], idx[k], idx[(k + 1) % n]);
            if cross(p[a], p[b], p[c]) <= 1e-15 {
                continue; // reflex or collinear corner
            }
            let inside = idx.iter().any(|&m| {
                m != a
                    && m != b
                    && m != c
                    && cross(p[a], p[b], p[m]) >= 0.0
                    && cross(p[b], p[c], p[m]) >= 0.0
                    && cross(p[c], p[a], p[m]) >= 0.0
            });
            if !inside {
                out.push([a, b, c]);
                idx.remove(k);
                clipped = true;
                break;
            }
        }
        if !clipped {
            // Only collinear corners left: drop one, else the polygon is not simple.
            let n = idx.len();
            let flat =
                (0..n).find(|&k| cross(p[idx[(k + n - 1) % n]], p[idx[k]], p[idx[(k + 1) % n]]).abs() <= 1e-15)?;
            idx.remove(flat);
        }
        guard += 1;
        if guard > 4 * p.len() {
            return None;
        }
    }
    out.push([idx[0], idx[1], idx[2]]);
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Ray;

    #[test]
    fn l_shaped_polygon_covers_its_area_only() {
        let l = [(0.0, 0.0), (4.0, 0.0), (4.0, 1.0), (1.0, 1.0), (1.0, 3.0), (0.0, 3.0)]
            .map(|(x, y)| Point3::new(x, y, 0.0));
        let mut b = SceneBuilder::new();
        b.polygon("L", &l).expect("valid polygon");
        let scene = b.build("l");
        let down = |x: f64, y: f64| scene.cast(&Ray::new(Point3::new(x, y, 1.0), -Vector3::z()).expect("ray"), 10.0);
        assert!(down(3.5, 0.5).is_some());
        assert!(down(0.5, 2.5).is_some());
        assert!(down(2.5, 2.0).is_none(), "the notch of the L is empty");
        // Area check: 4 + 2 = 6 m² from the triangles.
        assert_eq!(scene.primitive_count(), 4);
    }

    #[test]
    fn wall_opening_lets_rays_through() {
        let mut b = SceneBuilder::new();
        let path = [Point2::new(0.0, 0.0), Point2::new(10.0, 0.0)];
        b.wall(
            "w",
            &path,
            false,
            0.0,
            3.0,
            &[Opening { segment: 0, from_m: 4.0, to_m: 5.0, z_min_m: 0.0, z_max_m: 2.0 }],
        )
        .expect("valid wall");
        let scene = b.build("w");
        let through = |x: f64, z: f64| scene.cast(&Ray::new(Point3::new(x, -1.0, z), Vector3::y()).expect("ray"), 5.0);
        assert!(through(4.5, 1.0).is_none(), "door");
        assert!(through(4.5, 2.5).is_some(), "lintel");
        assert!(through(3.5, 1.0).is_some());
        assert!(through(5.5, 1.0).is_some());
    }

    /// A box pitched by 90° stands its long x edge upright.
    #[test]
    fn oriented_box() {
        let mut b = SceneBuilder::new();
        b.oriented_cuboid(
            "post",
            Point3::new(0.0, 0.0, 0.0),
            Vector3::new(4.0, 0.2, 0.2),
            [0.0, std::f64::consts::FRAC_PI_2, 0.0],
        )
        .expect("valid box");
        let scene = b.build("b");
        let down = scene.cast(&Ray::new(Point3::new(0.0, 0.0, 5.0), -Vector3::z()).expect("ray"), 10.0).expect("top");
        assert!((down.distance_m - 3.0).abs() < 1e-9, "top at z = 2: {}", down.distance_m);
        let side = scene.cast(&Ray::new(Point3::new(-5.0, 0.0, 1.5), Vector3::x()).expect("ray"), 10.0).expect("side");
        assert!((side.distance_m - 4.9).abs() < 1e-9);
    }

    #[test]
    fn bad_blocks_are_named_errors() {
        let mut b = SceneBuilder::new();
        let e = b.cuboid("crate", Point3::origin(), Vector3::new(1.0, -1.0, 1.0), 0.0).expect_err("negative size");
        assert!(e.to_string().contains("box 'crate': size_m[1]"), "{e}");
        let e = b.cylinder("pipe", Point3::origin(), Point3::new(1.0, 0.0, 0.0), f64::NAN).expect_err("NaN radius");
        assert!(e.to_string().contains("radius_m must be finite"), "{e}");
        let skew = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.0, 1.0, 0.5),
            Point3::new(0.0, 1.0, 0.0),
        ];
        let e = b.polygon("skew", &skew).expect_err("non-planar");
        assert!(e.to_string().contains("plane"), "{e}");
        let path = [Point2::new(0.0, 0.0), Point2::new(2.0, 0.0)];
        let o = Opening { segment: 0, from_m: 1.0, to_m: 3.0, z_min_m: 0.0, z_max_m: 1.0 };
        let e = b.wall("w", &path, false, 0.0, 2.0, &[o]).expect_err("opening beyond segment");
        assert!(e.to_string().contains("opening 0"), "{e}");
        // A scene 3e14 m out (issue 34, U1): beyond every grid.
        let e = b.sphere("far", Point3::new(3e14, 0.0, 0.0), 1.0).expect_err("too far");
        assert!(e.to_string().contains("within ±1e8 m"), "{e}");
        b.sphere("grid", Point3::new(500_000.0, 5_500_000.0, 0.0), 1.0).expect("a national-grid position");
    }
}
