//! What the user sees: [`tables`] on the terminal, [`json`] documents (each
//! a versioned [`crate::documents`] type), the
//! adjustment's [`listing`],
//! [`plot`]s (SVG) and the Rerun [`recording`]; [`shapes`] is the geometry
//! the plot and the recording share; [`target`] where a recording goes.

pub mod json;
pub mod listing;
pub mod plot;
#[cfg(feature = "recording")]
pub mod recording;
#[cfg(not(feature = "recording"))]
#[path = "headless.rs"]
pub mod recording;
pub mod shapes;
pub mod tables;
pub mod target;
