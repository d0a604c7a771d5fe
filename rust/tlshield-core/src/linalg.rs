//! The small dense vector arithmetic the shield's rows and the active-set solver share.

/// `a . b` over the shorter of the two.
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
