//! Point-cloud fusion: scans into the world frame.
//!
//! - [`direct`]: the direct transformation with the CPS pose, tilt and lever
//!   arm ([`direct::world_from_scanner`], [`direct::transform`]);
//! - [`icp`]: point-to-point (Horn) and point-to-plane ICP on a `kiddo`
//!   k-d tree ([`icp::Target`], [`icp::align`], [`icp::align_coarse_to_fine`],
//!   [`icp::IcpResult`]).
//!
//! Multi-view matching, CPS-prior ICP and pipe fitting are being built (see
//! the README's status table).
#![warn(missing_docs)]

pub mod direct;
pub mod error;
pub mod icp;

pub use error::{FusionError, Result};
