//! The Cooperative Positioning System model: pure math, no I/O, no threads.
//!
//! A parent robot with a total station and N ≥ 2 child robots with prisms
//! "dance": children move and the standing parent measures them
//! ([`TeamState::place_child`], seed 003 eqs 17–24); then the parent moves and
//! fixes itself from the standing children by weighted least squares
//! ([`TeamState::fix_parent`], eqs 7–16). The **joint** covariance of parent
//! and children is carried with every cross-term.
//!
//! Principal types:
//! - [`ParentPose`] (x, y, z, θ) and [`Reading`] (r, φ, ψ) — [`observation`];
//! - [`Instrument`] — the total station's noise model and limits;
//! - [`TeamState`] — means and joint covariance, order (x, y, z, θ) then each
//!   child's (x, y, z);
//! - [`ParentFix`] — a fix's pose, Σ_0, the F map, σ0² and, on request,
//!   redundancy numbers and Baarda w-statistics ([`Reliability`]);
//! - [`batch::Network`] / [`batch::adjust`] — the whole dance as one
//!   least-squares adjustment.
//!
//! - [`geom::Scene`] — surfaces with a BVH for ray casting and line of sight,
//!   the built-in scenes and the scene file.
//!
//! Units are SI (m, rad) throughout; frames are right-handed with z up.
#![warn(missing_docs)]

pub mod batch;
pub mod chain;
pub mod error;
pub mod fix;
pub mod geom;
pub mod instrument;
pub mod observation;
pub mod placement;
pub mod screen;
pub mod state;
pub mod stats;

pub use error::{CpsError, Result};

/// The largest coordinate a mission, a scene or a start pose may give,
/// metres (|x|, |y|, |z|): beyond every projected grid (false northings
/// reach 10⁷ m), and where f64 still holds 15 nm. Larger ones are refused
/// when read (issue 34, U1: a route at 3·10¹⁴ m validated, then stopped
/// the run's recording).
pub const MAX_COORDINATE_M: f64 = 1e8;
pub use fix::{FixOptions, ParentFix, Reliability, SightedChild, closed_form_start, fix_parent};
pub use instrument::{DistanceErrorModel, Instrument, RAD_PER_ARCSEC};
pub use observation::{ParentPose, Reading, observe, wrap_angle};
pub use placement::{Placement, place};
pub use state::TeamState;
pub use stats::{CHI2_2D_95_SQRT, CHI2_3D_95_SQRT, ErrorEllipse, W_CRITICAL, drift_percent, sigma_xy2};
