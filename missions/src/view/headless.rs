//! The recording's interface in a build without the `recording` feature
//! (`cargo build --no-default-features`): nothing is recorded, every
//! method returns at once, and what asks for a recording explicitly
//! (`--spawn`, `--connect`, `--rrd`, `--log-icp-iterations`) is refused
//! with an error that says why. `[output] rerun = true` then writes no
//! `mission.rrd`, and the run's summary says so.

use std::path::Path;

use anyhow::{Result, bail};
use cps::TeamState;
use cps::geom::Scene;
use nalgebra::{Matrix3, Matrix4, Point3};
use planner::Violation;

use crate::documents::adjustment::AdjustmentReport;
use crate::inspection::Inspection;
use crate::mission::Mission;
use crate::planning::Planned;
pub use crate::view::target::{Layout, Viewer};

const WHY: &str = "this cps-survey was built without the `recording` feature (cargo build --no-default-features): \
                   it writes no Rerun recording; build it with the default features for one";

/// Whether this build can record: it cannot.
pub fn available() -> Result<()> {
    bail!("{WHY}")
}

/// A plan recording cannot be written in this build.
pub fn write_plan_rrd(_mission: &Mission, path: &Path, _plans: &[(&str, &Planned, &[Violation])]) -> Result<()> {
    bail!("cannot write {}: {WHY}", path.display())
}

/// A recorder that records nothing.
#[derive(Debug, Default)]
pub struct Recorder {
    step: i64,
    sim_time_s: f64,
}

#[allow(clippy::unused_self, clippy::missing_const_for_fn)]
impl Recorder {
    /// A recorder that logs nothing.
    pub fn disabled() -> Self {
        Self::default()
    }

    /// Nothing to record to in this build: a disabled recorder, unless a
    /// viewer is asked for.
    pub fn new(_mission: &str, _file: Option<&Path>, viewer: &Viewer, _robots: Vec<String>) -> Result<Self> {
        if *viewer != Viewer::None {
            bail!("{WHY}");
        }
        Ok(Self::disabled())
    }

    /// Does nothing.
    pub fn layout(&mut self, _layout: Layout) -> Result<()> {
        Ok(())
    }

    /// Never true.
    pub fn enabled(&self) -> bool {
        false
    }

    /// Does nothing.
    pub fn scene(&mut self, _scene: &Scene) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn world(&mut self, _scene: Option<&Scene>) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn plan(&mut self, _mission: &Mission, _planned: &Planned, _root: &str, _v: &[Violation]) -> Result<()> {
        Ok(())
    }

    /// Advances the (unrecorded) timelines.
    pub fn advance(&mut self, seconds: f64) {
        self.step += 1;
        self.sim_time_s += seconds;
    }

    /// Does nothing.
    pub fn team(
        &mut self,
        _team: &TeamState,
        _truth: Option<&scanner::sim::Truth>,
        _predicted: Option<(&Matrix4<f64>, &[Matrix3<f64>])>,
    ) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn sight_lines(&mut self, _phase: &str, _from: &Point3<f64>, _to: &[(Point3<f64>, Option<f64>)]) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn trajectory(&mut self, _estimate: &cps::ParentPose, _truth: Option<&cps::ParentPose>) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn scan(&mut self, _kind: &str, _name: &str, _world_points: Vec<Point3<f32>>) -> Result<()> {
        Ok(())
    }

    /// The current (step, sim_time) position on the timelines.
    pub fn now(&self) -> (i64, f64) {
        (self.step, self.sim_time_s)
    }

    /// Does nothing.
    pub fn scan_at(&mut self, _kind: &str, _name: &str, _points: Vec<Point3<f32>>, _at: (i64, f64)) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn icp_iterations(
        &mut self,
        _traces: &[fusion::multiview::IcpTrace],
        _names: &[String],
        _bodies: &[&[Point3<f32>]],
    ) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn pipe(&mut self, _cloud: &[Point3<f32>], _inspection: &Inspection, _threshold_m: f64) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn adjustment(&mut self, _mission: &Mission, _report: &AdjustmentReport) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn info(&mut self, _text: impl Into<String>) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn warn(&mut self, _text: impl Into<String>) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn error(&mut self, _text: impl Into<String>) -> Result<()> {
        Ok(())
    }

    /// Does nothing.
    pub fn station_metrics(&mut self, _covariance: &Matrix4<f64>, _predicted: &Matrix4<f64>, _error: Option<f64>) {}

    /// Does nothing.
    pub fn fix_metrics(&mut self, _sigma0_squared: f64) {}

    /// Does nothing.
    pub fn icp_metrics(&mut self, _at: i64, _rmse_m: f64) {}

    /// Nothing to flush, no viewer to warn about.
    pub fn finish(self) -> Result<Option<String>> {
        Ok(None)
    }
}
