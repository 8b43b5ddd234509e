//! The scene file: a TOML description of a scene, optionally on top of a
//! built-in one. Every key carries its unit; unknown keys are errors; each
//! error names the line and column of the offending element.
//!
//! ```toml
//! name = "lab"            # required
//! base = "hall"           # optional: start from a built-in scene
//!
//! [[polygon]]             # planar, any simple outline, vertices in order
//! name = "ramp"
//! vertices_m = [[0, 0, 0], [4, 0, 0], [4, 2, 0.5], [0, 2, 0.5]]
//!
//! [[box]]                 # centre, full edge lengths, orientation
//! name = "crate"
//! center_m = [3, 4, 0.5]
//! size_m = [1, 1, 1]
//! yaw_deg = 30            # optional, default 0; R = Rz(yaw)·Ry(pitch)·Rx(roll)
//! pitch_deg = 0           # optional, default 0
//! roll_deg = 0            # optional, default 0
//!
//! [[cylinder]]            # lateral surface from a_m to b_m
//! name = "column"
//! a_m = [6, 6, 0]
//! b_m = [6, 6, 6]
//! radius_m = 0.3
//!
//! [[sphere]]
//! name = "ball"
//! center_m = [1, 1, 1]
//! radius_m = 0.5
//!
//! [[wall]]                # vertical walls along a 2D path
//! name = "partition"
//! path_m = [[10, 0], [10, 8]]
//! closed = false          # optional, default false
//! z_min_m = 0
//! z_max_m = 3
//! openings = [{ segment = 0, from_m = 2, to_m = 3, z_min_m = 0, z_max_m = 2.1 }]
//! ```

use nalgebra::{Point2, Point3, Vector3};
use serde::Deserialize;
use toml::Spanned;

use super::{Opening, Scene, SceneBuilder};
use crate::error::{CpsError, Result, line_column};

/// The raw scene file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// Scene name.
    pub name: String,
    /// A built-in scene to start from.
    pub base: Option<Spanned<String>>,
    /// Polygons.
    #[serde(default)]
    pub polygon: Vec<Spanned<PolygonSpec>>,
    /// Boxes.
    #[serde(default, rename = "box")]
    pub boxes: Vec<Spanned<BoxSpec>>,
    /// Cylinders.
    #[serde(default)]
    pub cylinder: Vec<Spanned<CylinderSpec>>,
    /// Spheres.
    #[serde(default)]
    pub sphere: Vec<Spanned<SphereSpec>>,
    /// Walls.
    #[serde(default)]
    pub wall: Vec<Spanned<WallSpec>>,
}

/// `[[polygon]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolygonSpec {
    /// Object name.
    pub name: String,
    /// Vertices in order, metres.
    pub vertices_m: Vec<[f64; 3]>,
}

/// `[[box]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// Object name.
    pub name: String,
    /// Centre, metres.
    pub center_m: [f64; 3],
    /// Full edge lengths, metres.
    pub size_m: [f64; 3],
    /// Rotation about z, degrees.
    #[serde(default)]
    pub yaw_deg: f64,
    /// Rotation about y, degrees.
    #[serde(default)]
    pub pitch_deg: f64,
    /// Rotation about x, degrees.
    #[serde(default)]
    pub roll_deg: f64,
}

/// `[[cylinder]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CylinderSpec {
    /// Object name.
    pub name: String,
    /// Axis start, metres.
    pub a_m: [f64; 3],
    /// Axis end, metres.
    pub b_m: [f64; 3],
    /// Radius, metres.
    pub radius_m: f64,
}

/// `[[sphere]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSpec {
    /// Object name.
    pub name: String,
    /// Centre, metres.
    pub center_m: [f64; 3],
    /// Radius, metres.
    pub radius_m: f64,
}

/// `[[wall]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallSpec {
    /// Object name.
    pub name: String,
    /// 2D path (x, y), metres.
    pub path_m: Vec<[f64; 2]>,
    /// Close the path back to its first point.
    #[serde(default)]
    pub closed: bool,
    /// Bottom, metres.
    pub z_min_m: f64,
    /// Top, metres.
    pub z_max_m: f64,
    /// Openings.
    #[serde(default)]
    pub openings: Vec<OpeningSpec>,
}

/// One opening of a `[[wall]]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpeningSpec {
    /// Segment index.
    pub segment: usize,
    /// Start along the segment, metres.
    pub from_m: f64,
    /// End along the segment, metres.
    pub to_m: f64,
    /// Bottom, metres.
    pub z_min_m: f64,
    /// Top, metres.
    pub z_max_m: f64,
}

fn at(text: &str, span: std::ops::Range<usize>, error: CpsError) -> CpsError {
    let (line, column) = line_column(text, span.start);
    CpsError::SceneFile { line, column, message: error.to_string() }
}

/// Parses and builds a scene from scene-file text. Errors carry the line
/// and column (1-based) of the offending element.
pub fn parse_scene_toml(text: &str) -> Result<Scene> {
    let spec: SceneSpec = toml::from_str(text).map_err(|e| {
        let (line, column) = e.span().map_or((0, 0), |s| line_column(text, s.start));
        CpsError::SceneFile { line, column, message: e.message().to_string() }
    })?;
    let mut b = SceneBuilder::new();
    if let Some(base) = &spec.base {
        super::builtin::add_builtin(&mut b, base.get_ref()).map_err(|e| at(text, base.span(), e))?;
    }
    let p = |v: &[f64; 3]| Point3::from(*v);
    for s in &spec.polygon {
        let v: Vec<Point3<f64>> = s.get_ref().vertices_m.iter().map(p).collect();
        b.polygon(&s.get_ref().name, &v).map_err(|e| at(text, s.span(), e))?;
    }
    for s in &spec.boxes {
        let x = s.get_ref();
        b.oriented_cuboid(
            &x.name,
            p(&x.center_m),
            Vector3::from(x.size_m),
            [x.roll_deg, x.pitch_deg, x.yaw_deg].map(f64::to_radians),
        )
        .map_err(|e| at(text, s.span(), e))?;
    }
    for s in &spec.cylinder {
        let x = s.get_ref();
        b.cylinder(&x.name, p(&x.a_m), p(&x.b_m), x.radius_m).map_err(|e| at(text, s.span(), e))?;
    }
    for s in &spec.sphere {
        let x = s.get_ref();
        b.sphere(&x.name, p(&x.center_m), x.radius_m).map_err(|e| at(text, s.span(), e))?;
    }
    for s in &spec.wall {
        let x = s.get_ref();
        let path: Vec<Point2<f64>> = x.path_m.iter().map(|q| Point2::from(*q)).collect();
        let openings: Vec<Opening> = x
            .openings
            .iter()
            .map(|o| Opening {
                segment: o.segment,
                from_m: o.from_m,
                to_m: o.to_m,
                z_min_m: o.z_min_m,
                z_max_m: o.z_max_m,
            })
            .collect();
        b.wall(&x.name, &path, x.closed, x.z_min_m, x.z_max_m, &openings).map_err(|e| at(text, s.span(), e))?;
    }
    if b.primitive_count() == 0 {
        return Err(CpsError::SceneFile {
            line: 1,
            column: 1,
            message: "the scene has no surfaces: add a base or at least one object".into(),
        });
    }
    Ok(b.build(&spec.name))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Ray;

    #[test]
    fn the_documented_example_parses() {
        let doc = include_str!("spec.rs");
        let example: String = doc
            .lines()
            .skip_while(|l| !l.starts_with("//! ```toml"))
            .skip(1)
            .take_while(|l| !l.starts_with("//! ```"))
            .map(|l| format!("{}\n", l.trim_start_matches("//!").trim_start()))
            .collect();
        let scene = parse_scene_toml(&example).expect("example scene");
        assert_eq!(scene.name(), "lab");
        // The crate (a box at (3, 4, 0.5), 1 m) seen from above.
        let hit = scene.cast(&Ray::new(Point3::new(3.0, 4.0, 3.0), -Vector3::z()).expect("ray"), 10.0).expect("hit");
        assert_eq!(scene.object_name(hit.object), "crate");
        assert!((hit.distance_m - 2.0).abs() < 1e-9);
    }

    #[test]
    fn errors_name_line_and_column() {
        let bad_key = "name = \"x\"\n[[box]]\nname = \"b\"\ncentre_m = [0, 0, 0]\nsize_m = [1, 1, 1]\n";
        let e = parse_scene_toml(bad_key).expect_err("unknown key");
        assert!(matches!(e, CpsError::SceneFile { line: 4, .. }), "{e}");
        assert!(e.to_string().contains("centre_m"), "{e}");
        let bad_value = "name = \"x\"\n\n[[sphere]]\nname = \"s\"\ncenter_m = [0, 0, 0]\nradius_m = -1\n";
        let e = parse_scene_toml(bad_value).expect_err("negative radius");
        assert!(matches!(e, CpsError::SceneFile { line: 3, column: 1, .. }), "{e}");
        assert!(e.to_string().contains("sphere 's': radius_m = -1"), "{e}");
        let bad_base = "name = \"x\"\nbase = \"warehouse\"\n";
        let e = parse_scene_toml(bad_base).expect_err("unknown base");
        assert!(matches!(e, CpsError::SceneFile { line: 2, column: 8, .. }), "{e}");
        let empty = "name = \"x\"\n";
        assert!(parse_scene_toml(empty).expect_err("empty").to_string().contains("no surfaces"));
    }
}
