//! The journal's readings as the dance's network, checked reading by
//! reading against the plan and screened for gross errors.

use anyhow::{Context, Result, bail};
use cps::ParentPose;
use cps::screen::{GROSS_ANGLE_RAD, GROSS_DISTANCE_M};
use planner::network::{DanceNetwork, Taken};

use crate::journal::{self, Event, MeasureKey, Phase};
use crate::mission::Mission;
use crate::planning::Planned;

/// The journal's readings as the dance's network: every `measure` event in
/// the dance's reading order (checked), the stations reached (their fix's
/// pose as the approximation) — a run stopped early gives the network so
/// far.
pub fn network(
    mission: &Mission,
    planned: &Planned,
    read: &journal::Read,
    path: &std::path::Path,
) -> Result<DanceNetwork> {
    let Some(instrument) = &mission.total_station else {
        bail!("mission \"{}\" is a robot alone: there is no network of total-station readings to adjust", mission.name)
    };
    let dance = &planned.dance;
    let order = planner::network::reading_order(dance);
    let mut readings = Vec::with_capacity(order.len());
    let mut stations: Vec<ParentPose> = vec![dance.station_pose(0)];
    // The readings' keys so far, with their journal lines.
    let mut seen: Vec<(usize, MeasureKey)> = Vec::new();
    for n in &read.events {
        match &n.event {
            Event::Measure(m) if m.key.attempt > 0 => {
                // A reading measured again after a fix's field test: it
                // supersedes its earlier attempt (the one before it).
                let earlier = MeasureKey { attempt: m.key.attempt - 1, ..m.key.clone() };
                let Some(k) = seen.iter().rposition(|(_, key)| *key == earlier) else {
                    bail!(
                        "{}:{}: {} without its attempt {} before it",
                        path.display(),
                        n.line,
                        key_words(&m.key),
                        earlier.attempt
                    );
                };
                readings[k] = checked_reading(m.data.measurement().to_reading(instrument), path, n)?;
                seen[k] = (n.line, m.key.clone());
            }
            Event::Measure(m) => {
                let Some(expected) = order.get(readings.len()) else {
                    bail!("{}:{}: a measurement beyond the plan's {} readings", path.display(), n.line, order.len());
                };
                let k = &m.key;
                let matches = match *expected {
                    Taken::Placement { cycle, child, .. } => {
                        k.phase == Phase::Placement && k.cycle == cycle && k.child == Some(child)
                    }
                    Taken::Fix { cycle, child, .. } => {
                        k.phase == Phase::Fix && k.cycle == cycle && k.child == Some(child)
                    }
                    Taken::Control { cycle, control, .. } => {
                        k.phase == Phase::Control
                            && k.cycle == cycle
                            && k.control.as_deref() == Some(dance.control[control].name.as_str())
                    }
                };
                if !matches {
                    // In words, not the record's JSON and a Rust value
                    // (issue 34, U7); a reading recorded twice said so.
                    let recorded = key_words(k);
                    let planned = taken_words(expected, &dance.control);
                    if let Some((line, _)) = seen.iter().find(|(_, key)| key == k) {
                        bail!(
                            "{}:{}: {recorded} again (line {line} recorded it): each reading once, the plan's next is {planned}",
                            path.display(),
                            n.line
                        );
                    }
                    bail!(
                        "{}:{}: the journal records {recorded} where the plan takes {planned}: the journal belongs to another plan",
                        path.display(),
                        n.line,
                    );
                }
                seen.push((n.line, k.clone()));
                readings.push(checked_reading(m.data.measurement().to_reading(instrument), path, n)?);
            }
            Event::Fix(f) => {
                let pose: ParentPose = (&f.data.pose).into();
                match f.key.station {
                    0 => stations[0] = pose,
                    s if s == stations.len() => stations.push(pose),
                    s => bail!(
                        "{}:{}: a fix of station {s} after station {}",
                        path.display(),
                        n.line,
                        stations.len() - 1
                    ),
                }
            }
            _ => {}
        }
    }
    let net = planner::network::build(dance, instrument, &mission.plan.start_covariance, &stations, &readings)
        .context("the journal's network")?;
    screen(&net, &seen, path)?;
    Ok(net)
}

/// `reading` of the journal's line `n` when it is finite.
fn checked_reading(reading: cps::Reading, path: &std::path::Path, n: &journal::Numbered) -> Result<cps::Reading> {
    if reading.to_vector().iter().any(|v| !v.is_finite()) {
        bail!("{}:{}: a non-finite reading: {}", path.display(), n.line, n.event.describe());
    }
    Ok(reading)
}

/// Refuses a reading that disagrees grossly ([`cps::screen`]'s bounds: a
/// reading off by them cannot be adjusted; issue 34, U2: a 1000 m distance
/// gave "degenerate geometry … station 6") with the journal's own poses
/// (the fixes' stations, the points placed from them), naming its journal
/// line, what it measured and what the poses give. `lines[k]`: reading
/// k's journal line and key.
fn screen(net: &DanceNetwork, lines: &[(usize, MeasureKey)], path: &std::path::Path) -> Result<()> {
    for (k, r) in net.network.readings.iter().enumerate() {
        let (Some(station), Some(point), Some((line, key))) =
            (net.network.stations.get(r.station), net.network.points.get(r.point), lines.get(k))
        else {
            continue;
        };
        let Ok(expected) = cps::observe(&station.pose, &point.position) else { continue };
        let got = &r.reading;
        if cps::screen::Misclosure::between(got, &expected).is_gross() {
            bail!(
                "{}:{line}: {} measures {:.3} m, {:.4}°, {:.4}° where the journal's poses give {:.3} m, {:.4}°, {:.4}° \
                 (off by more than {GROSS_DISTANCE_M} m or {:.1}°): a gross error, not noise the adjustment can take",
                path.display(),
                key_words(key),
                got.slope_m,
                got.azimuth_rad.to_degrees(),
                got.elevation_rad.to_degrees(),
                expected.slope_m,
                expected.azimuth_rad.to_degrees(),
                expected.elevation_rad.to_degrees(),
                GROSS_ANGLE_RAD.to_degrees()
            );
        }
    }
    Ok(())
}

/// A journal reading's key in words: "the fix reading of child 1 in cycle 2".
fn key_words(k: &MeasureKey) -> String {
    use crate::journal::Phase;
    let phase = match k.phase {
        Phase::Placement => "placement",
        Phase::Fix => "fix",
        Phase::Control => "control",
    };
    match (&k.control, k.child) {
        (Some(name), _) => format!("the {phase} reading of control point {name} in cycle {}", k.cycle),
        (None, Some(child)) => format!("the {phase} reading of child {child} in cycle {}", k.cycle),
        (None, None) => format!("a {phase} reading in cycle {}", k.cycle),
    }
}

/// A planned reading in words, as [`key_words`] says a recorded one.
fn taken_words(t: &Taken, control: &[planner::control::ControlPoint]) -> String {
    match *t {
        Taken::Placement { cycle, child, .. } => format!("the placement reading of child {child} in cycle {cycle}"),
        Taken::Fix { cycle, child, .. } => format!("the fix reading of child {child} in cycle {cycle}"),
        Taken::Control { cycle, control: c, .. } => {
            let name = control.get(c).map_or_else(|| format!("#{c}"), |p| p.name.clone());
            format!("the control reading of control point {name} in cycle {cycle}")
        }
    }
}
