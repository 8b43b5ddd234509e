//! The value checks every table shares: a number, a positive one, one
//! within bounds — each naming the field and the value on failure.

use toml::Spanned;
use toml::de::DeValue;

use crate::mission::reader::{At, Reader};

/// A raw TOML value with its span.
pub(super) type Raw<'i> = Spanned<DeValue<'i>>;

/// A number > 0.
pub(super) fn positive(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<f64> {
    r.number_in(v, f, 0.0, false, None).map(At::into_inner)
}

/// Any finite number.
pub(super) fn number(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<f64> {
    r.number(v, f).map(At::into_inner)
}

/// A number ≥ 0.
pub(super) fn non_negative(r: &mut Reader<'_>, v: &Raw<'_>, f: &str) -> Option<f64> {
    r.number_in(v, f, 0.0, true, None).map(At::into_inner)
}

/// A number in [min, max].
pub(super) fn within(min: f64, max: f64) -> impl Fn(&mut Reader<'_>, &Raw<'_>, &str) -> Option<f64> {
    move |r, v, f| r.number_in(v, f, min, true, Some(max)).map(At::into_inner)
}

/// A number in (0, max].
pub(super) fn positive_at_most(max: f64) -> impl Fn(&mut Reader<'_>, &Raw<'_>, &str) -> Option<f64> {
    move |r, v, f| r.number_in(v, f, 0.0, false, Some(max)).map(At::into_inner)
}
