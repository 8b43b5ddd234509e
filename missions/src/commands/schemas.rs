//! `cps-survey schemas [NAME] [--out DIR]`: the JSON Schema of every JSON
//! document the tool writes, generated from the types that write them
//! (`docs/schemas/` holds this version's).

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};

use super::Outcome;
use crate::documents::{Document, schema};

/// `schemas`' arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct SchemasArgs {
    /// One document's schema to print (`report`, `fusion`, `adjust`,
    /// `predict`, `plan`, `montecarlo`, `register`, `match`, `emulate`);
    /// without it,
    /// the list.
    pub name: Option<String>,
    /// Write every schema into DIR as `<name>.schema.json`.
    #[arg(long, value_name = "DIR", conflicts_with = "name")]
    pub out: Option<PathBuf>,
}

/// Every document: its name, its schema version, where it is written and
/// its schema.
pub fn documents() -> Vec<(&'static str, u32, &'static str, schemars::Schema)> {
    fn of<T: Document + 'static>(written: &'static str) -> (&'static str, u32, &'static str, schemars::Schema) {
        (T::NAME, T::VERSION, written, schema::<T>())
    }
    vec![
        of::<crate::documents::run::RunReport>("RUN_DIR/report.json"),
        of::<crate::documents::run::FusionReport>("RUN_DIR/fusion/<mode>/fusion.json, fuse --json"),
        of::<crate::documents::adjustment::AdjustmentReport>("adjust --json, report.json's adjustment"),
        of::<crate::documents::prediction::PredictionJson>("predict --json"),
        of::<crate::documents::plan::PlanJson>("plan --json"),
        of::<crate::documents::montecarlo::MonteCarloJson>("montecarlo --json"),
        of::<crate::documents::register::RegisterReport>("register --json"),
        of::<crate::documents::matching::MatchReport>("match --json, OUT/poses.json"),
        of::<crate::documents::ports::PortsJson>("emulate --json"),
    ]
}

/// Runs `schemas`.
pub fn run(args: &SchemasArgs, out: &mut dyn Write) -> Result<Outcome> {
    let documents = documents();
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for (name, _, _, schema) in &documents {
            let path = dir.join(format!("{name}.schema.json"));
            let text = serde_json::to_string_pretty(schema)? + "\n";
            // Renamed into place: a link there is replaced, not written through.
            scanner::io::replace_file(&path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))?;
        }
        writeln!(out, "wrote {} schemas into {}", documents.len(), dir.display())?;
    } else if let Some(name) = &args.name {
        let Some((_, _, _, schema)) = documents.iter().find(|d| d.0 == name) else {
            let names: Vec<_> = documents.iter().map(|d| d.0).collect();
            bail!("no document named \"{name}\"; expected one of {}", names.join(", "));
        };
        writeln!(out, "{}", serde_json::to_string_pretty(schema)?)?;
    } else {
        writeln!(out, "{:<11} {:>7}  written as", "document", "version")?;
        for (name, version, written, _) in &documents {
            writeln!(out, "{name:<11} {version:>7}  {written}")?;
        }
    }
    Ok(Outcome::Success)
}
