//! The total station's part of the dance: every sighting measured, a
//! placement's reading and a fix's readings tested in the field, measured
//! again or refused (issue 34, S7), and the fixes journaled and shown.

use anyhow::{Context, Result};
use cps::screen::{FieldTest, Misclosure};
use cps::{FixOptions, ParentPose, Reading, observe};
use nalgebra::Point3;
use planner::DanceCycle;
use scanner::{Prism, Target};

use super::Run;
use crate::documents::records::rows;
use crate::documents::run::Remeasured;
use crate::journal::{ChainRecord, Derived, Event, FixKey, FixRecord, MeasureKey, Measured, Phase, StepKey, Stop};
use crate::run::backend::DeviceKind;
use crate::run::observer::Shown;

/// How many times in one session a reading that fails a fix's field test
/// is measured again before the run stops (a resume measures again).
const MAX_REMEASURES: u32 = 2;

/// A total-station sighting of one point: what was aimed at, under which
/// journal key, and what was read.
#[derive(Debug, Clone)]
struct Sighting<'i> {
    key: MeasureKey,
    target: Target,
    /// The point's index in the team state (a child or a control point).
    point: usize,
    instrument: &'i cps::Instrument,
    reading: Reading,
}

/// A misclosure in words: "10.000 m, 0.0000°, 0.0000° off" style.
fn misclosure_words(m: &Misclosure) -> String {
    format!(
        "off by {:+.3} m, {:+.4}°, {:+.4}° (distance, azimuth, elevation)",
        m.slope_m,
        m.azimuth_rad.to_degrees(),
        m.elevation_rad.to_degrees()
    )
}

impl Run<'_> {
    /// One total-station measurement of `target`, as `instrument` reads it;
    /// with whether the device took it (not the journal's replay).
    fn measure(&mut self, key: MeasureKey, target: &Target, instrument: &cps::Instrument) -> Result<(Reading, bool)> {
        let replayed = self.dispatch.replayed;
        let m: Measured =
            self.dispatch.step(&mut self.obs, key, StepKey::Measure, DeviceKind::TotalStation, |team, _| {
                team.measure(target).map(Measured::new)
            })?;
        self.obs.measured();
        Ok((m.measurement().to_reading(instrument), self.dispatch.replayed == replayed))
    }

    /// A placement's reading. It has no redundancy, so one grossly off the
    /// formation point (cps::screen's bounds, against the parent's estimate)
    /// is measured again, and taken when it is near the formation point or
    /// agrees with the one before it (the child stands off its point: its
    /// drive, not the reading). Refused after [`MAX_REMEASURES`] attempts
    /// in this session.
    pub(super) fn placement_reading(
        &mut self,
        mut key: MeasureKey,
        target: &Target,
        instrument: &cps::Instrument,
    ) -> Result<Reading> {
        let (mut reading, _) = self.measure(key.clone(), target, instrument)?;
        let mut previous: Option<Reading> = None;
        let mut live = 0;
        loop {
            let off = Misclosure::between(&reading, &target.predicted);
            let agrees = previous.is_some_and(|p| !Misclosure::between(&reading, &p).is_gross());
            if !off.is_gross() || agrees {
                return Ok(reading);
            }
            let what = format!(
                "cycle {}: the placement reading of {} is {} from its formation point",
                key.cycle,
                self.prism_name(key.child.unwrap_or_default()),
                misclosure_words(&off)
            );
            if live >= MAX_REMEASURES {
                let why = format!("{what}, and {} measurements in this session disagree with each other", live + 1);
                return Err(self.refuse(&key, why));
            }
            self.obs.warn(format!("{what}: measured again"))?;
            previous = Some(reading);
            key.attempt += 1;
            self.note_remeasured(key.child.unwrap_or_default(), &key, what);
            let (again, was_live) = self.measure(key.clone(), target, instrument)?;
            live += u32::from(was_live);
            reading = again;
        }
    }

    /// The parent's fix from `sightings` once they pass the field test
    /// ([`cps::screen::field_test`]), taken by the team. A reading the test
    /// names is measured again — the next attempt in the journal, the
    /// superseded one kept — up to [`MAX_REMEASURES`] times in this
    /// session; a fix that still fails is refused, never journaled as a
    /// position (issue 34, S7).
    fn checked_fix(&mut self, cycle: usize, station: usize, sightings: &mut [Sighting<'_>]) -> Result<cps::ParentFix> {
        let options = FixOptions::default();
        let mut live = vec![0; sightings.len()];
        loop {
            let readings: Vec<(usize, Reading, &cps::Instrument)> =
                sightings.iter().map(|s| (s.point, s.reading, s.instrument)).collect();
            let (k, off) = match cps::screen::field_test(&self.team, &readings, &options) {
                FieldTest::Passed => return Ok(self.team.fix_parent_mixed(&readings, &options)?),
                FieldTest::Culprit { index, misclosure } => (index, misclosure),
                FieldTest::Failed { error, worst, fix } => {
                    let why = match (error, worst) {
                        (Some(e), _) => format!("it fails: {e}"),
                        // Not the readings: the fix itself.
                        (None, _) if fix.is_some_and(|(converged, ..)| !converged) => format!(
                            "it does not converge in {} iterations",
                            fix.map_or(0, |(_, iterations, _)| iterations)
                        ),
                        (None, Some((k, m))) if !m.is_gross() => format!(
                            "its σ0² is {:.3e} (at most {:.0e}: the readings disagree far beyond their noise); the reading of {} is {} from it",
                            fix.map_or(f64::NAN, |(.., s)| s),
                            cps::screen::GROSS_SIGMA0_SQUARED,
                            self.prism_name(sightings[k].point),
                            misclosure_words(&m)
                        ),
                        (None, Some((k, m))) => format!(
                            "the reading of {} is {} from it, and {}",
                            self.prism_name(sightings[k].point),
                            misclosure_words(&m),
                            if sightings.len() < 3 {
                                "with two readings no single one can be named"
                            } else {
                                "no single reading explains it"
                            }
                        ),
                        (None, None) => "it does not converge".into(),
                    };
                    let what = format!(
                        "cycle {cycle}: the parent's fix at station {station} from {} readings: {why}",
                        sightings.len()
                    );
                    if live.iter().any(|n| *n >= MAX_REMEASURES) {
                        let key = sightings.last().map(|s| s.key.clone()).context("a fix has sightings")?;
                        return Err(self.refuse(&key, format!("{what}, also when measured again")));
                    }
                    // Too few readings to name one (two points): every one
                    // is measured again.
                    self.obs.warn(format!("{what}: every reading measured again"))?;
                    for k in 0..sightings.len() {
                        self.remeasure(&mut sightings[k], &mut live[k], &what)?;
                    }
                    continue;
                }
            };
            let what = format!(
                "cycle {cycle}: the reading of {} is {} from the parent's fix at station {station} from the other {}",
                self.prism_name(sightings[k].point),
                misclosure_words(&off),
                sightings.len() - 1
            );
            if live[k] >= MAX_REMEASURES {
                let why = format!("{what}, also when measured again ({} time(s) in this session)", live[k]);
                return Err(self.refuse(&sightings[k].key, why));
            }
            self.obs.warn(format!("{what}: a gross error; measured again"))?;
            self.remeasure(&mut sightings[k], &mut live[k], &what)?;
        }
    }

    /// Measures `sighting` again as its next attempt, `why`; counts it in
    /// `live` when the device took it.
    fn remeasure(&mut self, sighting: &mut Sighting<'_>, live: &mut u32, why: &str) -> Result<()> {
        sighting.key.attempt += 1;
        self.note_remeasured(sighting.point, &sighting.key, why.to_string());
        let (reading, was_live) = self.measure(sighting.key.clone(), &sighting.target, sighting.instrument)?;
        sighting.reading = reading;
        *live += u32::from(was_live);
        Ok(())
    }

    /// Notes the re-measurement `key` of the team state's point `point` for
    /// the report.
    fn note_remeasured(&mut self, point: usize, key: &MeasureKey, why: String) {
        let point = self.prism_name(point);
        self.remeasured.push(Remeasured { cycle: key.cycle, point, attempt: key.attempt, why });
    }

    /// Stops the run on a measurement that cannot be trusted: journals the
    /// stop (the readings stay) and returns the error with the resume hint.
    fn refuse(&mut self, key: &MeasureKey, why: String) -> anyhow::Error {
        let stop = Stop {
            device: DeviceKind::TotalStation.name().into(),
            error: why.clone(),
            step: StepKey::Measure(key.clone()),
        };
        if let Err(e) = self.dispatch.journal.append(Event::Stop(stop)) {
            return e;
        }
        if let Err(e) = self.obs.stopped(format!("{why}: mission stopped")) {
            return e;
        }
        anyhow::anyhow!(
            "{why}. Nothing is taken as a position from it; the mission stopped cleanly and the journal keeps every \
             reading. Check the prisms and the instrument, then continue (it measures again) with: {}",
            self.dispatch.resume_hint
        )
    }

    /// The parent at station `station` (cycle `cycle`, 0 at the start),
    /// standing near `nominal`, sights every control point the plan has it
    /// sight there; each reading with the team-state index of the prism and
    /// its noise model (a control prism's centring is in its position).
    fn sight_control<'i>(
        &mut self,
        cycle: usize,
        station: usize,
        nominal: &ParentPose,
        instrument: &'i cps::Instrument,
    ) -> Result<Vec<Sighting<'i>>> {
        let mut sightings = Vec::new();
        for k in self.planned.dance.sighted_at(station).to_vec() {
            let control = &self.planned.dance.control[k];
            let target = Target { prism: Prism::Control(k), predicted: observe(nominal, &control.position)? };
            let key = MeasureKey {
                cycle,
                phase: Phase::Control,
                child: None,
                control: Some(control.name.clone()),
                attempt: 0,
            };
            let (reading, _) = self.measure(key.clone(), &target, instrument)?;
            sightings.push(Sighting { key, target, point: self.control_index + k, instrument, reading });
        }
        Ok(sightings)
    }

    /// At the start: the control points sighted from station 0, and with
    /// two or more the parent's pose by resection — journaled as the fix
    /// of cycle 0.
    pub(super) fn start(&mut self) -> Result<()> {
        let Some(instrument) = self.mission.total_station.clone() else { return Ok(()) };
        let sighting = instrument.without_target_centring();
        let nominal = self.planned.dance.station_pose(0);
        let mut sightings = self.sight_control(0, 0, &nominal, &sighting)?;
        if !self.planned.dance.resects_start() {
            return Ok(());
        }
        let fix = self.checked_fix(0, 0, &mut sightings)?;
        self.journal_fix(0, 0, &fix)?;
        let pose = self.team.parent();
        self.dispatch.team.relocalise_parent(&pose)?;
        let control: Vec<Point3<f64>> =
            self.planned.dance.sighted_at(0).iter().map(|&k| self.planned.dance.control[k].position).collect();
        self.obs.resected(&pose, &control, fix.sigma0_squared)
    }

    /// Journals a fix with what the scans' joint prior needs: its link in
    /// the chain of scan stations, or (a version 1 or 2 journal) its
    /// cross-covariances to every earlier scan station.
    fn journal_fix(&mut self, cycle: usize, station: usize, fix: &cps::ParentFix) -> Result<()> {
        let pose = self.team.parent();
        let (cross, chain) = if self.clones_scan_stations() {
            let cross = (0..self.team.clones())
                .map(|a| self.team.parent_clone_covariance(a).map(|c| rows(&c)))
                .collect::<cps::Result<Vec<_>>>()?;
            (Some(cross), None)
        } else {
            (None, Some(ChainRecord::of(&self.team)))
        };
        self.dispatch.note(Event::Fix(Derived {
            key: FixKey { cycle, station },
            data: FixRecord {
                pose: (&pose).into(),
                covariance: rows(&self.team.parent_covariance()),
                sigma0_squared: Some(fix.sigma0_squared),
                redundancy: Some(fix.redundancy),
                scan_cross_covariances: cross,
                chain,
                source: None,
            },
        }))
    }

    /// The parent, moved to near `nominal`, measures every child and every
    /// control point it sees there and fixes its pose from them (seed 003
    /// eqs 7–16); the fix is journaled, and every blunder suspect logged.
    pub(super) fn fix_parent(
        &mut self,
        cycle: &DanceCycle,
        nominal: &ParentPose,
        instrument: &cps::Instrument,
    ) -> Result<()> {
        let mut sightings = Vec::with_capacity(cycle.children.len());
        for (j, at) in cycle.children.iter().enumerate() {
            let target = Target { prism: Prism::Child(j), predicted: observe(nominal, at)? };
            let key = MeasureKey { cycle: cycle.cycle, phase: Phase::Fix, child: Some(j), control: None, attempt: 0 };
            let (reading, _) = self.measure(key.clone(), &target, instrument)?;
            sightings.push(Sighting { key, target, point: j, instrument, reading });
        }
        let sighting = instrument.without_target_centring();
        let control = self.sight_control(cycle.cycle, cycle.to, nominal, &sighting)?;
        sightings.extend(control);
        let fix = self.checked_fix(cycle.cycle, cycle.to, &mut sightings)?;
        let pose = self.team.parent();
        self.dispatch.team.relocalise_parent(&pose)?;
        self.journal_fix(cycle.cycle, cycle.to, &fix)?;
        // Sight lines coloured by each reading's largest |w|.
        let reliability = fix.reliability();
        let shown = sightings
            .iter()
            .enumerate()
            .map(|(k, s)| {
                let at = self.team.child(s.point).context("a sighted point is placed")?;
                Ok(Shown { name: self.prism_name(s.point), at, w: reliability.largest_w_of_point(k) })
            })
            .collect::<Result<Vec<_>>>()?;
        self.obs.fixed(cycle.cycle, &pose, &shown, fix.sigma0_squared)
    }
}
