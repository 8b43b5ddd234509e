//! Point-cloud fusion: scans into the world frame.
//!
//! - [`direct`]: the direct transformation with the CPS pose, tilt and lever
//!   arm ([`direct::world_from_scanner`], [`direct::transform`]);
//! - [`icp`]: point-to-point (Horn) and point-to-plane ICP on a `kiddo`
//!   k-d tree ([`icp::Target`], [`icp::align`], [`icp::align_coarse_to_fine`],
//!   [`icp::IcpResult`]);
//! - [`multiview`]: pairwise, incremental and simultaneous matching of many
//!   scans ([`multiview::register_views`]);
//! - [`links`]: a scan set adjusted over all its overlapping pairs, blind
//!   directions held by the start ([`links::adjust`]);
//! - [`noise`]: the covariance model calibrated on the data, by matching
//!   random halves and quarters of each scan ([`noise::calibrate`]);
//! - [`scanset`]: a user's scan set registered coarse to fine by a
//!   strategy or the link graph ([`scanset::register_set`]);
//! - [`graph`]: scan poses adjusted to absolute priors (the CPS poses) and
//!   relative ICP matches together ([`graph::optimize`], [`graph::cps_prior`]);
//! - [`chi2`]: the χ² limits every test of a move against its σ uses
//!   ([`chi2::chi2_999`], [`chi2::within`]);
//! - [`se3`]: the shared pose convention (ξ = (ω, v), left perturbation)
//!   and a Gaussian pose prior ([`se3::Prior`]);
//! - [`pipe`]: tube fitting into scanned pipes and the deviation map
//!   ([`pipe::fit_pipe`], [`pipe::anomalies`]);
//! - [`viewpoint`]: a scanner's position estimated from its scan's point
//!   spacing, for the free-space test of scans that do not state it
//!   ([`viewpoint::estimate`]).
#![warn(missing_docs)]

mod agreement;
mod candidates;
pub mod chi2;
pub mod direct;
pub mod error;
pub mod free_space;
pub mod global;
pub mod graph;
pub mod icp;
pub mod links;
pub mod multiview;
pub mod noise;
pub mod pipe;
pub mod priors;
pub mod scale;
pub mod scanset;
pub mod se3;
pub mod verify;
pub mod viewpoint;

pub use error::{FusionError, Result};
