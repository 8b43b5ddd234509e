//! The terminal text of `run`: its summary.

use std::io::Write;

use super::runner::RunSummary;
use crate::documents::adjustment::AdjustmentOutcome;
use crate::mission::Mission;

/// `run`: one line per station, the fusion and the pipe, the files written
/// and the verdict.
pub fn run_summary(out: &mut dyn Write, mission: &Mission, s: &RunSummary) -> std::io::Result<()> {
    writeln!(
        out,
        "mission \"{}\" (seed {}): {} stations, {} points fused",
        mission.name,
        mission.backend.seed,
        s.stations.len(),
        s.points
    )?;
    writeln!(
        out,
        "{:>7} {:>10} {:>10} {:>9} {:>11} {:>11} {:>9}",
        "station", "x_m", "y_m", "σxy_mm", "pred σxy_mm", "error_xy_mm", "scan"
    )?;
    for st in &s.stations {
        writeln!(
            out,
            "{:>7} {:>10.3} {:>10.3} {:>9.2} {:>11.2} {:>11} {:>9}",
            st.index,
            st.pose.position.x,
            st.pose.position.y,
            1e3 * cps::sigma_xy2(&st.covariance).sqrt(),
            1e3 * cps::sigma_xy2(&st.predicted_covariance).sqrt(),
            st.error_xy_m.map_or("-".to_string(), |e| format!("{:.2}", 1e3 * e)),
            if st.scan.is_some() { "yes" } else { "-" }
        )?;
    }
    let fusion = &s.report.fusion;
    if let (Some(rms), Some(direct)) = (fusion.rms_error_xy_m, fusion.direct_rms_error_xy_m)
        && fusion.mode != "direct"
    {
        writeln!(
            out,
            "fusion {}: {} ICP matches; RMS horizontal error of the scan poses {:.2} mm (direct: {:.2} mm)",
            fusion.mode,
            fusion.matches,
            1e3 * rms,
            1e3 * direct
        )?;
    }
    if !fusion.settled {
        writeln!(out, "{}", crate::products::text::UNSETTLED)?;
    }
    if let Some(pipe) = &s.report.pipe {
        crate::view::tables::pipe_summary(out, pipe)?;
    }
    match &s.report.adjustment {
        Some(AdjustmentOutcome::Adjusted(report)) => crate::view::listing::summary(out, report)?,
        Some(AdjustmentOutcome::Failed { error }) => writeln!(out, "network adjustment failed: {error}")?,
        None => {}
    }
    for r in &s.report.remeasured {
        writeln!(out, "measured again: {} (attempt {}): {}", r.point, r.attempt, r.why)?;
    }
    if s.replayed > 0 {
        writeln!(out, "resumed: {} journal events replayed", s.replayed)?;
    }
    writeln!(out, "outputs in {}: {}", s.dir.display(), s.files.join(", "))?;
    if let Some(warning) = &s.viewer_warning {
        writeln!(out, "warning: {warning}")?;
    }
    if s.files.iter().any(|f| f == "mission.rrd") {
        writeln!(out, "view with: rerun {}", s.dir.join("mission.rrd").display())?;
    } else if mission.output.rerun {
        writeln!(out, "no mission.rrd: this cps-survey was built without the `recording` feature")?;
    }
    writeln!(out, "acceptance: {}", if s.accepted { "passed" } else { "FAILED" })
}
