//! The terminal tables of every command: units in the column heads,
//! numbers in columns.

use std::io::Write;

use cps::{CHI2_2D_95_SQRT, RAD_PER_ARCSEC};
use planner::{Prediction, Robot, StepEstimate};

use crate::documents::pipe::PipeReport;
use crate::mission::Mission;
use crate::planning::Planned;
use crate::planning::analysis::{self, PlanReport};
use crate::planning::montecarlo::MonteCarlo;

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
    // The children's estimates by cycle, in one pass (a long route has
    // hundreds of thousands).
    let mut by_cycle: std::collections::BTreeMap<usize, Vec<&StepEstimate>> = std::collections::BTreeMap::new();
    for e in estimates.iter().filter(|e| matches!(e.robot, Robot::Child(_))) {
        by_cycle.entry(e.cycle).or_default().push(e);
    }
    for c in &prediction.cycles {
        let Some(placed) = by_cycle.get(&c.cycle) else { continue };
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

/// The pre-analysis: every station's adjusted σ next to the filter's, the
/// control each sights, the planned reliability and the every-station
/// acceptance.
pub fn write_adjusted(out: &mut dyn Write, mission: &Mission, planned: &Planned) -> std::io::Result<()> {
    if let Some(error) = &planned.adjusted_error {
        writeln!(out)?;
        writeln!(out, "adjusted network: not computed — {error}")?;
        if mission.acceptance.max_station_sigma_xy_m.is_some() {
            writeln!(out, "  acceptance     FAIL: max_station_sigma_xy_m cannot be checked without it")?;
        }
    }
    let Some(pre) = &planned.adjusted else { return Ok(()) };
    writeln!(out)?;
    writeln!(
        out,
        "adjusted network (pre-analysis: every planned reading adjusted together), redundancy {}:",
        pre.redundancy
    )?;
    writeln!(
        out,
        "{:>7} {:>9} {:>9} {:>9} {:>9} {:>10} {:>9} {:>9} {:>7} {:>13}  control",
        "station", "x_m", "y_m", "σxy_mm", "σz_mm", "σθ_arcsec", "a95_mm", "b95_mm", "az95_°", "filter_σxy_mm"
    )?;
    for s in &pre.stations {
        let e = cps::ErrorEllipse::from_covariance(&s.covariance.fixed_view::<2, 2>(0, 0).into_owned())
            .scaled(CHI2_2D_95_SQRT);
        let filter = planned.filter_covariance(s.index).map(|c| 1e3 * cps::sigma_xy2(&c).sqrt());
        writeln!(
            out,
            "{:>7} {:>9.2} {:>9.2} {:>9.3} {:>9.3} {:>10.2} {:>9.3} {:>9.3} {:>7.1} {:>13}  {}",
            s.index,
            s.pose.position.x,
            s.pose.position.y,
            1e3 * s.sigma_xy_m(),
            1e3 * s.covariance[(2, 2)].sqrt(),
            s.covariance[(3, 3)].sqrt() / RAD_PER_ARCSEC,
            1e3 * e.semi_major_m,
            1e3 * e.semi_minor_m,
            e.orientation_rad.to_degrees(),
            filter.map_or("-".into(), |f| format!("{f:.3}")),
            planned.control_sighted_at(s.index).join(", ")
        )?;
    }
    if let (Some(w), Some(filter_worst)) = (
        pre.worst(),
        pre.stations
            .iter()
            .filter_map(|s| planned.filter_covariance(s.index))
            .map(|c| cps::sigma_xy2(&c).sqrt())
            .reduce(f64::max),
    ) {
        writeln!(
            out,
            "  worst station  {}: √(σx² + σy²) = {:.4} m adjusted (the filter's worst: {:.4} m)",
            w.index,
            w.sigma_xy_m(),
            filter_worst
        )?;
    }
    if let Some(o) = pre.worst_mdb() {
        writeln!(
            out,
            "  worst MDB      {} station {} → {}: {} (moves station {} by {:.4} m)",
            o.kind,
            o.station,
            o.target,
            mdb_text(o.kind, o.mdb),
            o.station,
            o.station_shift_m.unwrap_or(0.0)
        )?;
    }
    let unchecked: Vec<_> = pre.unchecked().collect();
    if unchecked.is_empty() {
        writeln!(out, "  every planned observation is checked by others (redundancy ≥ 0.01)")?;
    } else {
        writeln!(out, "  {} planned observation(s) checked by nothing (redundancy < 0.01):", unchecked.len())?;
        for o in unchecked.iter().take(8) {
            writeln!(out, "    station {} → {} {}: r = {:.4}", o.station, o.target, o.kind, o.redundancy)?;
        }
        if unchecked.len() > 8 {
            writeln!(out, "    … and {} more (--json lists them all)", unchecked.len() - 8)?;
        }
    }
    if let (Some(max), Some((k, worst))) = (mission.acceptance.max_station_sigma_xy_m, planned.worst_station()) {
        let verdict = if worst <= max { "PASS" } else { "FAIL" };
        writeln!(
            out,
            "  acceptance     {verdict}: every station's √(σx² + σy²) ≤ {max} m (worst {worst:.4} m at station {k})"
        )?;
    }
    Ok(())
}

/// An MDB in its unit: millimetres for a distance, arcseconds for an angle.
pub fn mdb_text(kind: &str, mdb: Option<f64>) -> String {
    match mdb {
        None => "—".into(),
        Some(m) if kind == "slope_distance" => format!("{:.2} mm", 1e3 * m),
        Some(m) => format!("{:.1}″", m / RAD_PER_ARCSEC),
    }
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
            let verdict = if l.sigma_xy2_m2().sqrt() <= max { "PASS" } else { "FAIL" };
            writeln!(
                out,
                "  acceptance     {verdict}: √(σx² + σy²) = {:.4} m, limit {max} m",
                l.sigma_xy2_m2().sqrt()
            )?;
        }
    }
    write_adjusted(out, mission, planned)
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
            "predicted final: √(σx² + σy²) = {:.4} m (σx² + σy² = {s2:.3e} m²), σθ = {:.2}″",
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
        let sum = s.range_m2 + s.angle_m2 + s.centring_m2 + s.start_m2;
        if (sum - s.total_m2).abs() > 0.05 * s.total_m2 {
            writeln!(
                out,
                "  (the parts add up to {:.0} %: each is the plan with only that source on, and where the plan closes \
                 on control the weights shift with the sources)",
                pct(sum)
            )?;
        }
    }
    if let (Some(m), Some(s2)) = (report.one_more_child_m2, report.sigma_xy2_m2) {
        writeln!(
            out,
            "one more child (straight ahead): √(σx² + σy²) = {:.4} m ({:.2}× the variance as written)",
            m.sqrt(),
            m / s2
        )?;
    }
    if let (Some((stride, n, m)), Some(s2)) = (report.longer_stride, report.sigma_xy2_m2) {
        writeln!(
            out,
            "stride {stride} m ({n} cycles): √(σx² + σy²) = {:.4} m ({:.2}× the variance as written)",
            m.sqrt(),
            m / s2
        )?;
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
    if !report.control.is_empty() {
        writeln!(out, "control (control_at = {}):", plan.control_at)?;
        for c in &report.control {
            let from: Vec<String> = c.from.iter().map(|(k, d)| format!("{k} ({d:.1} m)")).collect();
            let kind = if c.fixed { "fixed" } else { "weighted" };
            writeln!(out, "  {:<10} {kind:<8}  seen from station {}", c.name, from.join(", "))?;
        }
        let start = if report.written.dance.resects_start() {
            "the start is resected on the control it sights"
        } else {
            "the start's pose and start_sigma_* are the datum"
        };
        writeln!(out, "  {start}")?;
    }
    write_adjusted(out, mission, &report.written)?;
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
        if !mission.control.is_empty() {
            writeln!(
                out,
                "  control_at = {} ({} station(s) sight control)",
                o.control_at,
                planner::sighting::setups(&o.planned.dance)
            )?;
        }
        let s2 = o.best.sigma_xy2_m2;
        write!(out, "  predicted final: √(σx² + σy²) = {:.4} m (σx² + σy² = {s2:.3e} m²)", s2.sqrt())?;
        match report.sigma_xy2_m2 {
            Some(w) => writeln!(out, ", {:.2}× better than as written", w / s2)?,
            None => writeln!(out)?,
        }
        if let Some((k, worst)) = o.planned.worst_station() {
            let written = report.written.worst_station().map(|w| w.1);
            writeln!(
                out,
                "  worst station adjusted: √(σx² + σy²) = {worst:.4} m at station {k}{}",
                written.map_or(String::new(), |w| format!(" (as written: {w:.4} m)"))
            )?;
        }
    }
    let a = &mission.acceptance;
    let verdict = if analysis::accepted(mission, report) { "PASS" } else { "FAIL" };
    let mut limits = Vec::new();
    if let Some(max) = a.max_final_sigma_xy_m {
        limits.push(format!("max_final_sigma_xy_m = {max} m"));
    }
    if let Some(max) = a.max_station_sigma_xy_m {
        limits.push(format!("max_station_sigma_xy_m = {max} m"));
    }
    if !limits.is_empty() {
        writeln!(out, "acceptance ({}): {verdict}", limits.join(", "))?;
    } else if verdict == "FAIL" {
        writeln!(out, "FAIL: the plan breaks constraints")?;
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

/// Monte Carlo rows: per station the predicted and empirical σxy, their
/// ratio and the mean NEES (flagged outside `interval`, when given).
fn write_mc_rows(
    out: &mut dyn Write,
    rows: &[planner::montecarlo::CycleStatistics],
    interval: Option<(f64, f64)>,
) -> std::io::Result<()> {
    writeln!(out, "{:>7} {:>13} {:>13} {:>7} {:>9}", "station", "pred σxy_mm", "emp σxy_mm", "ratio", "NEES")?;
    for s in rows {
        let outside = interval.is_some_and(|(lo, hi)| !(lo..=hi).contains(&s.nees_mean));
        writeln!(
            out,
            "{:>7} {:>13.3} {:>13.3} {:>7.3} {:>9.3}{}",
            s.cycle,
            1e3 * cps::sigma_xy2(&s.predicted).sqrt(),
            1e3 * cps::sigma_xy2(&s.empirical).sqrt(),
            s.ratio_xy(),
            s.nees_mean,
            if outside { "  outside" } else { "" }
        )?;
    }
    Ok(())
}

/// `montecarlo`: one row per station, then the verdict.
pub fn montecarlo(out: &mut dyn Write, mission: &Mission, mc: &MonteCarlo) -> std::io::Result<()> {
    writeln!(out, "mission \"{}\": {} trials (seed {}), positioning only", mission.name, mc.trials, mc.seed)?;
    write_mc_rows(out, &mc.stations, None)?;
    let (lo, hi) = mc.nees_interval;
    let last = mc.last().map_or(f64::NAN, |s| s.nees_mean);
    writeln!(out, "final mean NEES {last:.3} (the filter), 95 % interval [{lo:.3}, {hi:.3}] for {} trials", mc.trials)?;
    if !mc.adjusted.is_empty() {
        writeln!(out)?;
        writeln!(out, "the network adjustment of every trial, per station, against the pre-analysis:")?;
        let (alo, ahi) = mc.adjusted_interval;
        write_mc_rows(out, &mc.adjusted, Some(mc.adjusted_interval))?;
        let inside = mc.adjusted.iter().filter(|s| (alo..=ahi).contains(&s.nees_mean)).count();
        writeln!(
            out,
            "adjusted mean NEES within [{alo:.3}, {ahi:.3}] (95 % for all {} stations together): {inside} of {}",
            mc.adjusted.len(),
            mc.adjusted.len()
        )?;
    }
    writeln!(
        out,
        "{}",
        if mc.consistent() { "consistent with the prediction" } else { "NOT consistent with the prediction" }
    )
}
