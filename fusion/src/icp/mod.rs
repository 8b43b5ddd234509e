//! ICP (seed 000 §4): point-to-point with Horn's closed-form rotation and
//! point-to-plane with normals from the k nearest neighbours, nearest
//! neighbours through a `kiddo` k-d tree built once per target (and, from
//! the second iteration, mostly through each target point's
//! `Neighbourhood` instead), a maximum correspondence distance and a
//! coarse-to-fine schedule.
//!
//! **Covariance convention.** [`IcpResult::information`] is the 6×6 inverse
//! covariance of the error ξ = (ω, v) — rotation first, then translation — in
//! the **target** frame with **left** perturbation:
//! `target_from_source_true = exp(ξ) · target_from_source`, so a source
//! point p maps to `T̂p + ω × T̂p + v`. It is `Jᵀ J / (k·σ̂²)` at the last
//! linearisation point (within the tolerances of the solution when
//! converged), with σ̂² the residual variance per scalar residual and k
//! [`IcpConfig::noise_scale`] (1, or what the data's halves measured of
//! that model: [`crate::noise`]).
//!
//! Parts, as small_gicp keeps its registration: [`config`] (the metric, the
//! kernel, the settings), [`target`] (the k-d tree, normals and the
//! neighbourhood certificate of a target cloud), [`correspondences`] (one
//! pass of nearest neighbours into the normal equations' sums) and
//! [`solve`] (the iteration: Horn's closed form or Gauss–Newton, with an
//! optional pose prior, and the coarse-to-fine schedule); [`degeneracy`]
//! finds the directions the matches cannot see.

pub mod config;
pub mod correspondences;
pub mod degeneracy;
pub mod solve;
pub mod target;

pub use crate::se3::Prior;
pub use config::{IcpConfig, Kernel, Method};
pub use degeneracy::Observability;
pub use solve::{IcpResult, Stage, align, align_coarse_to_fine, align_with_prior};
pub use target::{KdTree, Target};
