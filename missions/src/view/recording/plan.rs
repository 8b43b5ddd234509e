//! The plan in a recording ([`Recorder::plan`]): under `world/<root>/` on
//! the `plan_step` timeline (the table in the recording's module doc).

use anyhow::Result;
use nalgebra::Point3;
use planner::{Action, Dance, Robot, Step, StepEstimate, Violation};

use crate::mission::Mission;
use crate::planning::Planned;
use crate::view::shapes::{ellipse_scale, ellipse_scale_name};

use super::colours::{ellipsoid_95, green, red};
use super::{Recorder, p32, rr};

/// The plan to log under `world/plan/` ([`Recorder::plan`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct PlanLog<'a> {
    /// Entity root: `plan` (as written) or `plan_optimized`; the 3D
    /// entities go under `world/<root>/`, the log and metrics under `<root>/`.
    pub root: &'a str,
    /// The schedule.
    pub dance: &'a Dance,
    /// Its steps ([`Dance::steps`] with the mission's scan stations).
    pub steps: &'a [Step],
    /// Every robot's predicted estimate ([`planner::step_estimates`]).
    pub estimates: &'a [StepEstimate],
    /// Constraints broken, each with its description.
    pub violations: &'a [(Violation, String)],
    /// Robot names: the parent's, then the children's in team order.
    pub names: &'a [String],
}

impl PlanLog<'_> {
    fn name(&self, r: Robot) -> String {
        let k = match r {
            Robot::Parent => 0,
            Robot::Child(j) => j + 1,
        };
        self.names.get(k).cloned().unwrap_or_else(|| format!("robot{k}"))
    }

    /// The ellipsoids' exaggeration: the largest 95 % half axis drawn at
    /// most half a station gap long (1-2-5 steps).
    fn ellipsoid_scale(&self) -> f64 {
        let largest = self
            .estimates
            .iter()
            .map(|e| ellipsoid_95(&e.covariance.fixed_view::<3, 3>(0, 0).into_owned()).0)
            .flat_map(|h| h.into_iter().map(f64::from))
            .fold(0.0, f64::max);
        let mut gaps: Vec<f64> =
            self.dance.stations.windows(2).map(|w| (w[1].position - w[0].position).norm()).collect();
        gaps.sort_by(f64::total_cmp);
        ellipse_scale(largest, 0.5 * gaps.get(gaps.len() / 2).copied().unwrap_or(1.0))
    }
}

impl Recorder {
    /// A mission's plan under `world/<root>/` (`plan` as written,
    /// `plan_optimized`) on the `plan_step` timeline: its steps, every
    /// robot's predicted estimate and each violation described (the
    /// runner's `step` and `sim_time` are left as they were).
    pub fn plan(&mut self, mission: &Mission, planned: &Planned, root: &str, violations: &[Violation]) -> Result<()> {
        let described: Vec<(Violation, String)> =
            violations.iter().map(|v| (v.clone(), v.describe(&|r| mission.robot_name(r)))).collect();
        let names = mission.robot_labels();
        self.log_plan(&PlanLog {
            root,
            dance: &planned.dance,
            steps: &planned.steps,
            estimates: &planned.estimates,
            violations: &described,
            names: &names,
        })
    }

    fn log_plan(&mut self, plan: &PlanLog) -> Result<()> {
        let Some(rec) = &self.rec else { return Ok(()) };
        rec.reset_time();
        let dance = plan.dance;
        let stations: Vec<[f32; 3]> = dance.stations.iter().map(|s| p32(&s.position)).collect();
        rr(rec.log_static(
            format!("world/{}/route", plan.root),
            &rerun::LineStrips3D::new([stations.clone()])
                .with_colors([rerun::Color::from_rgb(60, 120, 230)])
                .with_radii([0.015_f32]),
        ))?;
        let scanned: Vec<usize> = plan
            .steps
            .iter()
            .filter_map(|s| if let Action::Scan { station } = s.action { Some(station) } else { None })
            .collect();
        let colours: Vec<rerun::Color> = (0..stations.len())
            .map(|k| if scanned.contains(&k) { green() } else { rerun::Color::from_rgb(60, 120, 230) })
            .collect();
        rr(rec.log_static(
            format!("world/{}/stations", plan.root),
            &rerun::Points3D::new(stations).with_colors(colours).with_radii([0.06_f32]),
        ))?;
        let scale = plan.ellipsoid_scale();
        let scale_name = ellipse_scale_name(scale);
        let broken = |step: usize| plan.violations.iter().any(|(v, _)| v.step == step);
        let colour = |step: usize| if broken(step) { red() } else { green() };
        let line = |a: &Point3<f64>, b: &Point3<f64>, step: usize| {
            rerun::LineStrips3D::new([[p32(a), p32(b)]]).with_colors([colour(step)]).with_radii([0.01_f32])
        };
        let robot = |p: &Point3<f64>, parent: bool| {
            let c = if parent { rerun::Color::from_rgb(60, 120, 230) } else { rerun::Color::from_rgb(240, 140, 40) };
            rerun::Points3D::new([p32(p)]).with_colors([c]).with_radii([if parent { 0.25_f32 } else { 0.1 }])
        };
        rec.set_time_sequence("plan_step", 0);
        if let Some(s0) = dance.stations.first() {
            rr(rec.log(format!("world/{}/robots/{}", plan.root, plan.name(Robot::Parent)), &robot(&s0.position, true)))?;
        }
        let mut so_far: Vec<(Point3<f64>, String)> = Vec::new();
        let (mut fix_steps, mut sigma_xy, mut sigma_heading) = (Vec::new(), Vec::new(), Vec::new());
        for step in plan.steps {
            rec.set_time_sequence("plan_step", step.index as i64);
            match &step.action {
                Action::MoveChild { child, from, to } => {
                    rr(rec.log(format!("world/{}/moves", plan.root), &line(from, to, step.index)))?;
                    rr(rec.log(
                        format!("world/{}/robots/{}", plan.root, plan.name(Robot::Child(*child))),
                        &robot(to, false),
                    ))?;
                }
                Action::MoveParent { from, to } => {
                    let (a, b) = (dance.stations[*from].position, dance.stations[*to].position);
                    rr(rec.log(format!("world/{}/moves", plan.root), &line(&a, &b, step.index)))?;
                    rr(rec.log(format!("world/{}/robots/{}", plan.root, plan.name(Robot::Parent)), &robot(&b, true)))?;
                }
                Action::Measure { child, station, .. } => {
                    if let Some(c) = dance.child_at(step.cycle, *child) {
                        let from = dance.stations[*station].position;
                        rr(rec.log(format!("world/{}/sight_lines", plan.root), &line(&from, &c, step.index)))?;
                    }
                }
                Action::Sight { control, station } => {
                    if let Some(c) = dance.control.get(*control) {
                        let from = dance.stations[*station].position;
                        rr(rec.log(
                            format!("world/{}/control_sight_lines", plan.root),
                            &line(&from, &c.position, step.index),
                        ))?;
                    }
                }
                Action::Fix { .. } | Action::Scan { .. } => {}
            }
            for e in plan.estimates.iter().filter(|e| e.step == step.index && !e.scan) {
                let (half, q) = ellipsoid_95(&e.covariance.fixed_view::<3, 3>(0, 0).into_owned());
                let half = half.map(|h| h * scale as f32);
                rr(rec.log(
                    format!("world/{}/uncertainty/{}/predicted_95pct_x{scale_name}", plan.root, plan.name(e.robot)),
                    &rerun::Ellipsoids3D::from_centers_and_half_sizes([p32(&e.position)], [half])
                        .with_quaternions([q])
                        .with_colors([rerun::Color::from_rgb(230, 200, 40)])
                        .with_fill_mode(rerun::FillMode::MajorWireframe),
                ))?;
                if e.robot == Robot::Parent {
                    fix_steps.push(step.index as i64);
                    sigma_xy.push(e.sigma_xy2_m2().sqrt());
                    sigma_heading.push(e.covariance[(3, 3)].max(0.0).sqrt());
                }
            }
            let here: Vec<&(Violation, String)> =
                plan.violations.iter().filter(|(v, _)| v.step == step.index).collect();
            for (v, text) in &here {
                let at = v.position(dance, plan.steps);
                so_far.push((at, format!("step {}: {}, {}", v.step, v.check.name(), plan.name(v.robot))));
                rr(rec.log(
                    format!("{}/log", plan.root),
                    &rerun::TextLog::new(text.clone()).with_level(rerun::TextLogLevel::WARN),
                ))?;
            }
            if !here.is_empty() {
                rr(rec.log(
                    format!("world/{}/violations", plan.root),
                    &rerun::Points3D::new(so_far.iter().map(|(p, _)| p32(p)))
                        .with_colors([red()])
                        .with_radii([0.2_f32])
                        .with_labels(so_far.iter().map(|(_, l)| l.clone())),
                ))?;
            }
        }
        for (series, values) in [("predicted_sigma_xy_m", sigma_xy), ("predicted_sigma_heading_rad", sigma_heading)] {
            rr(rec.send_columns(
                format!("{}/metrics/{series}", plan.root),
                [rerun::TimeColumn::new_sequence("plan_step", fix_steps.clone())],
                rr(rerun::Scalars::new(values).columns_of_unit_batches())?,
            ))?;
        }
        rec.reset_time();
        if self.step > 0 || self.sim_time_s > 0.0 {
            rec.set_time_sequence("step", self.step);
            rec.set_duration_secs("sim_time", self.sim_time_s);
        }
        Ok(())
    }
}
