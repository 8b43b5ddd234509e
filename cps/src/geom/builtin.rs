//! The built-in scenes (z up, metres, floor or ground at z = 0):
//!
//! - `hall` — indoor hall 40 × 12 × 6 m (x 0…40, y 0…12) with three pillars
//!   down the middle and a few obstacles (the seed's indoor experiment);
//! - `building` — the outer walls (12 m high) of a 45 × 25 m building with an
//!   entrance recess and a corner notch, on open ground with two lamp posts
//!   (the seed's outdoor experiment);
//! - `corridor` — an office corridor 40 × 2 × 3 m along x (y −1…1) with
//!   0.15 m walls, doors into seven side rooms, and pilasters, radiators, a
//!   cabinet, a shelf, a bench and fire extinguishers along the walls (seed
//!   000's GMD Robobench);
//! - `sewer` — a straight pipe of radius 0.5 m, 20 m along x with its axis at
//!   (y = 0, z = 0.5), a dent in the crown at x = 12 m and a brick on the
//!   invert at x = 8 m (seed 000 §5).

use nalgebra::{Point2, Point3, Vector3};

use super::{Opening, Scene, SceneBuilder};
use crate::error::{CpsError, Result};

/// Names of the built-in scenes.
pub const BUILTIN_SCENES: [&str; 4] = ["hall", "building", "corridor", "sewer"];

/// Radius of the `sewer` pipe, metres.
pub const SEWER_RADIUS_M: f64 = 0.5;
/// Centre of the brick in the `sewer` scene, metres.
pub const SEWER_BRICK_CENTER: [f64; 3] = [8.0, 0.06, 0.0405];
/// Size of the brick in the `sewer` scene (length, width, height), metres.
pub const SEWER_BRICK_SIZE_M: [f64; 3] = [0.24, 0.115, 0.071];

/// A built-in scene by name (see [`BUILTIN_SCENES`]).
pub fn builtin(name: &str) -> Result<Scene> {
    let mut b = SceneBuilder::new();
    add_builtin(&mut b, name)?;
    Ok(b.build(name))
}

/// Adds the objects of built-in scene `name` to `b`.
pub(crate) fn add_builtin(b: &mut SceneBuilder, name: &str) -> Result<()> {
    match name {
        "hall" => hall(b),
        "building" => building(b),
        "corridor" => corridor(b),
        "sewer" => sewer(b),
        _ => Err(CpsError::UnknownName {
            what: "built-in scene".into(),
            name: name.into(),
            expected: BUILTIN_SCENES.join(", "),
        }),
    }
}

fn p3(x: f64, y: f64, z: f64) -> Point3<f64> {
    Point3::new(x, y, z)
}

fn size(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

fn path(points: &[(f64, f64)]) -> Vec<Point2<f64>> {
    points.iter().map(|&(x, y)| Point2::new(x, y)).collect()
}

fn hall(b: &mut SceneBuilder) -> Result<()> {
    b.cuboid("hall", p3(20.0, 6.0, 3.0), size(40.0, 12.0, 6.0), 0.0)?;
    for (k, x) in [10.0, 20.0, 30.0].into_iter().enumerate() {
        b.cuboid(&format!("pillar {}", k + 1), p3(x, 6.0, 3.0), size(0.5, 0.5, 6.0), 0.0)?;
    }
    b.cuboid("crates", p3(5.0, 2.0, 0.5), size(1.2, 0.8, 1.0), 0.3)?;
    b.cuboid("shelf", p3(17.0, 11.6, 1.25), size(6.0, 0.6, 2.5), 0.0)?;
    b.cuboid("machine", p3(25.0, 9.5, 0.9), size(2.0, 1.5, 1.8), 0.0)?;
    b.cylinder("tank", p3(33.0, 3.0, 0.0), p3(33.0, 3.0, 2.0), 0.6)?;
    let lid: Vec<Point3<f64>> = (0..24)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 24.0;
            p3(33.0 + 0.6 * a.cos(), 3.0 + 0.6 * a.sin(), 2.0)
        })
        .collect();
    b.polygon("tank lid", &lid)
}

fn building(b: &mut SceneBuilder) -> Result<()> {
    let outline = [
        (0.0, 0.0),
        (18.0, 0.0),
        (18.0, 3.0),
        (27.0, 3.0),
        (27.0, 0.0),
        (45.0, 0.0),
        (45.0, 20.0),
        (39.0, 20.0),
        (39.0, 25.0),
        (0.0, 25.0),
    ];
    let entrance = Opening { segment: 2, from_m: 3.0, to_m: 6.0, z_min_m: 0.0, z_max_m: 2.5 };
    b.wall("outer walls", &path(&outline), true, 0.0, 12.0, &[entrance])?;
    let roof: Vec<Point3<f64>> = outline.iter().map(|&(x, y)| p3(x, y, 12.0)).collect();
    b.polygon("roof", &roof)?;
    let ground = [(-30.0, -30.0), (75.0, -30.0), (75.0, 55.0), (-30.0, 55.0)].map(|(x, y)| p3(x, y, 0.0));
    b.polygon("ground", &ground)?;
    b.cylinder("lamp post 1", p3(-6.0, -6.0, 0.0), p3(-6.0, -6.0, 4.0), 0.1)?;
    b.cylinder("lamp post 2", p3(51.0, -6.0, 0.0), p3(51.0, -6.0, 4.0), 0.1)
}

fn corridor(b: &mut SceneBuilder) -> Result<()> {
    let door =
        |segment: usize, from_m: f64| Opening { segment, from_m, to_m: from_m + 0.9, z_min_m: 0.0, z_max_m: 2.1 };
    // South wall (y = −1) with doors into four rooms, north wall (y = 1) into three.
    b.wall(
        "south wall",
        &path(&[(0.0, -1.0), (40.0, -1.0)]),
        false,
        0.0,
        3.0,
        &[5.0, 15.0, 25.0, 35.0].map(|x| door(0, x)),
    )?;
    b.wall("north wall", &path(&[(0.0, 1.0), (40.0, 1.0)]), false, 0.0, 3.0, &[10.0, 20.0, 30.0].map(|x| door(0, x)))?;
    // The walls are 0.15 m thick: each door has its two reveals and a soffit.
    for (side, doors) in [(-1.0, &[5.0, 15.0, 25.0, 35.0][..]), (1.0, &[10.0, 20.0, 30.0][..])] {
        let (y0, y1) = (side, side * 1.15);
        b.wall(
            if side < 0.0 { "south wall, room side" } else { "north wall, room side" },
            &path(&[(0.0, y1), (40.0, y1)]),
            false,
            0.0,
            3.0,
            &doors.iter().map(|&x| door(0, x)).collect::<Vec<_>>(),
        )?;
        for &x in doors {
            for xr in [x, x + 0.9] {
                b.polygon("door reveal", &[p3(xr, y0, 0.0), p3(xr, y1, 0.0), p3(xr, y1, 2.1), p3(xr, y0, 2.1)])?;
            }
            b.polygon("door soffit", &[p3(x, y0, 2.1), p3(x + 0.9, y0, 2.1), p3(x + 0.9, y1, 2.1), p3(x, y1, 2.1)])?;
        }
    }
    b.wall("west end", &path(&[(0.0, -1.0), (0.0, 1.0)]), false, 0.0, 3.0, &[])?;
    b.wall("east end", &path(&[(40.0, -1.0), (40.0, 1.0)]), false, 0.0, 3.0, &[])?;
    for (k, x0) in [2.0, 12.0, 22.0, 32.0].into_iter().enumerate() {
        let x1 = x0 + 6.0;
        b.wall(
            &format!("south room {}", k + 1),
            &path(&[(x0, -1.0), (x0, -5.0), (x1, -5.0), (x1, -1.0)]),
            false,
            0.0,
            3.0,
            &[],
        )?;
        b.cuboid(&format!("south desk {}", k + 1), p3(x0 + 1.5 + k as f64, -4.2, 0.4), size(1.6, 0.8, 0.8), 0.0)?;
    }
    for (k, x0) in [7.0, 17.0, 27.0].into_iter().enumerate() {
        let x1 = x0 + 6.0;
        b.wall(
            &format!("north room {}", k + 1),
            &path(&[(x0, 1.0), (x0, 5.0), (x1, 5.0), (x1, 1.0)]),
            false,
            0.0,
            3.0,
            &[],
        )?;
        b.cuboid(&format!("north desk {}", k + 1), p3(x1 - 1.5 - k as f64, 4.2, 0.4), size(1.6, 0.8, 0.8), 0.0)?;
    }
    b.cuboid("cabinet", p3(12.5, -0.8, 0.9), size(1.0, 0.4, 1.8), 0.0)?;
    // What an office corridor has along its walls (south side, then north).
    for (k, x) in [8.0, 22.0, 37.5].into_iter().enumerate() {
        b.cuboid(&format!("south pilaster {}", k + 1), p3(x, -0.925, 1.5), size(0.3, 0.15, 3.0), 0.0)?;
    }
    for (k, x) in [4.0, 16.5, 36.0].into_iter().enumerate() {
        b.cuboid(&format!("north pilaster {}", k + 1), p3(x, 0.925, 1.5), size(0.3, 0.15, 3.0), 0.0)?;
    }
    for (k, (x, y)) in [(2.5, -0.95), (18.5, -0.95), (32.0, -0.95), (13.5, 0.95), (27.0, 0.95)].into_iter().enumerate()
    {
        b.cuboid(&format!("radiator {}", k + 1), p3(x, y, 0.45), size(1.0, 0.1, 0.6), 0.0)?;
    }
    b.cuboid("bench", p3(28.5, -0.8, 0.225), size(1.5, 0.4, 0.45), 0.0)?;
    b.cuboid("shelf", p3(24.0, 0.825, 1.0), size(0.9, 0.35, 2.0), 0.0)?;
    for (k, x) in [7.2, 33.5].into_iter().enumerate() {
        b.cylinder(&format!("fire extinguisher {}", k + 1), p3(x, 0.9, 0.3), p3(x, 0.9, 0.9), 0.08)?;
    }
    let slab = |z: f64| [(0.0, -5.0), (40.0, -5.0), (40.0, 5.0), (0.0, 5.0)].map(|(x, y)| p3(x, y, z));
    b.polygon("floor", &slab(0.0))?;
    b.polygon("ceiling", &slab(3.0))
}

fn sewer(b: &mut SceneBuilder) -> Result<()> {
    let r = SEWER_RADIUS_M;
    b.cylinder("pipe", p3(0.0, 0.0, r), p3(20.0, 0.0, r), r)?;
    // A dent in the crown: a sphere of radius 0.2 m reaching 4 cm into the pipe.
    b.sphere("deformation", p3(12.0, 0.0, r + r + 0.2 - 0.04), 0.2)?;
    let [x, y, z] = SEWER_BRICK_CENTER;
    let [l, w, h] = SEWER_BRICK_SIZE_M;
    b.cuboid("brick", p3(x, y, z), size(l, w, h), 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Ray;

    #[test]
    fn every_builtin_builds_and_unknown_names_are_listed() {
        for name in BUILTIN_SCENES {
            let s = builtin(name).expect("built-in scene");
            assert!(s.primitive_count() > 0, "{name}");
            assert_eq!(s.name(), name);
        }
        let e = builtin("warehouse").expect_err("unknown");
        assert!(e.to_string().contains("hall, building, corridor, sewer"), "{e}");
    }

    #[test]
    fn hall_dimensions_and_line_of_sight() {
        let hall = builtin("hall").expect("hall");
        let b = hall.bounds();
        assert!((b.extent() - Vector3::new(40.0, 12.0, 6.0)).norm() < 1e-9);
        // Looking up from the floor hits the ceiling at 6 m.
        let up = hall.cast(&Ray::new(p3(2.0, 2.0, 1.0), Vector3::z()).expect("ray"), 100.0).expect("ceiling");
        assert!((up.distance_m - 5.0).abs() < 1e-9);
        assert_eq!(hall.object_name(up.object), "hall");
        // Pillar 2 at x = 20, y = 6 blocks a sight line along y = 6.
        let blocked = hall.obstruction(&p3(15.0, 6.0, 1.5), &p3(25.0, 6.0, 1.5)).expect("pillar in the way");
        assert_eq!(hall.object_name(blocked.object), "pillar 2");
        assert!((blocked.point.x - 19.75).abs() < 1e-9);
        assert!(hall.line_of_sight(&p3(15.0, 3.0, 1.5), &p3(25.0, 3.0, 1.5)));
    }

    #[test]
    fn sewer_radius_dent_and_brick() {
        let sewer = builtin("sewer").expect("sewer");
        let axis = |x: f64| p3(x, 0.0, SEWER_RADIUS_M);
        let up = |x: f64| sewer.cast(&Ray::new(axis(x), Vector3::z()).expect("ray"), 10.0).expect("wall");
        assert!((up(4.0).distance_m - 0.5).abs() < 1e-12);
        assert!((up(12.0).distance_m - 0.46).abs() < 1e-9, "dent 4 cm deep");
        let down = sewer.cast(&Ray::new(p3(8.0, 0.06, 0.5), -Vector3::z()).expect("ray"), 10.0).expect("brick");
        assert_eq!(sewer.object_name(down.object), "brick");
        assert!((down.point.z - (SEWER_BRICK_CENTER[2] + SEWER_BRICK_SIZE_M[2] / 2.0)).abs() < 1e-12);
    }

    #[test]
    fn enclosing_objects_by_ray_parity() {
        let hall = builtin("hall").expect("hall");
        let names = |p| hall.enclosing(&p).into_iter().map(|o| hall.object_name(o).to_string()).collect::<Vec<_>>();
        assert_eq!(names(p3(2.0, 4.2, 1.5)), ["hall"], "the hall's free space");
        assert_eq!(names(p3(20.0, 6.0, 1.5)), ["hall", "pillar 2"], "inside a pillar");
        assert_eq!(names(p3(50.0, 6.0, 1.5)), Vec::<String>::new(), "outside");
        let sewer = builtin("sewer").expect("sewer");
        assert_eq!(sewer.enclosing(&p3(3.0, 0.0, 0.5)).len(), 1, "inside the pipe");
        assert_eq!(sewer.object_name(sewer.enclosing(&p3(3.0, 0.0, 0.5))[0]), "pipe");
    }
}
