//! A run directory made ready for a new run or for `--resume`: the journal
//! opened, the mission checked to be the one the run started with.

use std::path::Path;

use anyhow::{Context, Result, bail};

use crate::journal::directory;
use crate::journal::{self, EndRecord, Event, Journal, Start};
use crate::mission::Mission;
use crate::planning::Planned;

/// How the journaled run ended, if it did: the `end` event's record.
fn finished(read: &journal::Read) -> Option<EndRecord> {
    read.events.iter().rev().find(|n| !n.event.informational()).and_then(|n| match &n.event {
        Event::End(e) => Some(e.data),
        _ => None,
    })
}

/// The journal of the run in `dir`, opened to write: a new one (with the
/// mission and its scene file copied beside it), or with `resume` the
/// interrupted run's, whose mission must be `mission`. The journal aborts
/// the process after `abort_after` events (a crash test).
pub fn open(
    mission: &Mission,
    planned: &Planned,
    dir: &Path,
    resume: bool,
    abort_after: Option<usize>,
) -> Result<Journal> {
    let journal_path = dir.join("journal.jsonl");
    let mission_copy = dir.join("mission.toml");
    if !resume && journal_path.exists() && finished(&journal::read_without_cross_covariances(&journal_path)?).is_some()
    {
        bail!(
            "{} holds a finished run (its outputs are there; a run is never overwritten): \
             choose another --out directory",
            dir.display()
        );
    }
    if resume {
        if !journal_path.exists() {
            bail!("{} does not exist: there is no run to resume there", journal_path.display());
        }
        directory::refuse_links(dir)?;
        let lock = directory::lock(dir, &format!("run {} --resume", mission.source.file.display()))?;
        let read = journal::read(&journal_path)?;
        let start = read.start(&journal_path)?.clone();
        let as_run =
            std::fs::read_to_string(&mission_copy).with_context(|| format!("reading {}", mission_copy.display()))?;
        let scene_changed = match &mission.backend.scene_file {
            Some((_, text)) => std::fs::read_to_string(dir.join("scene.toml")).ok().as_ref() != Some(text),
            None => false,
        };
        if as_run == mission.source.text && !scene_changed && start.seed != mission.backend.seed {
            // (Issue 34, U10: this blamed the mission file.)
            bail!(
                "the run in {} started with seed {} (its journal's start); this resume has seed {}: resume with \
                 --seed {} (or the mission's own seed, without --seed)",
                dir.display(),
                start.seed,
                mission.backend.seed,
                start.seed
            );
        }
        if as_run != mission.source.text || scene_changed {
            bail!(
                "{} is not the mission this run started with ({}{}); resume with that file",
                mission.source.file.display(),
                mission_copy.display(),
                if scene_changed { ", and its scene file changed since: see scene.toml there" } else { "" }
            );
        }
        if let Some(end) = finished(&read) {
            bail!(
                "the run in {} is finished (acceptance {}): nothing to resume; its outputs are there",
                dir.display(),
                if end.accepted { "passed" } else { "FAILED" }
            );
        }
        let mut journal = Journal::resume(&journal_path, read)?;
        journal.hold(lock);
        journal.abort_after(abort_after);
        journal.append(Event::Resume)?;
        return Ok(journal);
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    directory::refuse_links(dir)?;
    if !journal_path.exists() {
        refuse_others_outputs(dir)?;
    }
    let lock = directory::lock(dir, &format!("run {}", mission.source.file.display()))?;
    let mut journal = Journal::create(&journal_path)?;
    journal.hold(lock);
    journal.abort_after(abort_after);
    scanner::io::replace_file(&mission_copy, mission.source.text.as_bytes())
        .with_context(|| format!("writing {}", mission_copy.display()))?;
    if let Some((_, text)) = &mission.backend.scene_file {
        scanner::io::replace_file(&dir.join("scene.toml"), text.as_bytes())
            .with_context(|| format!("writing {}/scene.toml", dir.display()))?;
    }
    journal.append(Event::Start(Start {
        mission: mission.name.clone(),
        seed: mission.backend.seed,
        scene: mission.backend.scene.clone(),
        stations: planned.stations(),
        children: mission.children.clone(),
    }))?;
    Ok(journal)
}

/// Refuses a new run into a directory that holds a run's outputs but no
/// journal (issue 34, W5: `report.json`, `stations.csv`, `adjustment.txt`,
/// `cloud.ply` there were overwritten): they are another run's, or
/// another command's, and not this one's to replace.
fn refuse_others_outputs(dir: &Path) -> Result<()> {
    let mut names: Vec<String> = ["report.json", "stations.csv", "adjustment.txt", "mission.toml", "scene.toml"]
        .into_iter()
        .chain(["mission.rrd", "scans", "fusion", crate::inspection::DEVIATION_FILE])
        .map(String::from)
        .collect();
    names.extend(crate::mission::OUTPUT_FORMATS.iter().map(|f| crate::output::cloud_file(f)));
    let found: Vec<&String> = names.iter().filter(|n| std::fs::symlink_metadata(dir.join(n)).is_ok()).collect();
    if !found.is_empty() {
        bail!(
            "{} holds {} but no journal.jsonl: outputs that are not this run's to overwrite; choose another --out \
             directory (or an empty one)",
            dir.display(),
            found.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(", ")
        );
    }
    Ok(())
}
