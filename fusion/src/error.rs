//! The one error type of the `fusion` crate.

use thiserror::Error;

/// What can go wrong while fusing scans.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum FusionError {
    /// Too few point pairs within the correspondence distance.
    #[error(
        "ICP: {found} correspondences within {max_distance_m} m at iteration {iteration}: expected at least {needed} (is the initial guess within the correspondence distance?)"
    )]
    TooFewCorrespondences {
        /// Pairs found.
        found: usize,
        /// Pairs needed.
        needed: usize,
        /// The correspondence distance, metres.
        max_distance_m: f64,
        /// Iteration (0-based).
        iteration: usize,
    },
    /// A setting is out of range.
    #[error("{what} = {value} is out of range: expected {expected}")]
    OutOfRange {
        /// Which setting.
        what: String,
        /// Its value.
        value: f64,
        /// What is accepted.
        expected: String,
    },
    /// The geometry does not constrain all six degrees of freedom.
    #[error("ICP: the normal equations are singular ({what}); the scans do not constrain all six degrees of freedom")]
    Degenerate {
        /// Where.
        what: String,
    },
    /// Global registration found no transform for a scan.
    #[error("global registration: {why}")]
    NoGlobalMatch {
        /// Why, in words.
        why: String,
    },
    /// A scan does not overlap the scans it must be matched against.
    #[error(
        "multi-view: scan {scan} has {pairs} correspondences with {against}: expected at least {needed} (is its pose guess within the correspondence distance, and do the scans overlap?)"
    )]
    NoOverlap {
        /// The scan's index.
        scan: usize,
        /// Correspondences found.
        pairs: usize,
        /// Correspondences needed.
        needed: usize,
        /// What it was matched against.
        against: String,
        /// That scan's index, when it was one scan (pairwise).
        partner: Option<usize>,
        /// The stage of a schedule it happened in (1-based; `None` outside
        /// one): from stage 2 on, the poses are the previous stage's, not
        /// the starts.
        stage: Option<usize>,
    },
    /// An error while matching one scan of a set.
    #[error("scan {scan}: {source}")]
    InScan {
        /// The scan's index.
        scan: usize,
        /// What went wrong.
        source: Box<FusionError>,
    },
    /// A scanner or file error.
    #[error(transparent)]
    Scanner(#[from] scanner::ScannerError),
}

impl FusionError {
    /// `Ok` when `value` is finite and > 0, else [`FusionError::OutOfRange`]
    /// naming `what`.
    pub(crate) fn require_positive(what: &str, value: f64) -> Result<()> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(FusionError::OutOfRange { what: what.into(), value, expected: "finite and > 0".into() })
        }
    }

    /// `Ok` when `value` is finite and ≥ 0, else [`FusionError::OutOfRange`]
    /// naming `what`.
    pub(crate) fn require_non_negative(what: &str, value: f64) -> Result<()> {
        if value.is_finite() && value >= 0.0 {
            Ok(())
        } else {
            Err(FusionError::OutOfRange { what: what.into(), value, expected: "finite and ≥ 0".into() })
        }
    }
}

/// Result alias of the `fusion` crate.
pub type Result<T, E = FusionError> = std::result::Result<T, E>;
