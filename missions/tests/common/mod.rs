//! What the missions crate's integration tests share.

use std::path::{Path, PathBuf};

/// The hall's route as `hall.toml` gives it.
pub const HALL_ROUTE: &str = "route_m = [[1.5, 4.2, 1.5], [37.5, 4.2, 1.5], [37.5, 7.8, 1.5], [1.5, 7.8, 1.5]]";

/// `hall.toml`'s text with each `(from, to)` of `edits` made; a `from` that
/// is not there (hall.toml changed) fails the test, naming it.
pub fn hall_edited(edits: &[(&str, &str)]) -> String {
    let hall = std::fs::read_to_string(format!("{}/examples/hall.toml", env!("CARGO_MANIFEST_DIR"))).expect("hall");
    edits.iter().fold(hall, |text, (from, to)| {
        assert!(text.contains(from), "hall.toml no longer holds {from:?}: update this test");
        text.replace(from, to)
    })
}

/// Writes the hall's first three stations at 8 slices as `dir/m.toml`:
/// with `west_control`, the west wall's control points sighted at the
/// start (the east wall's are out of this short route's range); else no
/// control at all.
#[allow(dead_code)] // Not every test file that includes this module uses it.
pub fn short_hall(dir: &Path, west_control: bool) -> PathBuf {
    let text = hall_edited(&[
        (HALL_ROUTE, "route_m = [[1.5, 4.2, 1.5], [8.7, 4.2, 1.5]]"),
        ("control_at = [0, 10, 21]", if west_control { "control_at = [0]" } else { "" }),
        ("slices = 180", "slices = 8"),
    ]);
    let cut = if west_control { "[[control]]\nname = \"E1\"" } else { "[[control]]" };
    let path = dir.join("m.toml");
    std::fs::write(&path, text.split(cut).next().expect("the text before the cut")).expect("mission");
    path
}
