//! The network adjustment of a run (`cps-survey adjust`, and at the end of
//! `run`): the journal's readings as one network ([`planner::network`]),
//! adjusted by [`cps::batch`] with its tests, the misclosures at the
//! control points, and its report ([`crate::documents::adjustment`]).
//!
//! **Misclosures.** Before the adjustment ties the route to a control
//! point, the survey and the other control points say where it is: the
//! network adjusted without that point's given coordinates (its sightings
//! kept). The misclosure of a control point is that position minus its
//! given coordinates, with the covariance of the difference (the surveyed
//! position's and the given coordinates' with the prism's centring). A
//! point without which the rest cannot hold the network (one of the two a
//! start is resected on, sighted nowhere else) has none.

mod network;

use anyhow::{Context, Result};
use cps::Reading;
use cps::batch::{AdjustOptions, Adjustment, ScalarStats, Source};
use nalgebra::{Matrix3, Point3};
use planner::network::{DanceNetwork, PointId};

use crate::documents::adjustment::*;
use crate::documents::records::{Ellipse, rows};
use crate::mission::Mission;
use crate::planning::Planned;
use crate::planning::preanalysis::{KINDS, point_name};

pub use network::network;

/// Adjusts the run's network: the statistics with `options`, the
/// misclosures, the report.
pub fn adjust(
    mission: &Mission,
    planned: &Planned,
    net: &DanceNetwork,
    options: &AdjustOptions,
) -> Result<AdjustmentReport> {
    let a = cps::batch::adjust(&net.network, options).context("adjusting the network")?;
    let name =
        |p: usize| net.points.get(p).map_or_else(|| format!("point {p}"), |id| point_name(mission, &planned.dance, id));
    let lambda0 = cps::stats::noncentrality(options.alpha0, options.beta0);
    let stations = (0..a.stations.len())
        .map(|k| {
            let p = &a.stations[k];
            let cov = a.station_covariance(k);
            StationAdjusted {
                index: k,
                x_m: p.position.x,
                y_m: p.position.y,
                z_m: p.position.z,
                heading_rad: p.heading_rad,
                covariance: rows(&cov),
                sigma_xy_m: cps::sigma_xy2(&cov).sqrt(),
                ellipse_95: Ellipse::of_95(&cov.fixed_view::<2, 2>(0, 0).into_owned()),
                relative_ellipse_95: k
                    .checked_sub(1)
                    .map(|j| Ellipse::of_95(&a.relative_covariance(j).fixed_view::<2, 2>(0, 0).into_owned())),
            }
        })
        .collect();
    let points = (0..a.points.len())
        .map(|p| {
            let x = &a.points[p];
            PointAdjusted {
                id: name(p),
                control: matches!(net.points.get(p), Some(PointId::Control(_))),
                x_m: x.x,
                y_m: x.y,
                z_m: x.z,
                covariance: rows(&a.point_covariance(p)),
            }
        })
        .collect();
    let (observations, removed) = observation_reports(&a, net, &name);
    let (coordinate_observations, removed_coordinates) = coordinate_reports(&a, net, &name);
    let worst_mdb = observations
        .iter()
        .filter(|o: &&ObservationReport| o.redundancy >= cps::batch::statistics::WEAKLY_CHECKED)
        .filter_map(|o| o.station_shift_m.map(|s| (o.index, o.station, s)))
        .max_by(|x, y| x.2.total_cmp(&y.2))
        .map(|(observation, station, shift_m)| WorstMdb { observation, station, shift_m });
    Ok(AdjustmentReport {
        schema_version: SCHEMA_VERSION,
        tool_version: crate::documents::TOOL_VERSION.into(),
        sigma0_squared: a.sigma0_squared,
        redundancy: a.redundancy,
        unknowns: a.unknowns,
        iterations: a.iterations,
        converged: a.converged,
        global_test: (&a.global_test).into(),
        global_test_after_snooping: a.after_snooping.as_ref().map(Into::into),
        model_accepted: a.model_accepted(),
        testing: TestingReport {
            alpha: options.alpha,
            alpha0: options.alpha0,
            beta0: options.beta0,
            lambda0,
            w_critical: a.w_critical,
            snooping: options.snooping,
        },
        stations,
        points,
        observations,
        coordinate_observations,
        removed_coordinates,
        removed,
        snooping_stopped: a.snooping_stopped.clone(),
        misclosures: misclosures(net, &name, &a),
        worst_mdb,
    })
}

/// Every reading's (r, φ, ψ), in network order, with its statistics — a
/// removed one with its residual at the final estimate and its w when
/// removed; and the removed ones' indices in the order removed.
fn observation_reports(
    a: &Adjustment,
    net: &DanceNetwork,
    name: &dyn Fn(usize) -> String,
) -> (Vec<ObservationReport>, Vec<usize>) {
    // Indexed once: a search per observation made the report quadratic
    // (a 40 km run's 48,000 readings: 2 s of 5).
    let by_reading: std::collections::HashMap<(usize, usize), &ScalarStats> = a
        .observations
        .iter()
        .filter_map(|o| match o.source {
            Source::Reading(k) => Some(((k, o.component), o)),
            _ => None,
        })
        .collect();
    let stat = |k: usize, c: usize| -> Option<&ScalarStats> { by_reading.get(&(k, c)).copied() };
    let mut out = Vec::with_capacity(3 * net.network.readings.len());
    for (k, r) in net.network.readings.iter().enumerate() {
        let value = r.reading.to_vector();
        let adjusted: Option<Reading> = cps::observe(&a.stations[r.station], &a.points[r.point]).ok();
        for c in 0..3 {
            let index = out.len();
            let base = ObservationReport {
                index,
                station: r.station,
                target: name(r.point),
                kind: KINDS[c].into(),
                value: value[c],
                sigma: r.covariance[(c, c)].sqrt(),
                residual: f64::NAN,
                redundancy: 0.0,
                w: None,
                mdb: None,
                bnr: None,
                station_shift_m: None,
                removed: false,
            };
            out.push(match stat(k, c) {
                Some(o) => ObservationReport {
                    residual: o.residual,
                    redundancy: o.redundancy,
                    w: o.w,
                    mdb: o.mdb,
                    bnr: o.bnr,
                    station_shift_m: o.station_shift_m,
                    ..base
                },
                None => {
                    let at = a.removed.iter().find(|x| x.source == Source::Reading(k) && x.component == c);
                    let residual = adjusted.map_or(f64::NAN, |adj| {
                        let d = adj.to_vector()[c] - value[c];
                        if c == 1 { cps::wrap_angle(d) } else { d }
                    });
                    ObservationReport { residual, w: at.map(|x| x.w), removed: true, ..base }
                }
            });
        }
    }
    let removed = a
        .removed
        .iter()
        .filter_map(|x| match x.source {
            Source::Reading(k) => Some(3 * k + x.component),
            _ => None,
        })
        .collect();
    (out, removed)
}

/// The weighted prior coordinates with their statistics, and after them
/// those data snooping removed (issue 34, S1: they were left out, and "0
/// removal(s)" reported) with their w then and their residual at the final
/// estimate; and the removed ones' indices in the order removed.
fn coordinate_reports(
    a: &Adjustment,
    net: &DanceNetwork,
    name: &dyn Fn(usize) -> String,
) -> (Vec<CoordinateReport>, Vec<usize>) {
    let label = |source: Source, component: usize| -> Option<(String, String)> {
        let (of, names): (String, &[&str]) = match source {
            Source::StationPrior(k) => (format!("station {k}"), &["x", "y", "z", "heading"]),
            Source::PointPrior(p) => (name(p), &["x", "y", "z"]),
            Source::Reading(_) => return None,
        };
        Some((of, names.get(component).copied().unwrap_or("?").into()))
    };
    let mut out: Vec<CoordinateReport> = a
        .observations
        .iter()
        .filter_map(|o| {
            let (of, coordinate) = label(o.source, o.component)?;
            Some(CoordinateReport {
                of,
                coordinate,
                sigma: o.sigma,
                residual: o.residual,
                redundancy: o.redundancy,
                w: o.w,
                mdb: o.mdb,
                removed: false,
            })
        })
        .collect();
    let mut removed = Vec::new();
    for x in &a.removed {
        let Some((of, coordinate)) = label(x.source, x.component) else { continue };
        // Adjusted − given, and the given coordinate's σ.
        let (residual, sigma) = match x.source {
            Source::StationPrior(k) => {
                let st = &net.network.stations[k];
                let v = |p: &cps::ParentPose| [p.position.x, p.position.y, p.position.z, p.heading_rad];
                let d = v(&a.stations[k])[x.component] - v(&st.pose)[x.component];
                let d = if x.component == 3 { cps::wrap_angle(d) } else { d };
                (d, st.prior.map_or(f64::NAN, |c| c[(x.component, x.component)].sqrt()))
            }
            Source::PointPrior(p) => {
                let pt = &net.network.points[p];
                let d = a.points[p][x.component] - pt.position[x.component];
                (d, pt.prior.map_or(f64::NAN, |c| c[(x.component, x.component)].sqrt()))
            }
            Source::Reading(_) => continue,
        };
        removed.push(out.len());
        out.push(CoordinateReport {
            of,
            coordinate,
            sigma,
            residual,
            redundancy: 0.0,
            w: Some(x.w),
            mdb: None,
            removed: true,
        });
    }
    (out, removed)
}

/// The misclosures at the control points outside the datum (module docs),
/// without what data snooping removed (`removed`; issue 34, S2: a 0.5 m
/// blunder, removed, still gave 21–55 mm misclosures beside "model
/// accepted").
fn misclosures(net: &DanceNetwork, name: &dyn Fn(usize) -> String, a: &Adjustment) -> Vec<Misclosure> {
    let removed: Vec<(Source, usize)> = a.removed.iter().map(|x| (x.source, x.component)).collect();
    let options = AdjustOptions { snooping: false, ..AdjustOptions::default() };
    let control: Vec<usize> =
        net.points.iter().enumerate().filter(|(_, id)| matches!(id, PointId::Control(_))).map(|(p, _)| p).collect();
    // One adjustment and an update a point (`cps::batch::freed`; issue 35:
    // an adjustment a point took 2.96 s for 41 control points). Without
    // this point's coordinates the rest may not hold the network (a start
    // resected on two points): no misclosure then.
    let Ok(freed) = cps::batch::freed::freed_points(&net.network, &options, &removed, &control, Some(a)) else {
        return Vec::new();
    };
    control
        .iter()
        .zip(freed)
        .filter_map(|(&p, freed)| {
            let freed = freed?;
            let given_cov = net.network.points[p].prior.unwrap_or_else(Matrix3::zeros);
            let given = net.network.points[p].position;
            let d: Point3<f64> = Point3::from(freed.position - given);
            let cov: Matrix3<f64> = freed.covariance + given_cov;
            let xy = cov.fixed_view::<2, 2>(0, 0).into_owned();
            Some(Misclosure {
                control: name(p),
                dx_m: d.x,
                dy_m: d.y,
                dz_m: d.z,
                horizontal_m: d.x.hypot(d.y),
                sigma_horizontal_m: xy.trace().sqrt(),
                sigma_z_m: cov[(2, 2)].sqrt(),
                chi2_horizontal: xy.try_inverse().map(|inv| (d.coords.xy().transpose() * inv * d.coords.xy())[(0, 0)]),
            })
        })
        .collect()
}
