//! The mission reader from arbitrary text: never a panic; a refusal names
//! at least one problem with a line and column inside the text; an accepted
//! mission's plan is checked (or refused) without a panic when it is small.
#![no_main]

use libfuzzer_sys::fuzz_target;
use missions::mission::diagnostics::Source;
use missions::{Mission, MissionError};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let lines = text.lines().count().max(1);
    match Mission::parse(Source::new(std::path::Path::new("fuzz.toml"), text.to_string())) {
        Ok(mission) => {
            // Plans of up to ~200 stations (a larger one is valid but slow
            // to place, and is not what this target looks for).
            let length: f64 = mission.plan.route_m.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
            if length / mission.plan.stride_m <= 200.0 {
                let _ = missions::planning::Planned::new(&mission);
            }
        }
        Err(MissionError::Invalid { problems, .. }) => {
            assert!(!problems.0.is_empty(), "refused without a problem");
            for p in problems.0.iter().filter(|p| p.file.as_os_str() == "fuzz.toml") {
                assert!(p.line >= 1 && p.line <= lines + 1, "line {} of {lines}", p.line);
            }
        }
        Err(_) => {}
    }
});
