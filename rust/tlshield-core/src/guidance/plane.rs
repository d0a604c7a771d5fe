//! What the router sees of the predicates the shield keeps the state out of: discs in the plane
//! of the CLF's two position dimensions, read through the one reading of a ball as geometry
//! ([`Round`], shared with the goal's regions).

use crate::predicate::Predicate;
use crate::region::Round;

/// A disc to route around: a centre in the plane of the CLF's position and a radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disc {
    /// The centre.
    pub center: [f64; 2],
    /// The radius (> 0).
    pub radius: f64,
}

/// The discs whose outside `predicate` asks for, as the router sees them, each given to
/// `found`: a ball over `pos` (centre fixed or read from `s`), or each such ball of a union;
/// anything else is not routed. The one rule for what the router goes around.
pub(crate) fn each_disc(
    predicate: &Predicate,
    pos: &[usize],
    s: &[f64],
    found: &mut impl FnMut(Disc),
) {
    if let Some(round) = Round::over(predicate, pos) {
        // A body point keeps the ball's radius from the centre, so the reference point
        // is safe from that disc grown by the point's distance from it.
        found(Disc {
            center: [round.centre_at(0, s), round.centre_at(1, s)],
            radius: round.radius() + round.body_reach().unwrap_or(0.0),
        });
    } else if let Predicate::Union(parts) = predicate {
        for part in parts {
            each_disc(part, pos, s, found);
        }
    }
}

/// Whether the router goes around the outside of `predicate` (see [`each_disc`]).
pub(crate) fn is_disc(predicate: &Predicate, pos: &[usize], s: &[f64]) -> bool {
    let mut any = false;
    each_disc(predicate, pos, s, &mut |_| any = true);
    any
}
