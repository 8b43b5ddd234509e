//! Covariance prediction: the CPS equations run on the nominal (noise-free)
//! readings of a dance (DESIGN §5 "Prediction").

use nalgebra::{Matrix2, Matrix3, Matrix4};

use cps::{ErrorEllipse, Instrument, ParentPose, TeamState, observe};

use crate::dance::{Dance, run_dance};
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
    let mut cycles = Vec::with_capacity(dance.cycles.len());
    run_dance(dance, &mut team, instrument, true, observe, |c, team| {
        cycles.push(CyclePrediction {
            cycle: c.cycle,
            distance_m: dance.stations[c.to].distance_m,
            parent: dance.station_pose(c.to),
            covariance: team.parent_covariance(),
            children_covariance: (0..n).map(|j| team.child_covariance(j)).collect(),
        })
    })?;
    Ok(Prediction { cycles })
}
