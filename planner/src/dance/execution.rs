//! The dance run through a team state on given readings: the prediction's
//! exact ones, Monte Carlo's noisy ones.

use nalgebra::Point3;

use cps::{FixOptions, Instrument, ParentFix, ParentPose, Reading, TeamState};

use super::schedule::{Dance, DanceCycle};
use crate::control::sighting_instrument;
use crate::error::PlanError;

/// What a reading is taken of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sighted<'a> {
    /// A child's prism where the dance puts it.
    Child(&'a Point3<f64>),
    /// Control point `k` of [`Dance::control`].
    Control(usize),
}

/// The noise-free reading of what is sighted (a prediction's readings).
pub fn nominal_reading(dance: &Dance) -> impl Fn(&ParentPose, Sighted<'_>) -> cps::Result<Reading> + '_ {
    move |from, sighted| match sighted {
        Sighted::Child(p) => cps::observe(from, p),
        Sighted::Control(k) => match dance.control.get(k) {
            Some(c) => cps::observe(from, &c.position),
            None => Err(cps::CpsError::UnknownChild { child: k, team: dance.control.len() }),
        },
    }
}

/// Runs `dance` through `team` (the start's pose and covariance, the
/// children not yet placed): the control points join the team as fixed
/// points; at station 0 the parent resects from the control points it
/// sights (two or more); in every cycle each moved child is placed from the
/// reading `read(station, child)` taken at the standing parent's nominal
/// station, then the parent fixes itself at the next station from fresh
/// readings of the children and of the control points it sights there;
/// `after_fix` sees the cycle (`None` for the start's resection), the team
/// and the fix after each fix. With `start_at_nominal`, Gauss–Newton starts
/// at the planned station instead of the closed-form start (prediction:
/// the readings are exact).
pub fn run_dance(
    dance: &Dance,
    team: &mut TeamState,
    instrument: &Instrument,
    start_at_nominal: bool,
    mut read: impl FnMut(&ParentPose, Sighted<'_>) -> cps::Result<Reading>,
    mut after_fix: impl FnMut(Option<&DanceCycle>, &TeamState, &ParentFix),
) -> Result<(), PlanError> {
    let start = |source| PlanError::Model { cycle: 0, source };
    let sighting = sighting_instrument(instrument);
    let points: Vec<_> = dance.control.iter().map(|c| (c.position, c.prism_covariance(instrument))).collect();
    let control = team.add_fixed_points(&points).map_err(start)?;
    let mut readings: Vec<(usize, Reading, &Instrument)> = Vec::with_capacity(dance.n_children() + control.len());
    // The control points sighted at station `at`, joined to `readings`.
    fn sight<'i>(
        dance: &Dance,
        control: &[usize],
        sighting: &'i Instrument,
        at: usize,
        read: &mut impl FnMut(&ParentPose, Sighted<'_>) -> cps::Result<Reading>,
        readings: &mut Vec<(usize, Reading, &'i Instrument)>,
    ) -> cps::Result<()> {
        let station = dance.station_pose(at);
        for &k in dance.sighted_at(at) {
            readings.push((control[k], read(&station, Sighted::Control(k))?, sighting));
        }
        Ok(())
    }
    // Every control point sighted from the start is read; two or more give
    // its pose by resection (one is left to the batch adjustment).
    let here = dance.station_pose(0);
    sight(dance, &control, &sighting, 0, &mut read, &mut readings).map_err(start)?;
    if dance.resects_start() {
        let options = FixOptions { initial: start_at_nominal.then_some(here), ..FixOptions::default() };
        let fix = team.fix_parent_mixed(&readings, &options).map_err(start)?;
        after_fix(None, team, &fix);
    }
    for c in &dance.cycles {
        let model = |source| PlanError::Model { cycle: c.cycle, source };
        let from = dance.station_pose(c.from);
        for &j in &c.moved {
            let reading = read(&from, Sighted::Child(&c.children[j])).map_err(model)?;
            team.place_child(j, &reading, instrument).map_err(model)?;
        }
        let to = dance.station_pose(c.to);
        readings.clear();
        for (j, child) in c.children.iter().enumerate() {
            readings.push((j, read(&to, Sighted::Child(child)).map_err(model)?, instrument));
        }
        sight(dance, &control, &sighting, c.to, &mut read, &mut readings).map_err(model)?;
        let options = FixOptions { initial: start_at_nominal.then_some(to), ..FixOptions::default() };
        let fix = team.fix_parent_mixed(&readings, &options).map_err(model)?;
        after_fix(Some(c), team, &fix);
    }
    Ok(())
}
