//! The examples in README.md are real: they parse and mean what it says.

use cps::geom::{Ray, parse_scene_toml};
use nalgebra::{Point3, Vector3};

fn readme() -> String {
    std::fs::read_to_string(tests::workspace().join("README.md")).expect("README.md")
}

/// The first ```toml block after `marker`.
fn toml_block_after(text: &str, marker: &str) -> String {
    let from = text.find(marker).unwrap_or_else(|| panic!("README lacks '{marker}'"));
    let rest = &text[from..];
    let start = rest.find("```toml\n").expect("a toml block") + "```toml\n".len();
    let end = rest[start..].find("```").expect("end of block");
    rest[start..start + end].to_string()
}

#[test]
fn scene_file_example_parses() {
    let text = toml_block_after(&readme(), "A scene file (TOML)");
    let scene = parse_scene_toml(&text).unwrap_or_else(|e| panic!("README scene example: {e}"));
    assert_eq!(scene.name(), "lab");
    // On top of the hall: the crate is there, and so is pillar 1.
    let down = scene.cast(&Ray::new(Point3::new(3.0, 4.0, 3.0), -Vector3::z()).expect("ray"), 10.0).expect("hit");
    assert_eq!(scene.object_name(down.object), "crate");
    assert!(
        !scene.line_of_sight(&Point3::new(8.0, 6.0, 1.0), &Point3::new(12.0, 6.0, 1.0)),
        "pillar 1 of the base hall"
    );
}
