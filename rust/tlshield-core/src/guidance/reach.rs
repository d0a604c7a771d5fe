//! Goals the guidance can reach (beyond the paper): one routed step's decision, the target the
//! CLF aims at and whether its goal can be reached, and Eq. 5B1's choice restricted to the
//! goals that can.
//!
//! Eq. 5B1 picks the most robust way an edge towards acceptance can hold, whether or not the
//! robot can get there. Where the router tells that the goal cannot be reached (a disc covers
//! it whole, it lies where a kept literal or an `Inside` barrier does not let the robot be, or
//! no way around the discs leads to it), the choice passes that alternative over and takes the
//! next best whose goal can be reached: the paper's agent learned to do this in its Fig.
//! 6.2.5d; here the guidance does it. Where none can be reached, the goal stays Eq. 5B1's and
//! the step says so. The automaton's ranks are not changed: they order states, and the choice
//! they serve is the one restricted here, per state.

use super::router::{Router, Routing};
use crate::automaton::Reading;
use crate::cnf::Literal;
use crate::predicate::Predicate;

/// One routed step's decision: the CLF's target, the goal it leads to (Eq. 5B1's, its free
/// part, or another edge's goal that can be reached) and whether that goal cannot be reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Routed {
    /// The point the CLF aims at (`|p - target|` is the way left).
    pub target: [f64; 2],
    /// The goal the way leads to, over the routing's plane.
    pub goal: [f64; 2],
    /// Whether the goal cannot be reached from the state (see the module docs).
    pub unreachable: bool,
}

/// Whether a point of the plane lies in a goal's region (with a scratch state).
type InGoal<'f> = &'f mut dyn FnMut([f64; 2], &mut Vec<f64>) -> bool;

/// Scratch of `Routing::route`: states with the position moved, and a goal buffer.
#[derive(Debug, Clone, Default)]
pub struct Scratch {
    probe: Vec<f64>,
    goal: Vec<f64>,
}

impl Routing {
    /// The routed decision at `(reading, q)` for Eq. 5B1's `goal` (over [`Routing::pos`]),
    /// around the discs of the user's barriers and of `safe`'s avoided literals: that goal's
    /// way when it can be reached, else the way to the most robust other goal alternative that
    /// can ([`Reading::goal_choice_where`]), else that goal's way, reported unreachable.
    pub(crate) fn route(
        &self,
        reading: &Reading<'_>,
        q: usize,
        goal: [f64; 2],
        safe: &[(Literal, f64)],
        (router, scratch): (&mut Router, &mut Scratch),
    ) -> Routed {
        let Scratch {
            probe,
            goal: buffer,
        } = scratch;
        let mut in_first =
            |point, probe: &mut Vec<f64>| reading.goal_region_holds(q, &self.pos, point, probe);
        let first = self.route_to(reading, goal, safe, router, (probe, &mut in_first));
        if !first.unreachable {
            return first;
        }
        let (mut found, mut tried) = (None, false);
        reading.goal_choice_where(q, buffer, &mut |alt, point| {
            if alt.dims != self.pos || point == goal {
                return false;
            }
            tried = true;
            let s = reading.state();
            let mut in_alt = |x, probe: &mut Vec<f64>| alt.holds_at(s, &self.pos, x, probe);
            let point = [point[0], point[1]];
            let routed = self.route_to(reading, point, safe, router, (probe, &mut in_alt));
            found = (!routed.unreachable).then_some(routed);
            found.is_some()
        });
        // The router keeps the last way planned: that of the goal taken (planned again only
        // where another goal was tried since).
        match (found, tried) {
            (Some(routed), _) => routed,
            (None, false) => first,
            (None, true) => self.route_to(reading, goal, safe, router, (probe, &mut in_first)),
        }
    }

    /// [`Routing::plan`] towards `goal` (its free part where a disc covers it, a point of the
    /// goal's region as `in_goal` reads it), and whether it can be reached.
    fn route_to(
        &self,
        reading: &Reading<'_>,
        goal: [f64; 2],
        safe: &[(Literal, f64)],
        router: &mut Router,
        (probe, in_goal): (&mut Vec<f64>, InGoal<'_>),
    ) -> Routed {
        let predicates = reading.automaton().spec().predicates();
        let s = reading.state();
        let mut in_goal = |point| in_goal(point, probe);
        let (target, goal) = self.plan(predicates, safe, s, (goal, &mut in_goal), router);
        let unreachable = !router.reached() || {
            let kept = safe
                .iter()
                .map(|(lit, _)| (&predicates[lit.atom], lit.positive));
            let user = self.avoid.iter().map(|p| (p, false));
            let held = self.inside.iter().map(|p| (p, true));
            excluded(probe, &self.pos, s, goal, kept.chain(user).chain(held))
        };
        Routed {
            target,
            goal,
            unreachable,
        }
    }
}

/// Whether `goal` (over `pos`) lies where one of `constraints` does not let the state be: a
/// predicate kept true (`true`) that is violated there, or kept false (`false`) that holds
/// there, read at `s` with the position moved to the goal (into `probe`). Only predicates that
/// read the position can tell.
fn excluded<'p>(
    probe: &mut Vec<f64>,
    pos: &[usize; 2],
    s: &[f64],
    goal: [f64; 2],
    constraints: impl Iterator<Item = (&'p Predicate, bool)>,
) -> bool {
    probe.clear();
    probe.extend_from_slice(s);
    probe[pos[0]] = goal[0];
    probe[pos[1]] = goal[1];
    constraints
        .filter(|(p, _)| p.reads(pos[0]) || p.reads(pos[1]))
        .any(|(p, kept_true)| {
            let rho = p.value(probe);
            if kept_true {
                rho < 0.0
            } else {
                rho > 0.0
            }
        })
}
