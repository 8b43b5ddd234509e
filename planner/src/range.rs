//! The part of the total station's range a plan may use.

use std::ops::RangeInclusive;

use cps::Instrument;

/// How far inside the total station's range a planned sight line keeps,
/// metres. A robot's drive errs by centimetres (the simulator's default:
/// 0.5 % of the move plus 5 mm/√m), so a prism planned on a limit lands
/// outside it about half of the time.
pub const RANGE_MARGIN_M: f64 = 0.05;

/// The slope distances a planned sight line may have: the instrument's
/// range less [`RANGE_MARGIN_M`] at either end.
pub fn usable(instrument: &Instrument) -> RangeInclusive<f64> {
    instrument.min_range_m + RANGE_MARGIN_M..=instrument.max_range_m - RANGE_MARGIN_M
}
