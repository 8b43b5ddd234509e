//! Covariance prediction: the CPS equations run on the nominal (noise-free)
//! readings of a dance (DESIGN §5 "Prediction").

use nalgebra::{DMatrix, Matrix2, Matrix3, Matrix4, Point3};

use cps::{ErrorEllipse, Instrument, ParentPose, TeamState};

use crate::dance::{Action, Dance, Robot, Step, run_dance};
use crate::error::Phase;
use crate::error::PlanError;

/// The prediction after one dance cycle.
#[derive(Debug, Clone, PartialEq)]
pub struct CyclePrediction {
    /// Cycle number, 1-based.
    pub cycle: usize,
    /// Path length travelled by the parent, metres.
    pub distance_m: f64,
    /// The parent's nominal pose after the cycle.
    pub parent: ParentPose,
    /// The parent's covariance, order (x, y, z, θ), m² and rad².
    pub covariance: Matrix4<f64>,
    /// Each child's covariance at the end of the cycle (x, y, z), m².
    pub children_covariance: Vec<Matrix3<f64>>,
}

impl CyclePrediction {
    /// σx² + σy², m².
    pub fn sigma_xy2_m2(&self) -> f64 {
        cps::sigma_xy2(&self.covariance)
    }

    /// 1σ heading error, radians.
    pub fn sigma_heading_rad(&self) -> f64 {
        self.covariance[(3, 3)].sqrt()
    }

    /// Horizontal drift as % of the distance travelled.
    pub fn drift_percent(&self) -> f64 {
        cps::drift_percent(&self.covariance, self.distance_m)
    }

    /// The 1σ horizontal error ellipse.
    pub fn ellipse_1sigma(&self) -> ErrorEllipse {
        ErrorEllipse::from_covariance(&Matrix2::from_fn(|i, j| self.covariance[(i, j)]))
    }
}

/// Predicted accuracy along a whole dance.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// The start station's covariance: from its resection on control
    /// points, else the start covariance as given.
    pub start: Matrix4<f64>,
    /// One entry per cycle, in order.
    pub cycles: Vec<CyclePrediction>,
}

impl Prediction {
    /// The last cycle, if the dance has any.
    pub fn last(&self) -> Option<&CyclePrediction> {
        self.cycles.last()
    }
}

/// Runs the dance's nominal readings through [`TeamState`]. The start pose is
/// station 0 with `start_covariance` (zero: known exactly). Fails on the first
/// sight line outside the instrument's range or degenerate geometry.
pub fn predict(
    dance: &Dance,
    instrument: &Instrument,
    start_covariance: &Matrix4<f64>,
) -> Result<Prediction, PlanError> {
    if let Some(first) = dance.range_violations(instrument).into_iter().next() {
        return Err(first);
    }
    let model = |source| PlanError::Model { cycle: 0, source };
    instrument.validate().map_err(model)?;
    let n = dance.n_children();
    let mut team = TeamState::new(dance.station_pose(0), *start_covariance, n).map_err(model)?;
    let mut start = *start_covariance;
    let mut cycles = Vec::with_capacity(dance.cycles.len());
    run_dance(dance, &mut team, instrument, true, crate::dance::nominal_reading(dance), |c, team, _| match c {
        None => start = team.parent_covariance(),
        Some(c) => cycles.push(CyclePrediction {
            cycle: c.cycle,
            distance_m: dance.stations[c.to].distance_m,
            parent: dance.station_pose(c.to),
            covariance: team.parent_covariance(),
            children_covariance: (0..n).map(|j| team.child_covariance(j)).collect(),
        }),
    })?;
    Ok(Prediction { start, cycles })
}

/// A robot's predicted estimate right after the step that set it: a child
/// after its placement, the parent after its fix (after its move when it
/// positions itself by odometry alone), and the parent at every scan (the
/// scan-station covariance, the one a direct transformation inherits).
#[derive(Debug, Clone, PartialEq)]
pub struct StepEstimate {
    /// Index of the step in [`Dance::steps`].
    pub step: usize,
    /// Dance cycle, 1-based (0: the start).
    pub cycle: usize,
    /// Whose estimate.
    pub robot: Robot,
    /// Whether the step is a scan (the estimate is the scan station's).
    pub scan: bool,
    /// Nominal position: the parent's station or the child's prism, metres.
    pub position: Point3<f64>,
    /// Covariance: parent (x, y, z, θ) 4×4 in m² and rad²; child (x, y, z)
    /// 3×3 in m².
    pub covariance: DMatrix<f64>,
}

impl StepEstimate {
    /// σx² + σy², m².
    pub fn sigma_xy2_m2(&self) -> f64 {
        self.covariance[(0, 0)] + self.covariance[(1, 1)]
    }

    /// The 1σ horizontal error ellipse.
    pub fn ellipse_1sigma(&self) -> ErrorEllipse {
        ErrorEllipse::from_covariance(&Matrix2::from_fn(|i, j| self.covariance[(i, j)]))
    }
}

/// Every robot's predicted estimate along `steps` (from [`Dance::steps`] of
/// the same `dance`), from a prediction of that dance. A child's block is
/// set by its placement and left alone by the parent's fixes (only the
/// cross-terms change), so the end-of-cycle child covariance is its
/// covariance right after placement. Steps that set no estimate are skipped;
/// cycles the prediction does not cover yield nothing.
pub fn step_estimates(dance: &Dance, prediction: &Prediction, steps: &[Step]) -> Vec<StepEstimate> {
    let parent_cov = |cycle: usize| -> Option<Matrix4<f64>> {
        if cycle == 0 { Some(prediction.start) } else { prediction.cycles.get(cycle - 1).map(|c| c.covariance) }
    };
    let parent = |s: &Step, station: usize, scan: bool| {
        parent_cov(s.cycle).map(|cov| StepEstimate {
            step: s.index,
            cycle: s.cycle,
            robot: Robot::Parent,
            scan,
            position: dance.stations[station].position,
            covariance: DMatrix::from_column_slice(4, 4, cov.as_slice()),
        })
    };
    steps
        .iter()
        .filter_map(|s| match s.action {
            Action::Measure { child, phase: Phase::Placement, .. } => {
                let cycle = prediction.cycles.get(s.cycle.checked_sub(1)?)?;
                let cov = cycle.children_covariance.get(child)?;
                Some(StepEstimate {
                    step: s.index,
                    cycle: s.cycle,
                    robot: Robot::Child(child),
                    scan: false,
                    position: dance.child_at(s.cycle, child)?,
                    covariance: DMatrix::from_column_slice(3, 3, cov.as_slice()),
                })
            }
            Action::Fix { station } => parent(s, station, false),
            Action::MoveParent { to, .. } if dance.n_children() == 0 => parent(s, to, false),
            Action::Scan { station } => parent(s, station, true),
            _ => None,
        })
        .collect()
}

/// The random part of a drive's odometry error: 1σ distance and heading
/// errors that grow with the square root of the distance driven.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryNoise {
    /// Distance error per √m driven, metres.
    pub sigma_distance_m_per_sqrt_m: f64,
    /// Heading error per √m driven, radians.
    pub sigma_heading_rad_per_sqrt_m: f64,
}

/// Dead reckoning: the covariance of a robot that positions itself by
/// odometry alone along `dance`'s stations (a [`crate::solo`] schedule).
///
/// A move of d metres along direction φ, Δ = d (cos φ, sin φ), truly
/// travels along the believed heading plus the heading error so far plus
/// half the new one δh ~ N(0, σh² d), scaled by 1 + δs/d with
/// δs ~ N(0, σd² d); the heading then errs by δh more. To first order the
/// error e = (ex, ey, ez, eθ) becomes F e + G (δs, δh) with
/// F = I + [0 0 0 −Δy; 0 0 0 Δx; 0; 0] and G = [cos φ −Δy/2; sin φ Δx/2; 0 0; 0 1].
/// Systematic errors (a scale error, a heading drift) are not random and
/// not in this covariance.
pub fn predict_odometry(dance: &Dance, noise: &OdometryNoise, start_covariance: &Matrix4<f64>) -> Prediction {
    let mut p = *start_covariance;
    let mut cycles = Vec::with_capacity(dance.cycles.len());
    for c in &dance.cycles {
        let (a, b) = (&dance.stations[c.from], &dance.stations[c.to]);
        let delta = b.position - a.position;
        let d = delta.xy().norm();
        let (dx, dy) = (delta.x, delta.y);
        let (cos, sin) = if d > 0.0 { (dx / d, dy / d) } else { (1.0, 0.0) };
        let mut f = Matrix4::identity();
        f[(0, 3)] = -dy;
        f[(1, 3)] = dx;
        let g = nalgebra::Matrix4x2::new(cos, -dy / 2.0, sin, dx / 2.0, 0.0, 0.0, 0.0, 1.0);
        let q = nalgebra::Matrix2::new(
            noise.sigma_distance_m_per_sqrt_m.powi(2) * d,
            0.0,
            0.0,
            noise.sigma_heading_rad_per_sqrt_m.powi(2) * d,
        );
        p = f * p * f.transpose() + g * q * g.transpose();
        cycles.push(CyclePrediction {
            cycle: c.cycle,
            distance_m: b.distance_m,
            parent: dance.station_pose(c.to),
            covariance: p,
            children_covariance: Vec::new(),
        });
    }
    Prediction { start: *start_covariance, cycles }
}
