//! What the missions crate's integration tests share.

use std::path::{Path, PathBuf};

/// Writes the hall's first three stations at 8 slices as `dir/m.toml`:
/// with `west_control`, the west wall's control points sighted at the
/// start (the east wall's are out of this short route's range); else no
/// control at all.
pub fn short_hall(dir: &Path, west_control: bool) -> PathBuf {
    let hall = std::fs::read_to_string(format!("{}/examples/hall.toml", env!("CARGO_MANIFEST_DIR"))).expect("hall");
    let route = "[[1.5, 4.2, 1.5], [37.5, 4.2, 1.5], [37.5, 7.8, 1.5], [1.5, 7.8, 1.5]]";
    assert!(hall.contains(route) && hall.contains("control_at = [0, 10, 21]"), "hall.toml changed: update this helper");
    let text = hall
        .replace(route, "[[1.5, 4.2, 1.5], [8.7, 4.2, 1.5]]")
        .replace("control_at = [0, 10, 21]", if west_control { "control_at = [0]" } else { "" })
        .replace("slices = 180", "slices = 8");
    let cut = if west_control { "[[control]]\nname = \"E1\"" } else { "[[control]]" };
    let path = dir.join("m.toml");
    std::fs::write(&path, text.split(cut).next().expect("the text before the cut")).expect("mission");
    path
}
