//! Point-cloud fusion: direct transformation to the world frame, ICP,
//! multi-view matching, CPS-prior ICP and pipe fitting.
//!
//! This crate is built up by the fusion issue; nothing is exposed yet.
#![warn(missing_docs)]
