//! Pipe inspection of a fused cloud (`[pipe]`, seed 000 §5): the tube fitted
//! from the nominal one ([`fusion::pipe::fit_pipe`]), every point's signed
//! deviation from it, and the deviating points grouped into anomalies
//! (obstacles, deformations) with their place along the pipe and around it.
//!
//! **Clock position.** Around the pipe, an anomaly's place is given as a
//! clock hour looking along the fitted axis from `axis_from_m` to
//! `axis_to_m` (the survey direction of sewer inspection codes such as
//! EN 13508-2): 12 is the crown (straight up), 3 the right wall, 6 the
//! invert, 9 the left wall. A vertical pipe has no crown; there 12 is the
//! world's +x side.

use std::path::Path;

use anyhow::{Context, Result};
use fusion::pipe::{Anomaly, AnomalyKind, Pipe, PipeConfig, PipeFit, anomalies, deviation_map, fit_pipe};
use nalgebra::{Point3, Vector3};

use crate::documents::pipe::{AnomalyReport, DeviationStats, PipeFitted, PipeReport, TubeReport};
use crate::mission::PipePlan;

/// File of the deviation map in a run directory.
pub const DEVIATION_FILE: &str = "pipe_deviation.ply";

/// The deviation's names in [`DEVIATION_FILE`]: ours, and CloudCompare's
/// (it loads fields named `scalar_*` as scalar fields), same values.
pub const DEVIATION_FIELDS: [&str; 2] = ["deviation_m", "scalar_deviation_m"];

/// The inspection's results.
#[derive(Debug, Clone)]
pub struct Inspection {
    /// The fitted tube and the fit's figures.
    pub fit: PipeFit,
    /// Signed deviation of every point of the cloud, metres (negative:
    /// inside the fitted tube).
    pub deviations: Vec<f32>,
    /// The deviating groups, largest first.
    pub anomalies: Vec<Anomaly>,
}

/// Fits the pipe into `cloud` from the plan's nominal tube, maps the
/// deviations and groups the anomalies.
pub fn inspect(plan: &PipePlan, cloud: &[Point3<f32>]) -> Result<Inspection> {
    let fit = fit_pipe(cloud, &plan.nominal, &PipeConfig::default()).context("fitting the pipe")?;
    let deviations = deviation_map(cloud, &fit.pipe);
    let anomalies =
        anomalies(cloud, &fit.pipe, plan.threshold_m, plan.link_m, plan.min_points).context("grouping deviations")?;
    Ok(Inspection { fit, deviations, anomalies })
}

/// Writes the deviation map ([`DEVIATION_FILE`]: x, y, z and `deviation_m`
/// per point) into `dir`.
pub fn write_deviation_map(dir: &Path, cloud: &[Point3<f32>], inspection: &Inspection) -> Result<()> {
    let path = dir.join(DEVIATION_FILE);
    scanner::io::write_ply_with_field(&path, cloud, &DEVIATION_FIELDS, &inspection.deviations)?;
    Ok(())
}

/// The clock hour (0 < h ≤ 12) of `point` around `pipe` (module docs).
pub fn clock_hour(pipe: &Pipe, point: &Point3<f64>) -> f64 {
    let n = pipe.direction();
    let reference = if n.z.abs() > 0.999 { Vector3::x() } else { Vector3::z() };
    let up = (reference - reference.dot(&n) * n).normalize();
    let right = n.cross(&up);
    let u = point - pipe.a;
    let radial = u - u.dot(&n) * n;
    let angle = radial.dot(&right).atan2(radial.dot(&up)).to_degrees().rem_euclid(360.0);
    let hour = angle / 30.0;
    if hour < 1e-9 { 12.0 } else { hour }
}

/// `h` as "hh:mm" (12:00 is the crown).
pub fn clock_text(hour: f64) -> String {
    let minutes = (hour * 60.0).round() as i64;
    let (h, m) = (minutes / 60, minutes % 60);
    format!("{:02}:{:02}", if h == 0 { 12 } else { h }, m)
}

fn xyz(p: &Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

fn kind_name(kind: AnomalyKind) -> &'static str {
    match kind {
        AnomalyKind::Intrusion => "intrusion",
        AnomalyKind::Bulge => "bulge",
    }
}

/// An anomaly in a few words: kind, depth and clock position around `pipe`.
pub fn label(pipe: &Pipe, anomaly: &Anomaly) -> String {
    let clock = clock_text(clock_hour(pipe, &anomaly.centroid));
    format!("{} {:.0} mm at {clock}", kind_name(anomaly.kind), 1e3 * anomaly.depth_m)
}

impl From<&Pipe> for TubeReport {
    fn from(p: &Pipe) -> Self {
        Self { axis_from_m: xyz(&p.a), axis_to_m: xyz(&p.b), radius_m: p.radius_m }
    }
}

/// Count, mean, RMS, extremes, 1st and 99th percentiles of the deviations
/// and how many exceed the threshold.
fn deviation_stats(deviations: &[f32], threshold_m: f64) -> DeviationStats {
    let mut sorted: Vec<f64> = deviations.iter().map(|&d| f64::from(d)).collect();
    sorted.sort_unstable_by(f64::total_cmp);
    let n = sorted.len().max(1) as f64;
    let quantile = |q: f64| sorted.get(((sorted.len().max(1) - 1) as f64 * q).round() as usize).copied();
    DeviationStats {
        points: sorted.len(),
        mean_m: sorted.iter().sum::<f64>() / n,
        rms_m: (sorted.iter().map(|d| d * d).sum::<f64>() / n).sqrt(),
        min_m: sorted.first().copied(),
        p01_m: quantile(0.01),
        p99_m: quantile(0.99),
        max_m: sorted.last().copied(),
        beyond_threshold: sorted.iter().filter(|d| d.abs() > threshold_m).count(),
    }
}

/// The report of an inspection: the nominal and fitted tubes, the fit's
/// figures, the deviation statistics and the anomalies.
pub fn report(plan: &PipePlan, inspection: &Inspection) -> PipeReport {
    let (nominal, fitted) = (&plan.nominal, &inspection.fit.pipe);
    let tilt = fitted.direction().angle(&nominal.direction()).to_degrees();
    let anomalies = inspection
        .anomalies
        .iter()
        .map(|a| {
            let hour = clock_hour(fitted, &a.centroid);
            AnomalyReport {
                kind: kind_name(a.kind).into(),
                points: a.points,
                centroid_m: xyz(&a.centroid),
                axial_from_m: a.axial_m.0,
                axial_to_m: a.axial_m.1,
                clock: clock_text(hour),
                clock_hour: hour,
                bounds_min_m: xyz(&a.bounds.0),
                bounds_max_m: xyz(&a.bounds.1),
                size_m: xyz(&Point3::from(a.bounds.1 - a.bounds.0)),
                depth_m: a.depth_m,
                max_deviation_m: a.max_deviation_m,
            }
        })
        .collect();
    PipeReport::Fitted(Box::new(PipeFitted {
        nominal: nominal.into(),
        fitted: fitted.into(),
        radius_change_m: fitted.radius_m - nominal.radius_m,
        axis_tilt_deg: tilt.min(180.0 - tilt),
        iterations: inspection.fit.iterations,
        converged: inspection.fit.converged,
        inliers: inspection.fit.inliers,
        rmse_m: inspection.fit.rmse_m,
        gate_m: inspection.fit.gate_m,
        threshold_m: plan.threshold_m,
        link_m: plan.link_m,
        min_points: plan.min_points,
        deviations: deviation_stats(&inspection.deviations, plan.threshold_m),
        deviation_file: DEVIATION_FILE.into(),
        anomalies,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Along +x with z up: the crown is 12, the right wall (−y) 3, the
    /// invert 6, the left wall (+y) 9 — and reversing the axis swaps
    /// right and left.
    #[test]
    fn clock_hours_around_a_horizontal_pipe() {
        let pipe = Pipe { a: Point3::new(0.0, 0.0, 0.5), b: Point3::new(20.0, 0.0, 0.5), radius_m: 0.5 };
        let at = |y: f64, z: f64| clock_hour(&pipe, &Point3::new(7.0, y, 0.5 + z));
        assert!((at(0.0, 0.5) - 12.0).abs() < 1e-9);
        assert!((at(-0.5, 0.0) - 3.0).abs() < 1e-9);
        assert!((at(0.0, -0.5) - 6.0).abs() < 1e-9);
        assert!((at(0.5, 0.0) - 9.0).abs() < 1e-9);
        // Half-way between the invert and the left wall: 7:30.
        assert_eq!(clock_text(at(0.3, -0.3)), "07:30");
        let back = Pipe { a: pipe.b, b: pipe.a, radius_m: 0.5 };
        assert!((clock_hour(&back, &Point3::new(7.0, -0.5, 0.5)) - 9.0).abs() < 1e-9);
        assert_eq!(clock_text(12.0), "12:00");
        assert_eq!(clock_text(0.5), "12:30");
    }
}
