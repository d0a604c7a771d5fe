//! What the router sees of the predicates the shield keeps the state out of: discs in the plane
//! of the CLF's two position dimensions, read through the one reading of a ball as geometry
//! ([`Round`], shared with the goal's regions), and walls: the half-planes it keeps the state
//! in.

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

/// A wall: the half-plane `a . p + c >= 0` of the CLF's position the state is kept in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    /// The inward normal (not zero).
    pub a: [f64; 2],
    /// The offset at this state (a half-space's other dimensions read at `s`).
    pub c: f64,
}

impl Wall {
    /// Whether `p` lies on the kept side, by more than rounding.
    pub(super) fn keeps(&self, p: [f64; 2]) -> bool {
        self.a[0] * p[0] + self.a[1] * p[1] + self.c > 0.0
    }
}

/// The walls a predicate kept true (`inside`) or false gives, each to `found`: a half-space
/// kept true is the half-plane of the position it reads there (its other dimensions read at
/// `s`); one kept false is the other side; an intersection kept true, or a union kept false,
/// gives each part's. Anything else (a disc, a convex polygon kept out of) is no wall. Kept
/// regions made of walls are convex, so a segment between two points on their kept side stays
/// there: the planner only drops the corners on the far side of a wall.
pub(crate) fn each_wall(
    (predicate, inside): (&Predicate, bool),
    pos: &[usize],
    s: &[f64],
    found: &mut impl FnMut(Wall),
) {
    match predicate {
        Predicate::Halfspace(h) => {
            let (w, sign) = (h.w(), if inside { 1.0 } else { -1.0 });
            let a = [sign * w[pos[0]], sign * w[pos[1]]];
            if a == [0.0, 0.0] {
                return;
            }
            let rest = (0..w.len().min(s.len()))
                .filter(|d| !pos.contains(d))
                .map(|d| w[d] * s[d])
                .sum::<f64>();
            found(Wall {
                a,
                c: sign * (h.b() + rest),
            });
        }
        Predicate::Intersection(parts) if inside => {
            for part in parts {
                each_wall((part, true), pos, s, found);
            }
        }
        Predicate::Union(parts) if !inside => {
            for part in parts {
                each_wall((part, false), pos, s, found);
            }
        }
        _ => {}
    }
}

/// Whether the router goes around the outside of `predicate` (see [`each_disc`]).
pub(crate) fn is_disc(predicate: &Predicate, pos: &[usize], s: &[f64]) -> bool {
    let mut any = false;
    each_disc(predicate, pos, s, &mut |_| any = true);
    any
}
