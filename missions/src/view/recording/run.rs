//! A run's events in a recording: the scene, the team at each step, sight
//! lines, trajectories, scans, ICP iterations, the pipe inspection, the
//! network adjustment and the per-station series (the table in the
//! recording's module doc).

use anyhow::Result;
use cps::geom::Scene;
use cps::{ParentPose, TeamState};
use nalgebra::{Matrix3, Matrix4, Point3};

use crate::documents::adjustment::AdjustmentReport;
use crate::inspection::{Inspection, label};
use crate::mission::Mission;
use crate::view::shapes::{ellipse_scale, ellipse_scale_name, scene_mesh};

use super::colours::{deviation_colour, ellipsoid_95, red, w_colour};
use super::{DISPLAY_VOXEL_M, PIPE_DISPLAY_POINTS, Recorder, ScanJob, p32, rr};

impl Recorder {
    /// Static content: axes convention, the scene, the robots' bodies.
    pub fn scene(&mut self, scene: &Scene) -> Result<()> {
        self.world(Some(scene))?;
        let Some(rec) = &self.rec else { return Ok(()) };
        for (k, name) in self.robots.iter().enumerate() {
            for (root, alpha) in [("robots", 255), ("truth", 90)] {
                let path = format!("world/{root}/{name}/body");
                if k == 0 {
                    let colour = rerun::Color::from_unmultiplied_rgba(60, 120, 230, alpha);
                    rr(rec.log_static(
                        path,
                        &rerun::Boxes3D::from_half_sizes([[0.35_f32, 0.25, 0.2]]).with_colors([colour]),
                    ))?;
                } else {
                    let colour = rerun::Color::from_unmultiplied_rgba(240, 140, 40, alpha);
                    rr(rec.log_static(
                        path,
                        &rerun::Points3D::new([[0.0_f32, 0.0, 0.0]]).with_radii([0.08_f32]).with_colors([colour]),
                    ))?;
                }
            }
        }
        Ok(())
    }

    /// The axes convention and, when given, the scene (static).
    pub fn world(&mut self, scene: Option<&Scene>) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        rr(rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP()))?;
        if let Some(scene) = scene {
            let (vertices, triangles) = scene_mesh(scene);
            rr(rec.log_static(
                "world/scene",
                &rerun::Mesh3D::new(vertices)
                    .with_triangle_indices(triangles)
                    .with_albedo_factor(rerun::datatypes::Rgba32::from_unmultiplied_rgba(200, 200, 210, 60)),
            ))?;
        }
        Ok(())
    }

    /// Every robot's estimated and true pose and 95 % ellipsoids (achieved,
    /// and predicted when given: the parent's 4×4 and each child's 3×3).
    pub fn team(
        &mut self,
        team: &TeamState,
        truth: Option<&scanner::sim::Truth>,
        predicted: Option<(&Matrix4<f64>, &[Matrix3<f64>])>,
    ) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        let transform = |p: &Point3<f64>, heading: f64| {
            rerun::Transform3D::from_translation_rotation(
                p32(p),
                rerun::Quaternion::from_xyzw([0.0, 0.0, (heading / 2.0).sin() as f32, (heading / 2.0).cos() as f32]),
            )
        };
        let parent = team.parent();
        // (estimate, heading, true position and heading); a child not yet
        // placed is shown where it truly stands (sim) or not at all.
        let mut poses =
            vec![(Some(parent.position), parent.heading_rad, truth.map(|t| (t.parent.position, t.parent.heading_rad)))];
        for j in 0..team.n_children() {
            let true_p = truth.and_then(|t| t.children.get(j).copied());
            poses.push((team.child(j).or(true_p), 0.0, true_p.map(|p| (p, 0.0))));
        }
        for (k, (name, (est, heading, true_pose))) in self.robots.iter().zip(&poses).enumerate() {
            let Some(est) = est else { continue };
            rr(rec.log(format!("world/robots/{name}"), &transform(est, *heading)))?;
            if let Some((true_p, true_heading)) = true_pose {
                rr(rec.log(format!("world/truth/{name}"), &transform(true_p, *true_heading)))?;
            }
            let achieved = if k == 0 {
                team.parent_covariance().fixed_view::<3, 3>(0, 0).into_owned()
            } else {
                team.child_covariance(k - 1)
            };
            let mut ellipsoids = vec![("achieved_95pct", achieved, rerun::Color::from_rgb(60, 120, 230))];
            if let Some((p, children)) = predicted {
                let c =
                    if k == 0 { Some(p.fixed_view::<3, 3>(0, 0).into_owned()) } else { children.get(k - 1).copied() };
                if let Some(c) = c {
                    ellipsoids.push(("predicted_95pct", c, rerun::Color::from_rgb(230, 200, 40)));
                }
            }
            for (what, cov, colour) in ellipsoids {
                let (half, q) = ellipsoid_95(&cov);
                rr(rec.log(
                    format!("world/uncertainty/{name}/{what}"),
                    &rerun::Ellipsoids3D::from_centers_and_half_sizes([p32(est)], [half])
                        .with_quaternions([q])
                        .with_colors([colour])
                        .with_fill_mode(rerun::FillMode::MajorWireframe),
                ))?;
            }
        }
        Ok(())
    }

    /// Sight lines from the parent to children; `w` per line (fix phase)
    /// colours them, `None` (placement: nothing checks it) is grey.
    pub fn sight_lines(&mut self, phase: &str, from: &Point3<f64>, to: &[(Point3<f64>, Option<f64>)]) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        let strips: Vec<[[f32; 3]; 2]> = to.iter().map(|(p, _)| [p32(from), p32(p)]).collect();
        let colours: Vec<rerun::Color> = to.iter().map(|(_, w)| w_colour(*w)).collect();
        rr(rec.log(
            format!("world/sight_lines/{phase}"),
            &rerun::LineStrips3D::new(strips).with_colors(colours).with_radii([0.01_f32]),
        ))
    }

    /// Adds the parent's estimated and true position to its trajectories.
    pub fn trajectory(&mut self, estimate: &ParentPose, truth: Option<&ParentPose>) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        let parent = self.robots.first().map_or("parent", String::as_str);
        for (what, p, colour) in [
            ("estimate", Some(estimate), rerun::Color::from_rgb(60, 120, 230)),
            ("truth", truth, rerun::Color::from_unmultiplied_rgba(60, 120, 230, 90)),
        ] {
            let Some(p) = p else { continue };
            let line = self.trajectories.entry(what).or_default();
            line.push(p32(&p.position));
            rr(rec.log(
                format!("world/trajectories/{parent}/{what}"),
                &rerun::LineStrips3D::new([line.clone()]).with_colors([colour]).with_radii([0.02_f32]),
            ))?;
        }
        Ok(())
    }

    /// One scan in the world frame, thinned to [`DISPLAY_VOXEL_M`] and
    /// coloured by height (on the worker thread); `kind` is `direct` or `icp`.
    pub fn scan(&mut self, kind: &str, name: &str, world_points: Vec<Point3<f32>>) -> Result<()> {
        let now = self.now();
        self.scan_at(kind, name, world_points, now)
    }

    /// Like [`Recorder::scan`], at an earlier time `at` from [`Recorder::now`]
    /// (an ICP-refined scan shown where its direct twin was taken).
    pub fn scan_at(&mut self, kind: &str, name: &str, world_points: Vec<Point3<f32>>, at: (i64, f64)) -> Result<()> {
        let Some((send, _)) = &self.scans else { return Ok(()) };
        let job =
            ScanJob { path: format!("world/scans/{kind}/{name}"), points: world_points, step: at.0, sim_time_s: at.1 };
        if send.send(job).is_err() {
            // The worker stopped on an error; `finish` reports it.
            self.scans.take().map(|(_, worker)| worker.join());
            anyhow::bail!("the recording's scan thread stopped");
        }
        Ok(())
    }

    /// Every ICP iteration of the fusion on the `icp_iteration` timeline
    /// (one tick per iteration, runs in the order they ran): each scan's
    /// points once, in its own frame, under a transform that follows the
    /// scan's world pose through the iterations, and how far each
    /// iteration moved it. `names[k]` and `bodies[k]` are scan k's.
    pub fn icp_iterations(
        &mut self,
        traces: &[fusion::multiview::IcpTrace],
        names: &[String],
        bodies: &[&[Point3<f32>]],
    ) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        rec.reset_time();
        let mut tick = 0_i64;
        let mut shown = vec![false; names.len()];
        let (mut ticks, mut shifts) = (Vec::new(), Vec::new());
        for t in traces {
            let (Some(name), Some(body)) = (names.get(t.scan), bodies.get(t.scan)) else { continue };
            let path = format!("world/scans/icp_iterations/{name}");
            let mut previous: Option<nalgebra::Isometry3<f64>> = None;
            for pose in &t.world_from_scan {
                rec.set_time_sequence("icp_iteration", tick);
                if !shown[t.scan] {
                    shown[t.scan] = true;
                    let thin = scanner::reduced_points(body, DISPLAY_VOXEL_M * 2.0).unwrap_or_else(|_| body.to_vec());
                    rr(rec.log(
                        format!("{path}/points"),
                        &rerun::Points3D::new(thin.iter().map(|p| [p.x, p.y, p.z]))
                            .with_colors([rerun::Color::from_rgb(230, 120, 40)])
                            .with_radii([0.015_f32]),
                    ))?;
                }
                let q = pose.rotation.coords;
                rr(rec.log(
                    path.as_str(),
                    &rerun::Transform3D::from_translation_rotation(
                        p32(&Point3::from(pose.translation.vector)),
                        rerun::Quaternion::from_xyzw([q.x as f32, q.y as f32, q.z as f32, q.w as f32]),
                    ),
                ))?;
                if let Some(p) = previous {
                    ticks.push(tick);
                    shifts.push((pose.translation.vector - p.translation.vector).norm());
                }
                previous = Some(*pose);
                tick += 1;
            }
        }
        if !ticks.is_empty() {
            rr(rec.send_columns(
                "metrics/icp_iteration_shift_m",
                [rerun::TimeColumn::new_sequence("icp_iteration", ticks)],
                rr(rerun::Scalars::new(shifts).columns_of_unit_batches())?,
            ))?;
        }
        rec.reset_time();
        rec.set_time_sequence("step", self.step);
        rec.set_duration_secs("sim_time", self.sim_time_s);
        Ok(())
    }

    /// The pipe inspection: the cloud coloured by deviation (at most
    /// [`PIPE_DISPLAY_POINTS`], evenly picked), the fitted axis and a
    /// labelled box around each anomaly.
    pub fn pipe(&mut self, cloud: &[Point3<f32>], inspection: &Inspection, threshold_m: f64) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        let every = cloud.len().div_ceil(PIPE_DISPLAY_POINTS).max(1);
        let shown = cloud.iter().zip(&inspection.deviations).step_by(every);
        let (points, colours): (Vec<[f32; 3]>, Vec<rerun::Color>) =
            shown.map(|(p, d)| ([p.x, p.y, p.z], deviation_colour(f64::from(*d), threshold_m))).unzip();
        rr(rec.log("world/pipe/deviation", &rerun::Points3D::new(points).with_colors(colours).with_radii([0.004_f32])))?;
        let pipe = &inspection.fit.pipe;
        rr(rec.log("world/pipe/axis", &rerun::LineStrips3D::new([[p32(&pipe.a), p32(&pipe.b)]])))?;
        if inspection.anomalies.is_empty() {
            return Ok(());
        }
        let (mins, sizes): (Vec<[f32; 3]>, Vec<[f32; 3]>) = inspection
            .anomalies
            .iter()
            .map(|a| (p32(&a.bounds.0), p32(&Point3::from(a.bounds.1 - a.bounds.0))))
            .unzip();
        let labels: Vec<String> = inspection.anomalies.iter().map(|a| label(pipe, a)).collect();
        rr(rec.log(
            "world/pipe/anomalies",
            &rerun::Boxes3D::from_mins_and_sizes(mins, sizes).with_labels(labels).with_colors([red()]),
        ))
    }

    /// The network adjustment at the end of a run: the control points
    /// (`world/control`, labelled), every reading as a sight line between
    /// the adjusted station and point coloured by its largest |w|
    /// (`world/adjustment/observations`), the ones data snooping removed in
    /// red (`world/adjustment/removed`), the misclosure at each control
    /// point as an arrow from its given position, exaggerated ×k
    /// (`world/adjustment/misclosures_x<k>`), and the tests in the log.
    pub fn adjustment(&mut self, mission: &Mission, report: &AdjustmentReport) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        if !mission.control.is_empty() {
            rr(rec.log(
                "world/control",
                &rerun::Points3D::new(mission.control.iter().map(|c| p32(&c.position_m)))
                    .with_labels(mission.control.iter().map(|c| c.name.clone()))
                    .with_colors([rerun::Color::from_rgb(200, 60, 200)])
                    .with_radii([0.06_f32]),
            ))?;
        }
        let point = |id: &str| report.points.iter().find(|p| p.id == id).map(|p| Point3::new(p.x_m, p.y_m, p.z_m));
        let (mut lines, mut colours, mut removed) = (Vec::new(), Vec::new(), Vec::new());
        for reading in report.observations.chunks(3) {
            let Some(o) = reading.first() else { continue };
            let (Some(station), Some(to)) = (report.stations.get(o.station), point(&o.target)) else { continue };
            let line = [p32(&Point3::new(station.x_m, station.y_m, station.z_m)), p32(&to)];
            if reading.iter().any(|o| o.removed) {
                removed.push(line);
                continue;
            }
            let w = reading.iter().filter_map(|o| o.w).max_by(|a, b| a.abs().total_cmp(&b.abs()));
            lines.push(line);
            colours.push(w_colour(w));
        }
        rr(rec.log(
            "world/adjustment/observations",
            &rerun::LineStrips3D::new(lines).with_colors(colours).with_radii([0.008_f32]),
        ))?;
        if !removed.is_empty() {
            rr(rec.log(
                "world/adjustment/removed",
                &rerun::LineStrips3D::new(removed).with_colors([red()]).with_radii([0.02_f32]),
            ))?;
        }
        if !report.misclosures.is_empty() {
            let largest =
                report.misclosures.iter().map(|m| (m.horizontal_m.powi(2) + m.dz_m.powi(2)).sqrt()).fold(0.0, f64::max);
            let scale = ellipse_scale(largest, 1.0);
            let (origins, vectors): (Vec<[f32; 3]>, Vec<[f32; 3]>) = report
                .misclosures
                .iter()
                .filter_map(|m| {
                    let c = mission.control.iter().find(|c| c.name == m.control)?;
                    let v = [m.dx_m, m.dy_m, m.dz_m].map(|d| (d * scale) as f32);
                    Some((p32(&c.position_m), v))
                })
                .unzip();
            rr(rec.log(
                format!("world/adjustment/misclosures_x{}", ellipse_scale_name(scale)),
                &rerun::Arrows3D::from_vectors(vectors)
                    .with_origins(origins)
                    .with_labels(
                        report.misclosures.iter().map(|m| format!("{} {:.1} mm", m.control, 1e3 * m.horizontal_m)),
                    )
                    .with_colors([rerun::Color::from_rgb(200, 60, 200)]),
            ))?;
        }
        let g = &report.global_test;
        let level = if report.model_accepted { rerun::TextLogLevel::INFO } else { rerun::TextLogLevel::WARN };
        let text = format!(
            "network adjustment: σ0² = {:.3}, redundancy {}, global test {}; {} observation(s) removed by data snooping; model {}",
            report.sigma0_squared,
            report.redundancy,
            if g.passed { "passed" } else { "FAILED" },
            report.removed.len() + report.removed_coordinates.len(),
            if report.model_accepted { "accepted" } else { "NOT accepted" }
        );
        self.event(level, text)?;
        for o in report.observations.iter().filter(|o| o.removed) {
            self.warn(format!(
                "removed by data snooping: {} of {} from station {} (w = {:.2})",
                o.kind,
                o.target,
                o.station,
                o.w.unwrap_or(f64::NAN)
            ))?;
        }
        Ok(())
    }

    /// A parent station's figures for the `metrics/` series: σxy, predicted
    /// σxy, σθ and (sim) its error to the truth.
    pub fn station_metrics(&mut self, covariance: &Matrix4<f64>, predicted: &Matrix4<f64>, error_xy_m: Option<f64>) {
        let s = &mut self.series;
        s.station_steps.push(self.step);
        s.sigma_xy_m.push(cps::sigma_xy2(covariance).sqrt());
        s.predicted_sigma_xy_m.push(cps::sigma_xy2(predicted).sqrt());
        s.sigma_heading_rad.push(covariance[(3, 3)].max(0.0).sqrt());
        if let Some(e) = error_xy_m {
            s.error_steps.push(self.step);
            s.error_xy_m.push(e);
        }
    }

    /// A parent fix's variance factor σ0², for `metrics/fix_sigma0_squared`.
    pub fn fix_metrics(&mut self, sigma0_squared: f64) {
        self.series.fix_steps.push(self.step);
        self.series.sigma0_squared.push(sigma0_squared);
    }

    /// A scan's ICP residual at step `at`, for `metrics/icp_rmse_m`.
    pub fn icp_metrics(&mut self, at: i64, rmse_m: f64) {
        self.series.icp_steps.push(at);
        self.series.icp_rmse_m.push(rmse_m);
    }
}
