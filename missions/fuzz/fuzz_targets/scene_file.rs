//! The scene-file reader from arbitrary text: never a panic; an accepted
//! scene answers a ray query with a finite distance or none.
#![no_main]

use libfuzzer_sys::fuzz_target;
use nalgebra::Point3;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(scene) = cps::geom::parse_scene_toml(text) {
        let (a, b) = (Point3::new(0.0, 0.0, 1.0), Point3::new(10.0, 3.0, 1.0));
        if let Some(hit) = scene.obstruction(&a, &b) {
            assert!(hit.distance_m.is_finite() && hit.distance_m >= 0.0);
        }
    }
});
