//! The terminal text of `fuse`: a row a scan.

use std::io::Write;

use super::fuse::{Fused, ScanView, error_heading, error_xy};

/// The line both texts print when `icp`'s simultaneous pass did not settle.
pub const UNSETTLED: &str = "fusion not settled: a simultaneous queue reached [fusion] max_matches_per_scan \
     with its scans still moving; the poses are where it stopped (docs/match.md, Known limits)";

/// `fuse`: one row per scan.
pub fn fusion(out: &mut dyn Write, views: &[ScanView], fused: &Fused) -> std::io::Result<()> {
    writeln!(
        out,
        "fusion {}: {} scans, {} ICP matches, {:.2} s",
        fused.mode.name(),
        views.len(),
        fused.matches,
        fused.seconds
    )?;
    if !fused.settled {
        writeln!(out, "{UNSETTLED}")?;
    }
    writeln!(
        out,
        "{:>7} {:>10} {:>10} {:>9} {:>8} {:>11} {:>11} {:>11}",
        "station", "x_m", "y_m", "z_m", "rmse_mm", "error_mm", "direct_mm", "Δθ_arcsec"
    )?;
    let mm = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.2}", 1e3 * v));
    for (v, f) in views.iter().zip(&fused.scans) {
        let t = f.world_from_body.translation.vector;
        let truth = v.truth.as_ref();
        writeln!(
            out,
            "{:>7} {:>10.3} {:>10.3} {:>9.3} {:>8} {:>11} {:>11} {:>11}",
            v.station,
            t.x,
            t.y,
            t.z,
            mm(f.rmse_m),
            mm(truth.map(|tr| error_xy(&f.world_from_body, tr))),
            mm(truth.map(|tr| error_xy(&v.direct(), tr))),
            truth.map_or("-".to_string(), |tr| format!(
                "{:.1}",
                error_heading(&f.world_from_body, tr).to_degrees() * 3600.0
            )),
        )?;
    }
    Ok(())
}
