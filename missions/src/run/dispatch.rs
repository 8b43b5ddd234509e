//! Every command of a run goes through the [`Dispatch`]: replayed from the journal
//! while it holds recorded steps, else given to the device — again after a
//! failure, up to the mission's retries — and journaled with the team's
//! state after it.

use std::time::Duration;

use anyhow::{Context, Result, bail};

use super::backend::{DeviceKind, Team};
use super::observer::Observer;
use crate::journal::{Event, Journal, Recorded, Retry, Step, StepKey, Stop};

/// The journal, the devices and the retry policy of a run.
#[derive(Debug)]
pub struct Dispatch {
    /// The journal.
    pub journal: Journal,
    /// The devices.
    pub team: Team,
    /// Attempts after the first.
    pub max_retries: u32,
    /// Pause before each retry.
    pub retry_delay: Duration,
    /// The command that resumes the run, for the stop message.
    pub resume_hint: String,
    /// Journal events replayed so far.
    pub replayed: usize,
}

impl Dispatch {
    /// One device command keyed by `key`. While the journal holds recorded
    /// steps, the next one (which must be this command) is used as it was
    /// and the team is put back to its recorded state after it. Otherwise
    /// the device is commanded — again after a failure, up to the mission's
    /// retries — and the reading is journaled with the team's state.
    /// `obs` shows retries and stops, and is the command's to show its work.
    pub fn step<T: Step + Clone>(
        &mut self,
        obs: &mut Observer,
        key: T::Key,
        to_step_key: impl Fn(T::Key) -> StepKey,
        device: DeviceKind,
        mut command: impl FnMut(&mut Team, &mut Observer) -> scanner::Result<T>,
    ) -> Result<T> {
        if let Some((line, event)) = self.journal.next_recorded() {
            let described = serde_json::to_string(&key).unwrap_or_default();
            let Some(recorded) = T::recorded(event.clone()).filter(|r| r.key == key) else {
                return Err(self.journal.mismatch(line, &event, &described));
            };
            self.replayed += 1;
            if let Some(sim) = &recorded.sim {
                self.team
                    .restore(sim)
                    .with_context(|| format!("restoring the team's state from journal line {line}"))?;
            }
            return Ok(recorded.data);
        }
        let mut attempt = 0;
        loop {
            match command(&mut self.team, obs) {
                Ok(data) => {
                    let sim = Some(self.team.checkpoint());
                    // Real instruments' steps carry their UTC time (the
                    // rosbag2's stamps); the simulator's keep the mission clock.
                    let unix_time_s = self.team.truth().is_none().then(crate::journal::unix_now);
                    self.journal.append(T::event(Recorded { key, data: data.clone(), sim, unix_time_s }))?;
                    return Ok(data);
                }
                // A file that cannot be written is not a device fault:
                // no retry (the device would measure again for nothing).
                Err(scanner::ScannerError::Io { path, source }) => {
                    obs.stopped(format!("writing {}: {source}: mission stopped", path.display()))?;
                    bail!(
                        "writing {}: {source}. A file-system error, not a {} fault: the mission stopped cleanly; \
                         the journal keeps every reading before it. Free space (or fix the permission), then \
                         continue with: {}",
                        path.display(),
                        device.name(),
                        self.resume_hint
                    );
                }
                Err(e) if attempt < self.max_retries => {
                    attempt += 1;
                    let step = to_step_key(key.clone());
                    let retry = Retry { device: device.name().into(), attempt, error: e.to_string(), step };
                    self.journal.append(Event::Retry(retry))?;
                    obs.warn(format!("{e}: retry {attempt} of {}", self.max_retries))?;
                    std::thread::sleep(self.retry_delay);
                }
                Err(e) => {
                    let step = to_step_key(key);
                    self.journal.append(Event::Stop(Stop {
                        device: device.name().into(),
                        error: e.to_string(),
                        step,
                    }))?;
                    obs.stopped(format!("{e}: mission stopped"))?;
                    bail!(
                        "{} failed {} time(s), last: {e}. The mission stopped cleanly; the journal keeps every \
                         reading so far. Once the device answers, continue with: {}",
                        device.name(),
                        attempt + 1,
                        self.resume_hint
                    );
                }
            }
        }
    }

    /// A result the run derives (a fix, the end): journaled live; on
    /// replay the recorded one must be there (the same step).
    pub fn note(&mut self, event: Event) -> Result<()> {
        if let Some((line, recorded)) = self.journal.next_recorded() {
            if !recorded.same_derived_step(&event) {
                return Err(self.journal.mismatch(line, &recorded, &event.describe()));
            }
            self.replayed += 1;
            return Ok(());
        }
        self.journal.append(event)
    }
}
