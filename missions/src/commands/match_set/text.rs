//! `match`'s tables and messages on the terminal.

use std::io::Write;

use crate::documents::matching::{CheckReport, MatchReport, RestartReport, ScanReport, StageReport, ViewpointReport};
use crate::scans::inputs::InputScan;

pub(super) fn write_text(out: &mut dyn Write, scans: &[InputScan], report: &MatchReport) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<32} {:>10} {:>10} {:>10} {:>9} {:>9}  unseen",
        "scan", "x m", "y m", "z m", "σ xyz mm", "σ rot °"
    )?;
    for (s, r) in scans.iter().zip(&report.scans) {
        let m = &r.world_from_scan;
        let c = &r.covariance;
        let (rot, pos) = ((c[0][0] + c[1][1] + c[2][2]).max(0.0).sqrt(), (c[3][3] + c[4][4] + c[5][5]).max(0.0).sqrt());
        writeln!(
            out,
            "{:<32} {:>10.4} {:>10.4} {:>10.4} {:>9.2} {:>9.4}  {}",
            s.name,
            m[0][3],
            m[1][3],
            m[2][3],
            pos * 1e3,
            rot.to_degrees(),
            r.degenerate_directions.len()
        )?;
    }
    let accepted = report.links.iter().filter(|l| l.accepted).count();
    writeln!(
        out,
        "{} links, {accepted} used; {} ICP runs; {:.3} s",
        report.links.len(),
        report.matches,
        report.seconds
    )?;
    writeln!(out, "stages: {}", stages(&report.stages))?;
    write_viewpoints(out, scans, report)?;
    if let Some(p) = &report.settings.pipe {
        writeln!(
            out,
            "the scans are a pipe (radius {:.3} m; at least {:.0} % of each scan's points on its tube, all round): \
             matched with the blind-direction threshold {} and the line test {}, as a pipe needs (--degeneracy-ratio \
             chooses another)",
            p.radius_m,
            100.0 * p.share,
            report.settings.degeneracy_ratio,
            report.settings.line_ratio
        )?;
    }
    if let Some(n) = &report.noise {
        writeln!(
            out,
            "covariances calibrated on the scans' halves and quarters: ×{:.2}, by pair ×{:.2} \
             (rotation ×{:.2}, translation ×{:.2} about each source's centroid; \
             halves ×{:.2}, ×{:.2}; quarters ×{:.2}, ×{:.2}; {} degrees of freedom, {:.3} s); \
             the two ways' disagreement by noise alone {:.2}",
            n.variance_scale,
            n.range_scale,
            n.rotation_scale,
            n.translation_scale,
            n.halves.variance_scale,
            n.halves.range_scale,
            n.quarters.variance_scale,
            n.quarters.range_scale,
            n.dof,
            n.seconds,
            n.asymmetry
        )?;
    }
    if let Some(r) = &report.restart {
        write_restart(out, scans, r)?;
    }
    for i in unlinked(report) {
        writeln!(
            out,
            "  not trusted: {} has no accepted link at the last stage: it keeps the coarser stages' pose, blind in every direction",
            scans[i].name
        )?;
    }
    for &i in &report.blind_without_start {
        writeln!(
            out,
            "  not trusted: {}: blind in {} direction(s), and a start found by --init global says nothing along them",
            scans[i].name,
            report.scans[i].degenerate_directions.len()
        )?;
    }
    if let Some(r) = &report.restart {
        write_undecided(out, scans, r)?;
    }
    if let Some(r) = &report.restart {
        write_unsupported(out, scans, r, report.stages.last().map_or(0.0, |s| s.max_correspondence_m))?;
    }
    let tolerance = report.stages.last().map_or(0.0, |s| s.voxel_m);
    // Whether the pipe's threshold ran already: the set's own (given, or
    // the scans found a pipe), or the restart's or the last further one's.
    let pipe_ran = if report.settings.degeneracy_ratio >= fusion::links::PIPE_DEGENERACY_RATIO {
        PipeRan::Set
    } else if report
        .restart
        .iter()
        .any(|r| r.degeneracy_ratio.is_some() || r.further.iter().any(|f| f.degeneracy_ratio.is_some()))
    {
        PipeRan::Restart
    } else {
        PipeRan::No
    };
    let estimated: Vec<bool> =
        report.scans.iter().map(|s| s.viewpoint.as_ref().is_some_and(ViewpointReport::is_estimate)).collect();
    for &i in &report.untrusted {
        let undecided =
            report.restart.iter().filter(|r| !r.corroborated).flat_map(|r| &r.undecided).any(|u| u.scan == i);
        let departed =
            report.scans.get(i).map_or(Ok(false), |s| why_departed(out, &scans[i].name, &report.mode, s, tolerance))?;
        let held = report
            .scans
            .get(i)
            .map_or(Ok(false), |s| why_held(out, &scans[i].name, &report.mode, s, tolerance, pipe_ran))?;
        let unsupported = report.restart.iter().flat_map(|r| &r.unsupported).any(|u| u.scan == i);
        let explained = undecided || departed || held || unsupported;
        why_untrusted(out, scans, &report.checks, &report.untrusted, &estimated, i, explained, tolerance)?;
    }
    for l in report.links.iter().filter(|l| !l.accepted || l.cycle.is_some()) {
        let targets: Vec<&str> = l.targets.iter().map(|&t| scans[t].name.as_str()).collect();
        let cycle = l.cycle.as_ref().map_or_else(String::new, |c| {
            let names: Vec<&str> = c.scans.iter().map(|&i| scans[i].name.as_str()).collect();
            format!(
                "the cycle {} → {} (the used links from {} to {} and this one disagree by {:.3}°, {:.3} m)",
                names.join(" → "),
                names.first().copied().unwrap_or_default(),
                names.first().copied().unwrap_or_default(),
                names.last().copied().unwrap_or_default(),
                c.angle_deg,
                c.translation_m
            )
        });
        let (source, targets) = (&scans[l.source].name, targets.join(", "));
        if l.accepted {
            writeln!(
                out,
                "  kept {source} → {targets}: it disagrees with {cycle}, but no other cycle tells which of its links is wrong: the variance factor carries it"
            )?;
        } else if cycle.is_empty() {
            writeln!(out, "  rejected {source} → {targets}: {}", l.reason.as_deref().unwrap_or(""))?;
        } else {
            writeln!(
                out,
                "  rejected {source} → {targets}: {}; it contradicts {cycle}",
                l.reason.as_deref().unwrap_or("")
            )?;
        }
    }
    Ok(())
}

/// The scanners' positions estimated from the scans' spacing (for the
/// free-space test), and those the spacing did not tell.
fn write_viewpoints(out: &mut dyn Write, scans: &[InputScan], report: &MatchReport) -> std::io::Result<()> {
    let estimated = |used: bool| -> Vec<String> {
        scans
            .iter()
            .zip(&report.scans)
            .filter_map(|(s, r)| {
                let v = r.viewpoint.as_ref().filter(|v| v.is_estimate() && v.used == used)?;
                Some(if used { s.name.clone() } else { format!("{} ({:.2})", s.name, v.explained.unwrap_or_default()) })
            })
            .collect()
    };
    let (used, unused) = (estimated(true), estimated(false));
    if !used.is_empty() {
        writeln!(
            out,
            "scanners' positions estimated from their scans' spacing, for the free-space test: {}",
            used.join(", ")
        )?;
    }
    if !unused.is_empty() {
        writeln!(
            out,
            "free space not tested from {}: neither the range nor a scanner turning about an axis explains enough of \
             the spacing (under {}: thinned on a grid, or merged from several stations?)",
            unused.join(", "),
            fusion::viewpoint::MIN_EXPLAINED
        )?;
    }
    Ok(())
}

/// In graph mode, the scans (after the first, which holds the frame) that
/// no accepted link of the last stage reaches.
pub(super) fn unlinked(report: &MatchReport) -> Vec<usize> {
    if report.mode != "graph" {
        return Vec::new();
    }
    (1..report.scans.len())
        .filter(|&i| !report.links.iter().any(|l| l.accepted && (l.source == i || l.targets.contains(&i))))
        .collect()
}

/// Whether scan `i` departs from where the verification's matches agree
/// by more than [`fusion::verify::MAX_DEPARTURE_CHI2`] in their σ and
/// `tolerance` (the finest voxel) in its points' motion (the modes
/// without a link graph), and if so the message that says so.
fn why_departed(out: &mut dyn Write, name: &str, mode: &str, s: &ScanReport, tolerance: f64) -> std::io::Result<bool> {
    let (Some(d), Some(t), Some(moved)) = (s.departure, s.departure_chi2, s.departure_m) else { return Ok(false) };
    if !fusion::scanset::departs(t, moved, tolerance) {
        return Ok(false);
    }
    let (turn, shift) =
        (d[..3].iter().map(|x| x * x).sum::<f64>().sqrt(), d[3..].iter().map(|x| x * x).sum::<f64>().sqrt());
    writeln!(
        out,
        "  not trusted: {}: {} matching stopped {:.3}°, {:.1} mm from where its verified pairs agree ({t:.0} σ² of \
         their adjustment, above {}; its points {moved:.3} m, beyond {tolerance:.3} m): a compromise of its matches \
         that no pair alone names; graph mode places the scans where their pairs agree",
        name,
        mode,
        turn.to_degrees(),
        shift * 1e3,
        fusion::verify::MAX_DEPARTURE_CHI2
    )?;
    Ok(true)
}

/// Where a pipe's blind-direction threshold ran already, for the held
/// message's remedy ([`why_held`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PipeRan {
    /// Nowhere: the remedy is that threshold.
    No,
    /// From the starts, as the restart or the last further restart.
    Restart,
    /// As the set's own (given, or the scans found a pipe).
    Set,
}

/// Whether scan `s` moved from its start along the directions only the
/// start holds beyond [`fusion::scanset::held_beyond`]'s limits
/// (`tolerance`: the finest voxel), and if so the message that says so:
/// in graph mode (`mode`) the directions its links do not see, in the
/// others those its matches hold no better than the start; the remedy a
/// pipe's threshold unless it ran already (`pipe_ran`).
fn why_held(
    out: &mut dyn Write,
    name: &str,
    mode: &str,
    s: &ScanReport,
    tolerance: f64,
    pipe_ran: PipeRan,
) -> std::io::Result<bool> {
    let (Some(chi2), Some(moved)) = (s.held_chi2, s.held_m) else { return Ok(false) };
    let k = s.held_directions.len();
    if !fusion::scanset::held_beyond(chi2, k, moved, tolerance) {
        return Ok(false);
    }
    let limit = fusion::scanset::held_limit(k);
    let (what, cause) = if mode == "graph" {
        (
            format!("its links do not see {k} direction(s), which only its start holds"),
            "a coarse stage's pull that the finest cannot undo",
        )
    } else {
        (
            format!("its matches hold {k} direction(s) no better than its start does"),
            "along what the scans barely see, the matches' pull is no evidence",
        )
    };
    let remedy = match pipe_ran {
        PipeRan::Set => "the matches ran with a pipe's threshold already: give better starts".to_string(),
        PipeRan::Restart => {
            "the pipe's threshold, tried from the starts (restart), named scans too: give better starts".to_string()
        }
        PipeRan::No => format!(
            "a pipe or a tunnel needs --degeneracy-ratio {}; or give better starts",
            fusion::links::PIPE_DEGENERACY_RATIO
        ),
    };
    writeln!(
        out,
        "  not trusted: {name}: {what}, yet the stages moved it {moved:.3} m from its start along them ({chi2:.1} in \
         χ² of its covariance there, above {limit:.1}): {cause} — {remedy}"
    )?;
    Ok(true)
}

/// Why the verification names scan `i` (`untrusted` all it names;
/// `estimated` the scans whose scanners' positions their spacing gave): the
/// pairs that moved it, the free space it was placed in, or — when
/// neither, and it is not `explained` elsewhere (left undecided by the
/// restart, departed from its pairs' agreement) — the named scans it
/// agrees with, nothing verified tying it to the first.
#[allow(clippy::too_many_arguments)]
fn why_untrusted(
    out: &mut dyn Write,
    scans: &[InputScan],
    checks: &[CheckReport],
    untrusted: &[usize],
    estimated: &[bool],
    i: usize,
    explained: bool,
    tolerance: f64,
) -> std::io::Result<()> {
    let disagreeing = || checks.iter().filter(|c| !c.consistent && (c.source == i || c.target == i));
    let other = |c: &CheckReport| if c.source == i { c.target } else { c.source };
    let moved: Vec<String> = disagreeing()
        .filter(|c| !c.free_space.as_ref().is_some_and(|f| f.violated()))
        .filter_map(|c| {
            Some(format!(
                "{} ({:.3} m, {:.2}°, residual {:.4} → {:.4} m{})",
                scans[other(c)].name,
                c.moved_m?,
                c.angle_deg.unwrap_or_default(),
                c.start_rmse_m.unwrap_or_default(),
                c.rmse_m.unwrap_or_default(),
                if c.converged == Some(false) { ", still moving at its iteration cap" } else { "" }
            ))
        })
        .collect();
    if !moved.is_empty() {
        writeln!(
            out,
            "  not trusted: {}: matched again from the final poses it moves beyond {tolerance:.3} m and 5 % of its \
             radius, or settles where its residual says it is {}× closer, beyond the σ of the two poses' relative \
             pose, against {}: the poses are not where the data agree (a symmetric fit from rough starts?)",
            scans[i].name,
            fusion::verify::MAX_RESIDUAL_GAIN,
            moved.join(", ")
        )?;
    }
    let seen: Vec<String> = disagreeing()
        .filter_map(|c| {
            let f = c.free_space.as_ref().filter(|f| f.violated())?;
            let (from, of) = (f.seen_from, if f.seen_from == c.source { c.target } else { c.source });
            Some(format!(
                "{:.0} % of {}'s points where {}'s scanner{} saw through",
                100.0 * f.share,
                scans[of].name,
                scans[from].name,
                if estimated.get(from).copied().unwrap_or(false) { " (estimated from its spacing)" } else { "" }
            ))
        })
        .collect();
    if !seen.is_empty() {
        // Only from estimated scanners: a scan thinned on a grid can leave
        // an estimate metres off that still explains its spacing.
        let only_estimated = disagreeing()
            .filter_map(|c| c.free_space.as_ref().filter(|f| f.violated()))
            .all(|f| estimated.get(f.seen_from).copied().unwrap_or(false));
        writeln!(
            out,
            "  not trusted: {}: placed in another scan's free space ({}): a scan of another place, or a fit \
             that is not where the scans meet{}",
            scans[i].name,
            seen.join("; "),
            if only_estimated {
                " (judged from scanner positions estimated from the scans' spacing: if the scans were thinned on \
                 a grid, say where the scanners stood — --scanner-at-origin, a PCD's VIEWPOINT — or test without \
                 them, --no-viewpoint-estimate)"
            } else {
                ""
            }
        )?;
    }
    let on: Vec<&str> = checks
        .iter()
        .filter(|c| c.consistent && (c.source == i || c.target == i))
        .map(other)
        .filter(|j| untrusted.contains(j))
        .map(|j| scans[j].name.as_str())
        .collect();
    if moved.is_empty() && seen.is_empty() && !explained && !on.is_empty() {
        writeln!(
            out,
            "  not trusted: {}: it agrees only with scans named here ({}): nothing verified ties it to {}",
            scans[i].name,
            on.join(", "),
            scans[0].name
        )?;
    }
    Ok(())
}

/// The scans' disagreement at the registration the restart left as the
/// result: the last kept further restart's, the kept restart's, or the
/// schedule's.
fn kept_disagreement(r: &RestartReport) -> Option<f64> {
    match r.further.iter().rev().find(|f| f.kept) {
        Some(f) => f.disagreement_m2,
        None if r.kept => r.restart_disagreement_m2,
        None => r.schedule_disagreement_m2,
    }
}

/// A stage list's line: each stage's voxel, distance, runs and time.
fn stages(stages: &[StageReport]) -> String {
    let each: Vec<String> = stages
        .iter()
        .map(|s| {
            let cap = if s.settled { "" } else { ", abandoned at its cap" };
            format!("{:.3}/{:.3} m: {} runs, {:.3} s{cap}", s.voxel_m, s.max_correspondence_m, s.matches, s.seconds)
        })
        .collect();
    each.join("; ")
}

/// The line naming the scans the result moved beyond the finest stage's
/// `reach` (metres) of their starts where the scans agree with it not
/// clearly better than with their starts ([`RestartReport::unsupported`]);
/// nothing where there are none.
fn write_unsupported(out: &mut dyn Write, scans: &[InputScan], r: &RestartReport, reach: f64) -> std::io::Result<()> {
    if r.unsupported.is_empty() {
        return Ok(());
    }
    let moved: Vec<String> =
        r.unsupported.iter().map(|u| format!("{} ({:.3} m)", scans[u.scan].name, u.moved_m)).collect();
    let (kept, starts) = (kept_disagreement(r).unwrap_or(f64::NAN), r.starts_disagreement_m2.unwrap_or(f64::NAN));
    writeln!(
        out,
        "  not trusted: {}: the result moved them from their starts beyond the finest stage's reach ({reach:.3} m), \
         and the scans agree with it not clearly better than with their starts ({kept:.4e} against {starts:.4e} m² a \
         point, {:.4}×; moves that far need below {}×): nothing in the data supports such moves",
        moved.join(", "),
        kept / starts,
        fusion::scanset::SUPPORT_RATIO
    )
}

/// The scans two registrations place apart with nothing in the data to
/// choose between them (`restart.undecided`): trusted where every later
/// shorter schedule corroborates the one kept, else each named.
fn write_undecided(out: &mut dyn Write, scans: &[InputScan], r: &RestartReport) -> std::io::Result<()> {
    if r.undecided.is_empty() {
        return Ok(());
    }
    // (A repeated schedule's scans are left undecided by a shorter
    // schedule, not by the restart.)
    let (which, reached) = if r.repeated {
        (
            "the schedule's (the restart repeated it) and a shorter schedule's",
            "every other shorter schedule from the first that left the schedule's place".to_string(),
        )
    } else {
        ("the schedule's and the restart's", format!("every further restart from the starts ({})", r.further.len()))
    };
    if r.corroborated {
        let apart: Vec<String> = r
            .undecided
            .iter()
            .map(|u| format!("{} ({:.3} m, {:.2}°)", scans[u.scan].name, u.apart_m, u.apart_deg))
            .collect();
        writeln!(
            out,
            "  {which} registrations place {} apart, and the scans agree with neither clearly better (1.5×); \
             {reached} landed where the one kept does: that one is trusted",
            apart.join(", "),
        )?;
        return Ok(());
    }
    for u in &r.undecided {
        writeln!(
            out,
            "  not trusted: {}: {which} registrations place it {:.3} m, {:.2}° apart, and the scans agree with \
             neither clearly better (1.5×): the data do not tell which is right",
            scans[u.scan].name, u.apart_m, u.apart_deg
        )?;
    }
    Ok(())
}

/// The restart's lines: why it ran, what it did, and each further
/// restart's.
fn write_restart(out: &mut dyn Write, scans: &[InputScan], r: &RestartReport) -> std::io::Result<()> {
    let names = |list: &[usize]| -> String {
        if list.is_empty() {
            "none".into()
        } else {
            list.iter().map(|&i| scans[i].name.as_str()).collect::<Vec<_>>().join(", ")
        }
    };
    let why = match (r.trigger.as_str(), r.moved_m, &r.schedule_error) {
        ("disagreeing", ..) => format!(
            "the schedule's links disagree more than their covariances allow (variance factor above {})",
            fusion::scanset::RESTART_VARIANCE_FACTOR
        ),
        ("untrusted", ..) => format!(
            "the schedule's poses put points in another scanner's free space (named: {})",
            names(r.schedule_untrusted.as_deref().unwrap_or_default())
        ),
        ("named", ..) => format!(
            "the verification names scans of the schedule's result ({})",
            names(r.schedule_untrusted.as_deref().unwrap_or_default())
        ),
        ("creeping", ..) => "a pair matched again from the schedule's poses still moves at its iteration cap, and the \
                             scans agree there no better than at their starts"
            .into(),
        ("abandoned", ..) => "a simultaneous queue of the schedule was abandoned at its iteration cap".into(),
        ("unsupported", ..) => {
            "the schedule moved scans beyond the finest stage's reach of their starts, and the scans \
                                agree there no better than at their starts"
                .into()
        }
        (_, Some(m), _) => format!(
            "the schedule moved {} {m:.3} m from its start",
            r.scan.map_or("a scan", |i| scans[i].name.as_str())
        ),
        (_, None, e) => format!("the schedule failed ({})", e.as_deref().unwrap_or("")),
    };
    let named = match (&r.schedule_untrusted, &r.restart_untrusted) {
        (Some(before), Some(after)) if before.len() != after.len() => {
            format!("the verification names {} there against {} at the schedule's poses", names(after), names(before))
        }
        _ => String::new(),
    };
    let verdict = match (r.kept, r.further.iter().any(|f| f.kept)) {
        (true, _) => "its poses kept",
        (false, true) => "not kept, nor the schedule's",
        (false, false) => "the schedule's poses kept",
    };
    let outcome = match (r.restart_disagreement_m2, r.schedule_disagreement_m2, &r.error) {
        _ if !named.is_empty() => format!("{named}: {verdict}"),
        (Some(after), Some(before), _) => format!(
            "the scans disagree {after:.3e} m² a point there against {before:.3e} at the schedule's poses: {verdict}"
        ),
        (_, _, Some(e)) => format!("it failed ({e}): {verdict}"),
        _ => "its poses kept".into(),
    };
    match r.degeneracy_ratio {
        Some(ratio) => writeln!(
            out,
            "restart: {why}, named only by moves along what only the starts hold, a queue abandoned at its cap; \
             from the starts with a pipe's blind-direction threshold, {ratio} ({}), {outcome}",
            stages(&r.stages)
        )?,
        None => {
            writeln!(out, "restart: {why}; from the starts without the first stage ({}), {outcome}", stages(&r.stages))?
        }
    }
    if !r.further.is_empty() {
        writeln!(
            out,
            "  not to be trusted (scans named, or the scans agree no better than at their starts, {:.3e} m² a \
             point{}{}):",
            r.starts_disagreement_m2.unwrap_or(f64::NAN),
            if r.repeated { "; or the restart only repeated the schedule's long move" } else { "" },
            if r.disagreeing_links {
                format!(
                    "; or its links disagree beyond a variance factor of {}",
                    fusion::scanset::GROSS_VARIANCE_FACTOR
                )
            } else {
                String::new()
            }
        )?;
    }
    for (k, f) in r.further.iter().enumerate() {
        let outcome = match (f.disagreement_m2, &f.error) {
            (Some(a), _) => format!(
                "the scans disagree {a:.3e} m² a point there: {}",
                match f.untrusted.as_deref() {
                    _ if f.nearer_starts => format!(
                        "its poses kept, nearer the starts (it moves a scan at most {:.3} m from its start; the scans \
                         agreed no better with the result before it than with their starts)",
                        f.moved_m.unwrap_or(f64::NAN)
                    ),
                    _ if f.kept => "its poses kept".to_string(),
                    Some(named) if !named.is_empty() => format!("not kept (the verification names {})", names(named)),
                    _ if f.degeneracy_ratio.is_some() =>
                        "not kept (the scans disagree there beyond 1.5× the best before)".to_string(),
                    _ => "not kept (not 1.5× better than the best before)".to_string(),
                }
            ),
            (None, e) => format!("it failed ({}): not kept", e.as_deref().unwrap_or("")),
        };
        match f.degeneracy_ratio {
            Some(ratio) => writeln!(
                out,
                "  again from the starts with a pipe's blind-direction threshold, {ratio} ({}): named only by \
                 moves along what only the starts hold, {outcome}",
                stages(&f.stages)
            )?,
            // (After the pipe's restart, the first is without the
            // first stage.)
            None => writeln!(
                out,
                "  again without the first {} stage{} ({}), {outcome}",
                k + 1 + usize::from(r.degeneracy_ratio.is_none()),
                if k == 0 && r.degeneracy_ratio.is_some() { "" } else { "s" },
                stages(&f.stages)
            )?,
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::documents::matching::{FurtherReport, UndecidedReport, UnsupportedReport};

    fn check(target: usize, source: usize, moved_m: f64, consistent: bool) -> CheckReport {
        CheckReport {
            source,
            target,
            overlap: 1000,
            moved_m: Some(moved_m),
            angle_deg: Some(0.0),
            chi2: None,
            relative_motion: Some(moved_m / 10.0),
            seen_motion_m: Some(moved_m),
            rmse_m: Some(0.01),
            start_rmse_m: Some(0.01),
            converged: Some(true),
            noise_m: 0.01,
            relative_sigma_xyz_m: None,
            relative_sigma_rot_deg: None,
            relative_chi2: None,
            relative_dof: None,
            consistent,
            free_space: None,
        }
    }

    fn why(checks: &[CheckReport], untrusted: &[usize], i: usize, undecided: bool) -> String {
        let scans: Vec<InputScan> = ["a", "b", "c", "d"].iter().map(|n| InputScan::empty(n, n)).collect();
        let mut out = Vec::new();
        why_untrusted(&mut out, &scans, checks, untrusted, &[], i, undecided, 0.05).expect("written");
        String::from_utf8(out).expect("UTF-8")
    }

    #[test]
    fn a_scan_that_agrees_only_with_named_scans_says_so_and_with_which() {
        // b moved 1.2 m against a; c agrees with b (named) and nothing else.
        let checks = [check(0, 1, 1.2, false), check(1, 2, 0.001, true), check(0, 3, 0.001, true)];
        let named = [1, 2];
        let b = why(&checks, &named, 1, false);
        assert!(
            b.contains("b: matched again from the final poses it moves") && b.contains("against a (1.200 m"),
            "{b}"
        );
        assert!(!b.contains("agrees only"), "{b}");
        let c = why(&checks, &named, 2, false);
        assert_eq!(c, "  not trusted: c: it agrees only with scans named here (b): nothing verified ties it to a\n");
        // Left undecided by the restart, it is said there instead.
        assert_eq!(why(&checks, &named, 2, true), "");
    }

    /// A departure beyond the limit in σ² and the voxel in motion is said
    /// with its size; within either, nothing.
    #[test]
    fn a_departure_from_where_the_pairs_agree_says_how_far() {
        let scan = |chi2: f64, moved: f64| ScanReport {
            file: "b.ply".into(),
            name: "b".into(),
            number: 1,
            world_from_scan: [[0.0; 4]; 4],
            covariance: [[0.0; 6]; 6],
            departure: Some([0.012, 0.0, 0.0, 0.0, 0.016, 0.0]),
            departure_chi2: Some(chi2),
            departure_m: Some(moved),
            degenerate_directions: Vec::new(),
            held_chi2: None,
            held_m: None,
            held_directions: Vec::new(),
            viewpoint: None,
        };
        let said = |s: &ScanReport| {
            let mut out = Vec::new();
            let departed = why_departed(&mut out, "b", "simultaneous", s, 0.04).expect("written");
            (departed, String::from_utf8(out).expect("UTF-8"))
        };
        let (departed, text) = said(&scan(4744.0, 0.14));
        assert!(departed);
        assert_eq!(
            text,
            "  not trusted: b: simultaneous matching stopped 0.688°, 16.0 mm from where its verified pairs agree (4744 \
             σ² of their adjustment, above 1500; its points 0.140 m, beyond 0.040 m): a compromise of its matches \
             that no pair alone names; graph mode places the scans where their pairs agree\n"
        );
        assert_eq!(said(&scan(1400.0, 0.14)), (false, String::new()));
        assert_eq!(said(&scan(4744.0, 0.004)), (false, String::new()));
    }

    /// A graph-mode scan moved along what it reports blind beyond the
    /// χ² limit for as many directions and the voxel in motion is said
    /// with both; within either, or with nothing blind, nothing.
    #[test]
    fn a_move_along_what_only_the_start_holds_says_what_a_pipe_needs() {
        let scan = |blind: usize, chi2: f64, moved: f64| ScanReport {
            file: "b.ply".into(),
            name: "b".into(),
            number: 1,
            world_from_scan: [[0.0; 4]; 4],
            covariance: [[0.0; 6]; 6],
            departure: None,
            departure_chi2: None,
            departure_m: None,
            degenerate_directions: vec![[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]; blind],
            held_chi2: (blind > 0).then_some(chi2),
            held_m: (blind > 0).then_some(moved),
            held_directions: vec![[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]; blind],
            viewpoint: None,
        };
        let said = |s: &ScanReport| {
            let mut out = Vec::new();
            let held = why_held(&mut out, "b", "graph", s, 0.0085, PipeRan::No).expect("written");
            (held, String::from_utf8(out).expect("UTF-8"))
        };
        let (held, text) = said(&scan(2, 18.8, 0.074));
        assert!(held);
        assert_eq!(
            text,
            "  not trusted: b: its links do not see 2 direction(s), which only its start holds, yet the stages moved \
             it 0.074 m from its start along them (18.8 in χ² of its covariance there, above 13.8): a coarse stage's \
             pull that the finest cannot undo — a pipe or a tunnel needs --degeneracy-ratio 0.01; or give better starts\n"
        );
        // 12 is beyond one direction's limit (10.8), within two's (13.8).
        assert!(said(&scan(1, 12.0, 0.074)).0);
        assert_eq!(said(&scan(2, 12.0, 0.074)), (false, String::new()));
        assert_eq!(said(&scan(2, 18.8, 0.005)), (false, String::new()));
        assert_eq!(said(&scan(0, 18.8, 0.074)), (false, String::new()));
        // The other modes: the directions its matches hold no better than
        // the start, whatever they report blind.
        let mut pairwise = scan(2, 18.8, 0.074);
        pairwise.degenerate_directions.clear();
        let mut out = Vec::new();
        assert!(why_held(&mut out, "b", "pairwise", &pairwise, 0.0085, PipeRan::No).expect("written"));
        assert_eq!(
            String::from_utf8(out).expect("UTF-8"),
            "  not trusted: b: its matches hold 2 direction(s) no better than its start does, yet the stages moved it \
             0.074 m from its start along them (18.8 in χ² of its covariance there, above 13.8): along what the scans \
             barely see, the matches' pull is no evidence — a pipe or a tunnel needs --degeneracy-ratio 0.01; or give \
             better starts\n"
        );
        // Where the pipe's threshold ran already, it is not the remedy.
        let mut out = Vec::new();
        assert!(why_held(&mut out, "b", "pairwise", &pairwise, 0.0085, PipeRan::Restart).expect("written"));
        let text = String::from_utf8(out).expect("UTF-8");
        assert!(
            text.ends_with(
                "no evidence — the pipe's threshold, tried from the starts (restart), named scans too: give better \
                 starts\n"
            ),
            "{text}"
        );
        // Where the set ran with it (given, or the scans found a pipe), neither.
        let mut out = Vec::new();
        assert!(why_held(&mut out, "b", "pairwise", &pairwise, 0.0085, PipeRan::Set).expect("written"));
        let text = String::from_utf8(out).expect("UTF-8");
        assert!(
            text.ends_with("no evidence — the matches ran with a pipe's threshold already: give better starts\n"),
            "{text}"
        );
    }

    /// The restart with a pipe's threshold says so, and the further
    /// restarts after it count the stages they leave out from one.
    /// A stage of `voxel_m` cells, 16 runs in 0.5 s.
    fn stage(voxel_m: f64, settled: bool) -> StageReport {
        StageReport { voxel_m, max_correspondence_m: 4.0 * voxel_m, matches: 16, seconds: 0.5, settled }
    }

    /// A further restart with the last `n` of two stages, not kept, b named.
    fn further(n: usize) -> FurtherReport {
        FurtherReport {
            stages: [0.02, 0.01][2 - n..].iter().map(|&v| stage(v, false)).collect(),
            disagreement_m2: Some(3.2e-5),
            error: None,
            kept: false,
            untrusted: Some(vec![1]),
            degeneracy_ratio: None,
            moved_m: Some(0.3),
            nearer_starts: false,
        }
    }

    /// A restart set off by b's move, not kept, with `further` and the
    /// blind-direction threshold `ratio`.
    fn restart(ratio: Option<f64>, further: Vec<FurtherReport>) -> RestartReport {
        RestartReport {
            scan: Some(1),
            moved_m: Some(0.77),
            schedule_error: None,
            stages: vec![stage(0.04, true), stage(0.02, true), stage(0.01, true)],
            schedule_disagreement_m2: Some(3.2e-5),
            restart_disagreement_m2: Some(3.8e-5),
            starts_disagreement_m2: Some(3.9e-5),
            error: None,
            kept: false,
            trigger: "moved".into(),
            schedule_untrusted: Some(vec![1]),
            restart_untrusted: Some(vec![1]),
            undecided: Vec::new(),
            corroborated: false,
            repeated: false,
            disagreeing_links: false,
            unsupported: Vec::new(),
            further,
            degeneracy_ratio: ratio,
        }
    }

    /// The long moves a result the scans agree with not clearly better
    /// than with their starts are named with the two agreements, their
    /// ratio and the ratio needed (the building's scan009 at 0.9963×).
    #[test]
    fn unsupported_moves_say_how_far_and_how_little_better_the_scans_agree() {
        let scans: Vec<InputScan> = ["a", "b"].iter().map(|n| InputScan::empty(n, n)).collect();
        let r = RestartReport {
            kept: true,
            restart_disagreement_m2: Some(4.6521e-2),
            starts_disagreement_m2: Some(4.6695e-2),
            unsupported: vec![UnsupportedReport { scan: 1, moved_m: 1.2287 }],
            ..restart(None, Vec::new())
        };
        let mut out = Vec::new();
        write_unsupported(&mut out, &scans, &r, 0.428).expect("written");
        assert_eq!(
            String::from_utf8(out).expect("UTF-8"),
            "  not trusted: b (1.229 m): the result moved them from their starts beyond the finest stage's reach \
             (0.428 m), and the scans agree with it not clearly better than with their starts (4.6521e-2 against \
             4.6695e-2 m² a point, 0.9963×; moves that far need below 0.99×): nothing in the data supports such \
             moves\n"
        );
        let mut out = Vec::new();
        write_unsupported(&mut out, &scans, &restart(None, Vec::new()), 0.428).expect("written");
        assert!(out.is_empty());
    }

    #[test]
    fn undecided_scans_say_which_registrations_place_them_apart_and_whether_they_are_trusted() {
        let scans: Vec<InputScan> = ["a", "b"].iter().map(|n| InputScan::empty(n, n)).collect();
        let said = |repeated: bool, corroborated: bool| {
            let undecided = vec![UndecidedReport { scan: 1, apart_m: 1.854, apart_deg: 2.44 }];
            let r = RestartReport { undecided, repeated, corroborated, ..restart(None, vec![further(2), further(1)]) };
            let mut out = Vec::new();
            write_undecided(&mut out, &scans, &r).expect("written");
            String::from_utf8(out).expect("UTF-8")
        };
        assert_eq!(
            said(false, false),
            "  not trusted: b: the schedule's and the restart's registrations place it 1.854 m, 2.44° apart, and the \
             scans agree with neither clearly better (1.5×): the data do not tell which is right\n"
        );
        assert_eq!(
            said(false, true),
            "  the schedule's and the restart's registrations place b (1.854 m, 2.44°) apart, and the scans agree with \
             neither clearly better (1.5×); every further restart from the starts (2) landed where the one kept does: \
             that one is trusted\n"
        );
        // A repeated schedule's: a shorter schedule left them undecided.
        assert_eq!(
            said(true, false),
            "  not trusted: b: the schedule's (the restart repeated it) and a shorter schedule's registrations place it \
             1.854 m, 2.44° apart, and the scans agree with neither clearly better (1.5×): the data do not tell which \
             is right\n"
        );
        assert!(
            said(true, true).contains(
                "; every other shorter schedule from the first that left the schedule's place landed where the one \
                 kept does: that one is trusted\n"
            ),
            "{}",
            said(true, true)
        );
        // Nothing undecided, nothing said.
        let mut out = Vec::new();
        write_undecided(&mut out, &scans, &restart(None, Vec::new())).expect("written");
        assert!(out.is_empty());
    }

    #[test]
    fn a_restart_with_the_pipes_threshold_says_why_and_the_further_count_on() {
        let said = |r: &RestartReport| {
            let scans: Vec<InputScan> = ["a", "b"].iter().map(|n| InputScan::empty(n, n)).collect();
            let mut out = Vec::new();
            write_restart(&mut out, &scans, r).expect("written");
            String::from_utf8(out).expect("UTF-8")
        };
        let pipe = said(&restart(Some(0.01), vec![further(2), further(1)]));
        assert!(
            pipe.starts_with(
                "restart: the schedule moved b 0.770 m from its start, named only by moves along what only the \
                 starts hold, a queue abandoned at its cap; from the starts with a pipe's blind-direction threshold, \
                 0.01 (0.040/0.160 m: 16 runs, 0.500 s; "
            ),
            "{pipe}"
        );
        assert!(pipe.contains("\n  again without the first 1 stage (0.020/0.080 m"), "{pipe}");
        assert!(pipe.contains("\n  again without the first 2 stages (0.010/0.040 m"), "{pipe}");
        let usual = said(&restart(None, vec![further(1)]));
        assert!(
            usual.starts_with(
                "restart: the schedule moved b 0.770 m from its start; from the starts without the first stage (0.040"
            ),
            "{usual}"
        );
        assert!(usual.contains("\n  again without the first 2 stages (0.010/0.040 m"), "{usual}");
        // One kept as nearer the starts says so, and how far it moves a scan.
        let nearer = FurtherReport { kept: true, nearer_starts: true, untrusted: Some(Vec::new()), ..further(1) };
        let kept = said(&restart(None, vec![nearer]));
        assert!(
            kept.contains(
                "\n  again without the first 2 stages (0.010/0.040 m: 16 runs, 0.500 s, abandoned at its cap), the scans \
                 disagree 3.200e-5 m² a point there: its poses kept, nearer the starts (it moves a scan at most 0.300 m \
                 from its start; the scans agreed no better with the result before it than with their starts)\n"
            ),
            "{kept}"
        );
    }

    #[test]
    fn a_pair_that_settles_closer_says_by_how_much() {
        // d slid 0.3 m against a, within the motion tiers, to a fit with
        // its residual 25.6 → 7.6 mm.
        let mut slid = check(0, 3, 0.3, false);
        (slid.start_rmse_m, slid.rmse_m, slid.angle_deg) = (Some(0.0256), Some(0.0076), Some(0.17));
        let d = why(&[slid], &[3], 3, false);
        assert_eq!(
            d,
            "  not trusted: d: matched again from the final poses it moves beyond 0.050 m and 5 % of its radius, or \
             settles where its residual says it is 1.5× closer, beyond the σ of the two poses' relative pose, against \
             a (0.300 m, 0.17°, residual 0.0256 → 0.0076 m): the poses are not where the data agree (a symmetric fit \
             from rough starts?)\n"
        );
    }

    #[test]
    fn a_pair_stopped_at_its_cap_says_so() {
        // d's pair with c crept 0.83 m and 3.7° at its iteration cap, its
        // residual barely lower (named, say, by another pair).
        let mut crept = check(2, 3, 0.825, false);
        (crept.start_rmse_m, crept.rmse_m, crept.angle_deg, crept.converged) =
            (Some(0.0510), Some(0.0488), Some(3.66), Some(false));
        let d = why(&[crept], &[3], 3, false);
        assert!(
            d.contains("against c (0.825 m, 3.66°, residual 0.0510 → 0.0488 m, still moving at its iteration cap)"),
            "{d}"
        );
    }
}
