//! Every JSON document the CLI writes, typed, and the versioned contract
//! they keep: each opens with `schema_version` (of that document's schema,
//! `docs/schemas/<name>.schema.json`) and `tool_version` (the cps-survey
//! that wrote it), then the document's own keys (docs/json.md).
//!
//! [`records`] are the shapes every document shares (position, pose,
//! ellipse, link, matrices as rows); then one file a document: [`run`]
//! (`report.json`, `fusion.json`), [`adjustment`], [`pipe`],
//! [`prediction`], [`plan`], [`montecarlo`], [`register`], [`matching`]
//! (`poses.json`), [`ports`] (`emulate --json`). The documents are made
//! where their data is (the runner, the commands, the views); this room
//! imports nothing of the crate.

pub mod adjustment;
pub mod matching;
pub mod montecarlo;
pub mod pipe;
pub mod plan;
pub mod ports;
pub mod prediction;
pub mod records;
pub mod register;
pub mod run;

use std::io::Write;

use schemars::JsonSchema;
use serde::Serialize;

/// The cps-survey version written into every document.
pub const TOOL_VERSION: &str = env!("CARGO_PKG_VERSION");

/// A JSON document of the contract: its schema's file name and version.
pub trait Document: Serialize + JsonSchema {
    /// `docs/schemas/<NAME>.schema.json`.
    const NAME: &'static str;
    /// Raised when a key changes meaning or goes; keys are only ever added
    /// within a version.
    const VERSION: u32;
    /// Whether the document carries `schema_version` and `tool_version` as
    /// its own keys (the adjustment, which `report.json` nests whole).
    const SELF_VERSIONED: bool = false;
}

/// `document` with its header: what is written, and what the schema
/// describes.
#[derive(Debug, Serialize, JsonSchema)]
pub struct Versioned<'a, T> {
    /// The version of this document's schema.
    pub schema_version: u32,
    /// The cps-survey version that wrote this document.
    pub tool_version: &'static str,
    /// The document.
    #[serde(flatten)]
    pub document: &'a T,
}

/// `document` with its header.
pub fn versioned<T: Document>(document: &T) -> Versioned<'_, T> {
    Versioned { schema_version: T::VERSION, tool_version: TOOL_VERSION, document }
}

/// Writes `document` with its header as one JSON line.
pub fn write_line<T: Document>(out: &mut dyn Write, document: &T) -> std::io::Result<()> {
    // Through a block buffer: stdout is line-buffered, and serde's many
    // small writes each searched for a newline (a tenth of a 10,000-cycle
    // `predict --json`, 60 MB on one line).
    let mut buffered = std::io::BufWriter::with_capacity(1 << 16, &mut *out);
    if T::SELF_VERSIONED {
        serde_json::to_writer(&mut buffered, document)?;
    } else {
        serde_json::to_writer(&mut buffered, &versioned(document))?;
    }
    writeln!(buffered)?;
    buffered.flush()
}

/// Writes `document` with its header as pretty JSON (with a final
/// newline) to `path`.
pub fn write_file<T: Document>(path: &std::path::Path, document: &T) -> anyhow::Result<()> {
    use anyhow::Context;
    let text = if T::SELF_VERSIONED {
        serde_json::to_string_pretty(document)?
    } else {
        serde_json::to_string_pretty(&versioned(document))?
    } + "\n";
    // A new file renamed into place: never half-written, never through a link.
    scanner::io::replace_file(path, text.as_bytes()).with_context(|| format!("writing {}", path.display()))
}

/// The JSON Schema (draft 2020-12) of `T`'s documents, header included.
pub fn schema<T: Document + 'static>() -> schemars::Schema {
    // The documents are written, never read: the serialization contract
    // (a key skipped when empty is optional, `serde(default)` is not).
    let generator = || schemars::generate::SchemaSettings::draft2020_12().for_serialize().into_generator();
    let own = generator().into_root_schema_for::<T>();
    let mut schema =
        if T::SELF_VERSIONED { own.clone() } else { generator().into_root_schema_for::<Versioned<'static, T>>() };
    schema.insert("title".into(), format!("cps-survey {} document, schema version {}", T::NAME, T::VERSION).into());
    // The document's own description, not the header's.
    match own.get("description") {
        Some(d) => schema.insert("description".into(), d.clone()),
        None => schema.remove("description"),
    };
    schema
}
