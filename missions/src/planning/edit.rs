//! `plan --optimize --out FILE`: the mission file with the chosen plan
//! filled in, edited through `toml_edit`, which keeps every comment, every
//! other key and the layout as written.

use std::path::Path;

use anyhow::{Context, Result};
use planner::{FormationKind, Strategy};
use toml_edit::{Array, DocumentMut, InlineTable, Item, TableLike, Value, value};

use super::analysis::Optimized;
use crate::mission::{ControlAt, Mission};

/// Writes the mission file with the chosen plan: `stride_m`, the formation
/// (`formation_m` as offsets, or the generated `formation` table when the
/// mission has one), `strategy`, `hops` and (when the search chose another)
/// `control_at` set, and a relative `scene_file`
/// made absolute when the new file lives in another directory. A header
/// comment says where the plan came from.
pub fn write_mission(mission: &Mission, optimized: &Optimized, path: &Path) -> Result<()> {
    let c = &optimized.best.candidate;
    let mut doc: DocumentMut = mission
        .source
        .text
        .parse()
        .with_context(|| format!("{}: re-reading the mission to edit it", mission.source.file.display()))?;
    let plan = doc
        .get_mut("plan")
        .and_then(Item::as_table_like_mut)
        .with_context(|| format!("{}: no [plan] table to edit", mission.source.file.display()))?;
    set(plan, "stride_m", c.stride_m.into());
    if plan.contains_key("formation") {
        let FormationKind::Symmetric { forward_m, lateral_m } = c.formation else {
            anyhow::bail!("the search returns symmetric formations only");
        };
        let mut t = InlineTable::new();
        t.insert("kind", "symmetric".into());
        t.insert("forward_m", forward_m.into());
        t.insert("lateral_m", lateral_m.into());
        t.insert("up_m", c.up_m.into());
        set(plan, "formation", Value::InlineTable(t));
    } else {
        let offsets: Array =
            optimized.offsets(mission).iter().map(|o| Value::Array(Array::from_iter([o.x, o.y, o.z]))).collect();
        set(plan, "formation_m", Value::Array(offsets));
    }
    set(plan, "strategy", c.strategy.name().into());
    match c.strategy {
        Strategy::ParentHops { hops } => {
            set(plan, "hops", i64::try_from(hops).context("hops beyond i64")?.into());
        }
        Strategy::Leapfrog => {
            plan.remove("hops");
        }
    }
    if !mission.control.is_empty() && optimized.control_at != mission.plan.control_at {
        let at: Value = match &optimized.control_at {
            ControlAt::Stations(list) => {
                Value::Array(list.iter().map(|&k| i64::try_from(k).map(Value::from)).collect::<Result<Array, _>>()?)
            }
            other => other.to_string().trim_matches('"').into(),
        };
        set(plan, "control_at", at);
        // The written comment described the written choice.
        if let Some(v) = plan.get_mut("control_at").and_then(Item::as_value_mut) {
            v.decor_mut().set_suffix(format!("  # chosen by plan --optimize (written: {})", mission.plan.control_at));
        }
    }
    let same_dir = path.parent().map(Path::to_path_buf).unwrap_or_default()
        == mission.source.file.parent().map(Path::to_path_buf).unwrap_or_default();
    if let (false, Some((resolved, _))) = (same_dir, &mission.backend.scene_file)
        && let Some(backend) = doc.get_mut("backend").and_then(Item::as_table_like_mut)
    {
        let absolute = std::fs::canonicalize(resolved).unwrap_or_else(|_| resolved.clone());
        set(backend, "scene_file", absolute.display().to_string().into());
    }
    let header = format!(
        "# Plan chosen by `cps-survey plan --optimize` from {}: {}, stride {} m, {} cycles,\n\
         # predicted final σx² + σy² = {:.3e} m².\n",
        mission.source.file.display(),
        c.strategy,
        c.stride_m,
        optimized.best.cycles(),
        optimized.best.sigma_xy2_m2
    );
    std::fs::write(path, header + &doc.to_string()).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// Sets `key` to `new`, keeping the comments and spacing around the value
/// it replaces (a new key goes at the end of the table).
fn set(table: &mut dyn TableLike, key: &str, mut new: Value) {
    if let Some(old) = table.get(key).and_then(Item::as_value) {
        *new.decor_mut() = old.decor().clone();
    }
    table.insert(key, value(new));
}
