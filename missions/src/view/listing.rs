//! The adjustment as a surveyor files it (`adjustment.txt`, in the spirit
//! of GNU Gama's and STAR*NET's listings: the input summary, the control,
//! the adjusted coordinates with σ and ellipses, the residual table with r,
//! w and MDB, the tests, what was removed) and its summary on the terminal.

use std::fmt::Write as _;
use std::io::Write;

use crate::documents::adjustment::AdjustmentReport;
use crate::mission::Mission;

fn mm(v: f64) -> String {
    format!("{:.2}", 1e3 * v)
}

fn opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.map_or("-".into(), f)
}

/// A value in its kind's display unit: metres as mm, radians as arc-seconds.
fn in_unit(kind: &str, v: f64) -> String {
    match kind {
        "slope_distance" | "x" | "y" | "z" => format!("{:.2} mm", 1e3 * v),
        _ => format!("{:.2}″", v / cps::RAD_PER_ARCSEC),
    }
}

/// The verdict of the global test in words: of every observation, and
/// after data snooping's removals.
fn global(report: &AdjustmentReport) -> String {
    let g = &report.global_test;
    let (Some(lo), Some(hi)) = (g.lower, g.upper) else {
        return "global test: no redundancy, nothing to test".into();
    };
    let mut text = format!(
        "global test: vᵀPv = {:.2}, χ²_{}({:.3}, {:.3}) = [{lo:.2}, {hi:.2}]: {}",
        g.statistic,
        g.dof,
        g.alpha / 2.0,
        1.0 - g.alpha / 2.0,
        if g.passed { "PASS" } else { "FAIL" }
    );
    if let Some(a) = &report.global_test_after_snooping
        && let Some(hi) = a.upper
    {
        let removals = report.removed.len() + report.removed_coordinates.len();
        text += &after_snooping(removals, a.statistic, hi, a.dof, a.alpha);
    }
    text
}

/// The global test after snooping's `removed` removals, its relation as it
/// is (issue 34, U8 printed "80.81 ≤ 77.38 … FAIL").
fn after_snooping(removed: usize, statistic: f64, hi: f64, dof: usize, alpha: f64) -> String {
    let (relation, verdict) = if statistic <= hi { ("≤", "PASS") } else { (">", "FAIL") };
    format!(
        "; after snooping's {removed} removal(s) vᵀPv = {statistic:.2} {relation} {hi:.2} (χ²_{dof}({:.3})): {verdict}",
        1.0 - alpha / 2.0,
    )
}

/// The full listing (`adjustment.txt`).
pub fn listing(mission: &Mission, report: &AdjustmentReport) -> String {
    let mut s = String::new();
    let w = &mut s;
    let _ = writeln!(w, "cps-survey network adjustment — mission \"{}\"", mission.name);
    let _ = writeln!(w, "{}", "=".repeat(72));
    let _ = writeln!(w);
    let _ = writeln!(w, "Input");
    let _ = writeln!(
        w,
        "  stations {}, points {} ({} control), observations {} ({} removed), prior coordinates {} ({} removed)",
        report.stations.len(),
        report.points.len(),
        report.points.iter().filter(|p| p.control).count(),
        report.observations.len(),
        report.removed.len(),
        report.coordinate_observations.len(),
        report.removed_coordinates.len()
    );
    let _ = writeln!(
        w,
        "  unknowns {}, redundancy {}, iterations {} ({})",
        report.unknowns,
        report.redundancy,
        report.iterations,
        if report.converged { "converged" } else { "NOT converged" }
    );
    let t = &report.testing;
    let _ = writeln!(
        w,
        "  tests: α = {}, α0 = {}, β0 = {}, λ0 = {:.2}, |w| critical {:.3}, data snooping {}",
        t.alpha,
        t.alpha0,
        t.beta0,
        t.lambda0,
        t.w_critical,
        if t.snooping { "on" } else { "off" }
    );
    let _ = writeln!(w);
    let _ = writeln!(w, "Control points (given, σ)");
    for c in &mission.control {
        let sd = |k: usize| c.covariance[(k, k)].sqrt();
        let held = |k: usize| if sd(k) > 0.0 { format!("{:.1}", 1e3 * sd(k)) } else { "fixed".into() };
        let _ = writeln!(
            w,
            "  {:<10} {:>12.4} {:>12.4} {:>10.4}   σ mm {:>6} {:>6} {:>6}",
            c.name,
            c.position_m.x,
            c.position_m.y,
            c.position_m.z,
            held(0),
            held(1),
            held(2)
        );
    }
    let _ = writeln!(w);
    let _ = writeln!(w, "Adjusted stations (σ and 95 % ellipses in mm, heading σ in arc-seconds)");
    let _ = writeln!(
        w,
        "  {:>4} {:>12} {:>12} {:>10} {:>7} {:>7} {:>7} {:>7} {:>8} {:>8} {:>7} {:>8} {:>8}",
        "st", "x_m", "y_m", "z_m", "σx", "σy", "σz", "σθ″", "a95", "b95", "az°", "rel a95", "rel b95"
    );
    for st in &report.stations {
        let c = &st.covariance;
        let _ = writeln!(
            w,
            "  {:>4} {:>12.4} {:>12.4} {:>10.4} {:>7} {:>7} {:>7} {:>7.2} {:>8} {:>8} {:>7.1} {:>8} {:>8}",
            st.index,
            st.x_m,
            st.y_m,
            st.z_m,
            mm(c[0][0].max(0.0).sqrt()),
            mm(c[1][1].max(0.0).sqrt()),
            mm(c[2][2].max(0.0).sqrt()),
            c[3][3].max(0.0).sqrt() / cps::RAD_PER_ARCSEC,
            mm(st.ellipse_95.semi_major_m),
            mm(st.ellipse_95.semi_minor_m),
            st.ellipse_95.orientation_rad.to_degrees(),
            opt(st.relative_ellipse_95.map(|e| e.semi_major_m), mm),
            opt(st.relative_ellipse_95.map(|e| e.semi_minor_m), mm),
        );
    }
    let _ = writeln!(w);
    let _ = writeln!(w, "Adjusted points (σ in mm)");
    for p in report.points.iter().filter(|p| p.control) {
        let c = &p.covariance;
        let _ = writeln!(
            w,
            "  {:<10} {:>12.4} {:>12.4} {:>10.4}   σ {:>6} {:>6} {:>6}",
            p.id,
            p.x_m,
            p.y_m,
            p.z_m,
            mm(c[0][0].max(0.0).sqrt()),
            mm(c[1][1].max(0.0).sqrt()),
            mm(c[2][2].max(0.0).sqrt())
        );
    }
    let _ = writeln!(
        w,
        "  ({} child placements: report.json / adjust --json)",
        report.points.iter().filter(|p| !p.control).count()
    );
    let _ = writeln!(w);
    let _ = writeln!(w, "Misclosures at control (the survey alone, its datum only, minus given; mm)");
    if report.misclosures.is_empty() {
        let _ = writeln!(w, "  none: every control point is part of the datum");
    }
    for m in &report.misclosures {
        let _ = writeln!(
            w,
            "  {:<10} dx {:>8} dy {:>8} dz {:>8}  horizontal {:>8} ± {:>7}  χ²₂ {}",
            m.control,
            mm(m.dx_m),
            mm(m.dy_m),
            mm(m.dz_m),
            mm(m.horizontal_m),
            mm(m.sigma_horizontal_m),
            opt(m.chi2_horizontal, |c| format!("{c:.2}"))
        );
    }
    let _ = writeln!(w);
    let _ = writeln!(w, "Observations (residual = adjusted − observed; r redundancy number; MDB at λ0)");
    let _ = writeln!(
        w,
        "  {:>5} {:>4} {:<10} {:<15} {:>15} {:>12} {:>12} {:>6} {:>7} {:>12} {:>8}",
        "obs", "st", "target", "kind", "value", "residual", "σ", "r", "w", "MDB", "shift mm"
    );
    for o in &report.observations {
        let value = if o.kind == "slope_distance" {
            format!("{:.4} m", o.value)
        } else {
            format!("{:.5}°", o.value.to_degrees())
        };
        let flag = if o.removed {
            " REMOVED"
        } else if o.redundancy < planner::analysis::UNCHECKED_REDUNDANCY {
            " unchecked"
        } else if o.w.is_some_and(|w| w.abs() > report.testing.w_critical) {
            " *"
        } else {
            ""
        };
        let _ = writeln!(
            w,
            "  {:>5} {:>4} {:<10} {:<15} {:>15} {:>12} {:>12} {:>6.3} {:>7} {:>12} {:>8}{flag}",
            o.index,
            o.station,
            o.target,
            o.kind,
            value,
            in_unit(&o.kind, o.residual),
            in_unit(&o.kind, o.sigma),
            o.redundancy,
            opt(o.w, |w| format!("{w:.2}")),
            opt(o.mdb, |m| in_unit(&o.kind, m)),
            opt(o.station_shift_m, mm),
        );
    }
    if !report.coordinate_observations.is_empty() {
        let _ = writeln!(w);
        let _ = writeln!(w, "Prior coordinates (residual = adjusted − given)");
        for c in &report.coordinate_observations {
            let tests = if c.removed {
                format!("removed by data snooping (w {:.2})", c.w.unwrap_or(f64::NAN))
            } else {
                format!(
                    "r {:>6.3} w {:>7} MDB {:>12}",
                    c.redundancy,
                    opt(c.w, |w| format!("{w:.2}")),
                    opt(c.mdb, |m| in_unit(&c.coordinate, m))
                )
            };
            let _ = writeln!(
                w,
                "  {:<12} {:<8} residual {:>12} σ {:>12} {tests}",
                c.of,
                c.coordinate,
                in_unit(&c.coordinate, c.residual),
                in_unit(&c.coordinate, c.sigma),
            );
        }
    }
    let _ = writeln!(w);
    let _ = writeln!(w, "Tests");
    let _ = writeln!(w, "  σ0² = {:.4} (redundancy {})", report.sigma0_squared, report.redundancy);
    let _ = writeln!(w, "  {}", global(report));
    summary_lines(w, report);
    s
}

/// The lines both the listing and the terminal give: removals, the worst
/// MDB, observations nothing checks, w warnings.
fn summary_lines(w: &mut String, report: &AdjustmentReport) {
    if report.removed.is_empty() && report.removed_coordinates.is_empty() {
        let _ = writeln!(w, "  data snooping: nothing removed");
    }
    for &i in &report.removed_coordinates {
        if let Some(c) = report.coordinate_observations.get(i) {
            let _ = writeln!(
                w,
                "  removed prior coordinate {} of {}: w = {:.2}, residual {} (adjusted − given)",
                c.coordinate,
                c.of,
                c.w.unwrap_or(f64::NAN),
                in_unit(&c.coordinate, c.residual)
            );
        }
    }
    for (n, &i) in report.removed.iter().enumerate() {
        if let Some(o) = report.observations.get(i) {
            let _ = writeln!(
                w,
                "  removed ({}) observation {i}: {} of {} from station {}, w = {:.2}, residual {}",
                n + 1,
                o.kind,
                o.target,
                o.station,
                o.w.unwrap_or(f64::NAN),
                in_unit(&o.kind, o.residual)
            );
        }
    }
    if let Some(why) = &report.snooping_stopped {
        let _ = writeln!(w, "  data snooping stopped: {why}");
    }
    if let Some(m) = &report.worst_mdb
        && let Some(o) = report.observations.get(m.observation)
    {
        let _ = writeln!(
            w,
            "  worst MDB: observation {} ({} of {} from station {}), MDB {}, moves station {} by {:.2} mm",
            m.observation,
            o.kind,
            o.target,
            o.station,
            opt(o.mdb, |v| in_unit(&o.kind, v)),
            m.station,
            1e3 * m.shift_m
        );
    }
    let unchecked = report
        .observations
        .iter()
        .filter(|o| !o.removed && o.redundancy < planner::analysis::UNCHECKED_REDUNDANCY)
        .count();
    let _ = writeln!(w, "  {unchecked} observation(s) checked by nothing (r < 0.01)");
    for o in
        report.observations.iter().filter(|o| !o.removed && o.w.is_some_and(|w| w.abs() > report.testing.w_critical))
    {
        let _ = writeln!(
            w,
            "  warning: observation {} ({} of {} from station {}) has |w| = {:.2} > {:.2}",
            o.index,
            o.kind,
            o.target,
            o.station,
            o.w.unwrap_or(0.0).abs(),
            report.testing.w_critical
        );
    }
}

/// The terminal summary after a run's station table or `adjust`.
pub fn summary(out: &mut dyn Write, report: &AdjustmentReport) -> std::io::Result<()> {
    let worst = report.stations.iter().max_by(|a, b| a.sigma_xy_m.total_cmp(&b.sigma_xy_m));
    let mut s = String::new();
    let _ = writeln!(
        s,
        "network adjustment: {} stations, {} points, {} observations, redundancy {}; σ0² = {:.3}; worst station σxy {}",
        report.stations.len(),
        report.points.len(),
        report.observations.len(),
        report.redundancy,
        report.sigma0_squared,
        worst.map_or("-".into(), |w| format!("{} mm at station {}", mm(w.sigma_xy_m), w.index))
    );
    let _ = writeln!(s, "  {}", global(report));
    for m in &report.misclosures {
        let _ = writeln!(
            s,
            "  misclosure at {}: {} mm horizontal (± {} mm), {} mm in z",
            m.control,
            mm(m.horizontal_m),
            mm(m.sigma_horizontal_m),
            mm(m.dz_m)
        );
    }
    summary_lines(&mut s, report);
    out.write_all(s.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::after_snooping;

    #[test]
    fn the_global_test_after_snooping_states_the_relation_it_found() {
        assert_eq!(
            after_snooping(1, 80.81, 77.38, 58, 0.05),
            "; after snooping's 1 removal(s) vᵀPv = 80.81 > 77.38 (χ²_58(0.975)): FAIL"
        );
        assert!(after_snooping(0, 50.0, 77.38, 58, 0.05).ends_with("50.00 ≤ 77.38 (χ²_58(0.975)): PASS"));
    }
}
