//! Point-cloud fusion: scans into the world frame.
//!
//! - [`direct`]: the direct transformation with the CPS pose, tilt and lever
//!   arm ([`direct::world_from_scanner`], [`direct::transform`]).
//!
//! ICP, multi-view matching, CPS-prior ICP and pipe fitting are being built
//! (see the README's status table).
#![warn(missing_docs)]

pub mod direct;
