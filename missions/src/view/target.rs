//! Where a recording goes and how it opens: the same in every build (the
//! recording's, and the headless build's, which refuses them).

/// Which default layout a recording opens with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// A run: the world, the accuracy series, fix σ0², the event log.
    Mission,
    /// A plan (`--rrd`): the world, the predicted series, the violations.
    Plan,
}

/// Where the recording goes besides `mission.rrd`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum Viewer {
    /// The file only.
    #[default]
    None,
    /// Start a viewer (`rerun` on the PATH) and stream to it too.
    Spawn,
    /// Stream to a running viewer at this URL too
    /// (e.g. `rerun+http://127.0.0.1:9876/proxy`).
    Connect(String),
}
