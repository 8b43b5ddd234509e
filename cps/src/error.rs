//! The one error type of the `cps` crate.

use thiserror::Error;

/// Everything that can go wrong in the CPS model. Each variant names the
/// offending quantity, its value and what was expected.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum CpsError {
    /// A parent fix needs at least two children.
    #[error("a parent fix needs at least 2 children, got {got}")]
    TooFewChildren {
        /// Number of children given.
        got: usize,
    },
    /// A number that must be finite is NaN or infinite.
    #[error("{what} must be finite, got {value}")]
    NonFinite {
        /// What the number is (e.g. "slope distance of child 1").
        what: String,
        /// The value found.
        value: f64,
    },
    /// A number lies outside its allowed range.
    #[error("{what} = {value} is out of range: expected {expected}")]
    OutOfRange {
        /// What the number is.
        what: String,
        /// The value found.
        value: f64,
        /// Human-readable expected range, e.g. "≥ 0".
        expected: String,
    },
    /// A sight line is outside the instrument's measuring range.
    #[error(
        "child {child}: slope distance {range_m:.3} m is outside the instrument's range \
         [{min_m} m, {max_m} m]"
    )]
    BeyondInstrumentRange {
        /// Child index (team order).
        child: usize,
        /// Slope distance of the sight line.
        range_m: f64,
        /// Instrument minimum range.
        min_m: f64,
        /// Instrument maximum range.
        max_m: f64,
    },
    /// Two points that must be distinct coincide (horizontally for angles).
    #[error("{what}: points coincide (separation {separation_m:e} m); expected distinct points")]
    CoincidentPoints {
        /// Which points.
        what: String,
        /// Their separation.
        separation_m: f64,
    },
    /// The child index is not part of the team.
    #[error("child index {child} is out of range: the team has {team} children")]
    UnknownChild {
        /// The index given.
        child: usize,
        /// Team size.
        team: usize,
    },
    /// A station clone that does not exist.
    #[error("station clone {clone} does not exist; the team state holds {clones} clone(s)")]
    UnknownClone {
        /// The index asked for.
        clone: usize,
        /// Clones held.
        clones: usize,
    },
    /// A child is used in a fix before it was ever placed.
    #[error("child {child} has not been placed yet; place it before the parent uses it")]
    ChildNotPlaced {
        /// Child index.
        child: usize,
    },
    /// The same child appears twice in one parent fix.
    #[error("child {child} appears more than once in one parent fix")]
    DuplicateChild {
        /// Child index.
        child: usize,
    },
    /// The geometry does not determine the unknowns (rank deficient or
    /// numerically singular).
    #[error("degenerate geometry: {what} (condition estimate {condition:e})")]
    DegenerateGeometry {
        /// What is degenerate.
        what: String,
        /// Condition estimate of the offending matrix.
        condition: f64,
    },
    /// The unknowns are determined, but the normal equations lose nearly
    /// every digit on one of them: its pivot is a vanishing fraction of its
    /// diagonal (a 1,000 km open traverse at 5″: σ of kilometres against
    /// readings of millimetres).
    #[error(
        "numerically singular normal equations: {what} has a pivot of {pivot:.1e} of its diagonal (condition estimate ≥ {condition:.1e}): the observations determine it, but its precision spans more orders of magnitude than double precision carries"
    )]
    NumericallySingular {
        /// The unknown whose pivot vanished.
        what: String,
        /// Its pivot relative to its diagonal entry.
        pivot: f64,
        /// A lower bound of the normal matrix's condition number (1/pivot).
        condition: f64,
    },
    /// A covariance matrix that must be positive (semi-)definite is not.
    #[error("{what} is not a valid covariance (not symmetric positive definite)")]
    NotPositiveDefinite {
        /// Which covariance.
        what: String,
    },
    /// The iteration diverged (the estimate left the finite numbers).
    #[error("{what} diverged after {iterations} iterations")]
    Diverged {
        /// Which estimation.
        what: String,
        /// Iterations done.
        iterations: usize,
    },
    /// A name that is not one of the known ones.
    #[error("unknown {what} '{name}': expected one of {expected}")]
    UnknownName {
        /// What kind of name.
        what: String,
        /// The name given.
        name: String,
        /// The names accepted.
        expected: String,
    },
    /// A scene file is malformed or describes impossible geometry.
    #[error("line {line}, column {column}: {message}")]
    SceneFile {
        /// 1-based line (0 when unknown).
        line: usize,
        /// 1-based column (0 when unknown).
        column: usize,
        /// What is wrong.
        message: String,
    },
}

/// Result alias of the `cps` crate.
pub type Result<T, E = CpsError> = std::result::Result<T, E>;

/// 1-based (line, column) of byte `offset` in `text`, counting columns in
/// characters; an offset inside a character or past the end is clamped.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut end = offset.min(text.len());
    while end > 0 && !text.is_char_boundary(end) {
        end -= 1;
    }
    let before = &text[..end];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// Error when `value` is not finite.
pub(crate) fn ensure_finite(what: impl FnOnce() -> String, value: f64) -> Result<f64> {
    if value.is_finite() { Ok(value) } else { Err(CpsError::NonFinite { what: what(), value }) }
}
