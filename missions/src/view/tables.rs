//! The terminal tables of every command: units in the column heads,
//! numbers in columns.

use std::io::Write;

use cps::{CHI2_2D_95_SQRT, RAD_PER_ARCSEC};
use planner::{Prediction, Robot, StepEstimate};

use crate::commands::montecarlo::MonteCarlo;
use crate::mission::Mission;
use crate::planning::Planned;
use crate::planning::analysis::{self, PlanReport};
use crate::run::adjust::AdjustmentOutcome;
use crate::run::fuse::{Fused, ScanView, error_heading, error_xy};
use crate::run::inspection::PipeReport;
use crate::run::runner::RunSummary;

/// The children right after each placement: √(σx² + σy²) per child, one
/// row per cycle that placed any.
fn write_children(
    out: &mut dyn Write,
    mission: &Mission,
    prediction: &Prediction,
    estimates: &[StepEstimate],
) -> std::io::Result<()> {
    if mission.children.is_empty() || prediction.cycles.is_empty() {
        return Ok(());
    }
    writeln!(out)?;
    writeln!(out, "children after placement, √(σx² + σy²) in mm:")?;
    write!(out, "{:>6}", "cycle")?;
    for name in &mission.children {
        write!(out, " {name:>12}")?;
    }
    writeln!(out)?;
    for c in &prediction.cycles {
        let placed: Vec<&StepEstimate> =
            estimates.iter().filter(|e| e.cycle == c.cycle && matches!(e.robot, Robot::Child(_))).collect();
        if placed.is_empty() {
            continue;
        }
        write!(out, "{:>6}", c.cycle)?;
        for j in 0..mission.children.len() {
            match placed.iter().find(|e| e.robot == Robot::Child(j)) {
                Some(e) => write!(out, " {:>12.3}", 1e3 * e.sigma_xy2_m2().sqrt())?,
                None => write!(out, " {:>12}", "stays")?,
            }
        }
        writeln!(out)?;
    }
    Ok(())
}

/// The scan stations' covariance: what a direct transformation inherits.
fn write_scans(out: &mut dyn Write, estimates: &[StepEstimate]) -> std::io::Result<()> {
    let scans: Vec<&StepEstimate> = estimates.iter().filter(|e| e.scan).collect();
    if scans.is_empty() {
        return Ok(());
    }
    writeln!(out)?;
    writeln!(out, "scan stations:")?;
    writeln!(out, "{:>6} {:>9} {:>9} {:>9} {:>10}", "step", "x_m", "y_m", "σxy_mm", "σθ_arcsec")?;
    for e in scans {
        writeln!(
            out,
            "{:>6} {:>9.2} {:>9.2} {:>9.3} {:>10.2}",
            e.step,
            e.position.x,
            e.position.y,
            1e3 * e.sigma_xy2_m2().sqrt(),
            e.covariance[(3, 3)].sqrt() / RAD_PER_ARCSEC
        )?;
    }
    Ok(())
}

/// `predict`: one row per cycle, the children after each placement, the
/// scan stations and the final summary.
pub fn prediction(out: &mut dyn Write, mission: &Mission, planned: &Planned) -> std::io::Result<()> {
    let prediction = &planned.prediction;
    let n = prediction.cycles.len();
    let dist = prediction.last().map_or(0.0, |l| l.distance_m);
    writeln!(out, "mission {}: {n} cycles, {} children, {dist:.1} m of route", mission.name, mission.children.len())?;
    writeln!(
        out,
        "{:>6} {:>9} {:>9} {:>9} {:>9} {:>10} {:>9} {:>9} {:>7} {:>8}",
        "cycle", "dist_m", "σx_mm", "σy_mm", "σz_mm", "σθ_arcsec", "a95_mm", "b95_mm", "az95_°", "drift_%"
    )?;
    for c in &prediction.cycles {
        let e = c.ellipse_1sigma().scaled(CHI2_2D_95_SQRT);
        writeln!(
            out,
            "{:>6} {:>9.2} {:>9.3} {:>9.3} {:>9.3} {:>10.2} {:>9.3} {:>9.3} {:>7.1} {:>8.4}",
            c.cycle,
            c.distance_m,
            1e3 * c.covariance[(0, 0)].sqrt(),
            1e3 * c.covariance[(1, 1)].sqrt(),
            1e3 * c.covariance[(2, 2)].sqrt(),
            c.sigma_heading_rad() / RAD_PER_ARCSEC,
            1e3 * e.semi_major_m,
            1e3 * e.semi_minor_m,
            e.orientation_rad.to_degrees(),
            c.drift_percent(),
        )?;
    }
    write_children(out, mission, prediction, &planned.estimates)?;
    write_scans(out, &planned.estimates)?;
    if let Some(l) = prediction.last() {
        let e = l.ellipse_1sigma().scaled(CHI2_2D_95_SQRT);
        writeln!(out)?;
        writeln!(out, "final after {:.1} m:", l.distance_m)?;
        writeln!(out, "  σx² + σy²      {:.6} m²  (√ = {:.4} m)", l.sigma_xy2_m2(), l.sigma_xy2_m2().sqrt())?;
        writeln!(out, "  σz             {:.4} m", l.covariance[(2, 2)].sqrt())?;
        writeln!(out, "  σθ             {:.2}″", l.sigma_heading_rad() / RAD_PER_ARCSEC)?;
        writeln!(
            out,
            "  95 % ellipse   {:.4} m × {:.4} m, major axis at {:.1}°",
            e.semi_major_m,
            e.semi_minor_m,
            e.orientation_rad.to_degrees()
        )?;
        writeln!(out, "  drift          {:.4} % of distance", l.drift_percent())?;
        if let Some(max) = mission.acceptance.max_final_sigma_xy_m {
            let verdict = if crate::planning::accepted(mission, prediction) { "PASS" } else { "FAIL" };
            writeln!(
                out,
                "  acceptance     {verdict}: √(σx² + σy²) = {:.4} m, limit {max} m",
                l.sigma_xy2_m2().sqrt()
            )?;
        }
    }
    Ok(())
}

/// `plan`'s report as text.
pub fn plan(out: &mut dyn Write, mission: &Mission, report: &PlanReport) -> std::io::Result<()> {
    let plan = &mission.plan;
    let name = |r| mission.robot_name(r);
    let scene =
        if mission.backend.given { format!("scene \"{}\"", mission.backend.scene) } else { "open space".into() };
    writeln!(
        out,
        "mission {}: {}, stride {} m, {} stations, {} cycles, {} steps, checked in {scene}",
        mission.name,
        plan.strategy,
        plan.stride_m,
        report.written.stations(),
        report.written.dance.cycles.len(),
        report.written.steps.len()
    )?;
    if report.violations.is_empty() {
        writeln!(out, "constraints: every step keeps every constraint")?;
    } else {
        writeln!(out, "constraints: {} violation(s)", report.violations.len())?;
        for v in &report.violations {
            writeln!(out, "  {}", v.describe(&name))?;
        }
    }
    if let (Some(s2), Some(h)) = (report.sigma_xy2_m2, report.sigma_heading_rad) {
        writeln!(
            out,
            "predicted final: σx² + σy² = {s2:.6} m² (√ = {:.4} m), σθ = {:.2}″",
            s2.sqrt(),
            h / RAD_PER_ARCSEC
        )?;
    }
    if let Some(s) = report.sensitivity {
        let pct = |x: f64| 100.0 * x / s.total_m2;
        writeln!(
            out,
            "what dominates: {} — range {:.1} %, angle {:.1} %, centring {:.1} %, start {:.1} % of σx² + σy²",
            s.dominant(),
            pct(s.range_m2),
            pct(s.angle_m2),
            pct(s.centring_m2),
            pct(s.start_m2)
        )?;
    }
    if let (Some(m), Some(s2)) = (report.one_more_child_m2, report.sigma_xy2_m2) {
        writeln!(out, "one more child (straight ahead): σx² + σy² = {m:.6} m² ({:.2}× as written)", m / s2)?;
    }
    if let (Some((stride, n, m)), Some(s2)) = (report.longer_stride, report.sigma_xy2_m2) {
        writeln!(out, "stride {stride} m ({n} cycles): σx² + σy² = {m:.6} m² ({:.2}× as written)", m / s2)?;
    }
    if let Some(min) = analysis::min_redundancy(report) {
        let u = analysis::unchecked(report);
        writeln!(
            out,
            "reliability: smallest redundancy number of a fix observation {min:.3}; {} observation(s) checked by nothing{}",
            u.len(),
            if u.is_empty() { "" } else { " (see --json)" }
        )?;
        writeln!(out, "  each child's placement rests on one pointing: checked only through the next fix")?;
    }
    if let Some(o) = &report.optimized {
        let c = &o.best.candidate;
        writeln!(out)?;
        writeln!(
            out,
            "optimized ({} candidates predicted, {} checked, {:.2} s): {}, stride {} m, {} cycles",
            o.predicted,
            o.checked,
            o.seconds,
            c.strategy,
            c.stride_m,
            o.best.cycles()
        )?;
        let offsets: Vec<String> =
            o.offsets(mission).iter().map(|o| format!("[{:.3}, {:.3}, {:.3}]", o.x, o.y, o.z)).collect();
        writeln!(out, "  formation_m = [{}]", offsets.join(", "))?;
        let s2 = o.best.sigma_xy2_m2;
        write!(out, "  predicted final: σx² + σy² = {s2:.6} m² (√ = {:.4} m)", s2.sqrt())?;
        match report.sigma_xy2_m2 {
            Some(w) => writeln!(out, ", {:.2}× better than as written", w / s2)?,
            None => writeln!(out)?,
        }
    }
    if let Some(max) = mission.acceptance.max_final_sigma_xy_m {
        writeln!(
            out,
            "acceptance (max_final_sigma_xy_m = {max} m): {}",
            if analysis::accepted(mission, report) { "PASS" } else { "FAIL" }
        )?;
    } else if !analysis::accepted(mission, report) {
        writeln!(out, "FAIL: the plan breaks constraints")?;
    }
    Ok(())
}

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
    if let Some(pipe) = &s.report.pipe {
        pipe_summary(out, pipe)?;
    }
    match &s.report.adjustment {
        Some(AdjustmentOutcome::Adjusted(report)) => super::listing::summary(out, report)?,
        Some(AdjustmentOutcome::Failed { error }) => writeln!(out, "network adjustment failed: {error}")?,
        None => {}
    }
    if s.replayed > 0 {
        writeln!(out, "resumed: {} journal events replayed", s.replayed)?;
    }
    writeln!(out, "outputs in {}: {}", s.dir.display(), s.files.join(", "))?;
    if s.files.iter().any(|f| f == "mission.rrd") {
        writeln!(out, "view with: rerun {}", s.dir.join("mission.rrd").display())?;
    } else if mission.output.rerun {
        writeln!(out, "no mission.rrd: this cps-survey was built without the `recording` feature")?;
    }
    writeln!(out, "acceptance: {}", if s.accepted { "passed" } else { "FAILED" })
}

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

/// The pipe inspection: the fitted tube and one line per anomaly.
pub fn pipe_summary(out: &mut dyn Write, pipe: &PipeReport) -> std::io::Result<()> {
    let p = match pipe {
        PipeReport::Failed { error } => return writeln!(out, "pipe: no fit: {error}"),
        PipeReport::Fitted(p) => p,
    };
    let count = p.anomalies.len();
    writeln!(
        out,
        "pipe: radius {:.4} m (nominal {:.4} m), axis {:.3}° from the nominal, RMS {:.1} mm over {} points; {} anomal{} beyond {:.0} mm",
        p.fitted.radius_m,
        p.nominal.radius_m,
        p.axis_tilt_deg,
        1e3 * p.rmse_m,
        p.inliers,
        count,
        if count == 1 { "y" } else { "ies" },
        1e3 * p.threshold_m,
    )?;
    if p.anomalies.is_empty() {
        return Ok(());
    }
    writeln!(
        out,
        "{:>10} {:>15} {:>6} {:>20} {:>9} {:>7}",
        "kind", "along axis m", "clock", "size mm", "depth mm", "points"
    )?;
    for a in &p.anomalies {
        let size = |k: usize| 1e3 * a.size_m[k];
        writeln!(
            out,
            "{:>10} {:>15} {:>6} {:>20} {:>9.1} {:>7}",
            a.kind,
            format!("{:.2}–{:.2}", a.axial_from_m, a.axial_to_m),
            a.clock,
            format!("{:.0} × {:.0} × {:.0}", size(0), size(1), size(2)),
            1e3 * a.depth_m,
            a.points,
        )?;
    }
    Ok(())
}

/// `montecarlo`: one row per station, then the verdict.
pub fn montecarlo(out: &mut dyn Write, mission: &Mission, mc: &MonteCarlo) -> std::io::Result<()> {
    writeln!(out, "mission \"{}\": {} trials (seed {}), positioning only", mission.name, mc.trials, mc.seed)?;
    writeln!(out, "{:>7} {:>13} {:>13} {:>7} {:>9}", "station", "pred σxy_mm", "emp σxy_mm", "ratio", "NEES")?;
    for s in &mc.stations {
        writeln!(
            out,
            "{:>7} {:>13.3} {:>13.3} {:>7.3} {:>9.3}",
            s.cycle,
            1e3 * cps::sigma_xy2(&s.predicted).sqrt(),
            1e3 * cps::sigma_xy2(&s.empirical).sqrt(),
            s.ratio_xy(),
            s.nees_mean
        )?;
    }
    let (lo, hi) = mc.nees_interval;
    writeln!(
        out,
        "final mean NEES {:.3}, 95 % interval [{lo:.3}, {hi:.3}] for {} trials: {}",
        mc.last().map_or(f64::NAN, |s| s.nees_mean),
        mc.trials,
        if mc.consistent() { "consistent with the prediction" } else { "NOT consistent with the prediction" }
    )
}
