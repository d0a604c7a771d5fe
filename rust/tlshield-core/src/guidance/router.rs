//! The router (beyond the paper): the target the CLF aims at, leading around the discs
//! the shield keeps the robot out of.
//!
//! A CLF aimed straight at a goal behind an obstacle makes the CLF-CBF QP park the robot in
//! front of it: where the barrier's gradient is parallel to the CLF's, the QP cancels the push
//! and the closed loop has an equilibrium on the barrier's rim (Reis, Aguiar and Silvestre 2021).
//! The router removes that equilibrium by construction: the CLF's target lies in the direction
//! of a point the robot can reach in a straight line without entering any known disc, on a
//! shortest path around them. Where the robot stands on a disc's rim, that line is tangent to
//! the disc (or points away from it), so the barrier never cancels it: the CLF's push always has
//! a component the barrier leaves free, and the robot slides around instead of stopping.
//!
//! The planner is a visibility graph over the discs' current centres (so moving obstacles are
//! re-read every step):
//! - each disc of radius `r` is inflated to `R = r (1 + clearance)` and circumscribed by a
//!   regular polygon of [`SIDES`](super::SIDES) sides, whose vertices are the graph's nodes, with the two
//!   points along the tangents from the robot to the inflated circle, at least a lookahead
//!   ([`LOOKAHEAD`](super::LOOKAHEAD) radii) away (a node inside another inflated disc is dropped): `inflate.rs`
//!   and `graph.rs`;
//! - two nodes are joined when the segment between them keeps out of every inflated disc (a
//!   polygon's own sides touch its disc and are allowed; a segment from the robot may cut
//!   [`ROBOT_SLACK`](super::ROBOT_SLACK) into the clearance, never into a disc);
//! - the robot's position and the goal are nodes too, and A* (the straight distance to the goal
//!   as its heuristic) gives the shortest path: `search.rs`;
//! - the aim is the point a lookahead along that path if the robot sees it, else the point
//!   along the tangent on the side the path wraps the disc it meets first, else the farthest
//!   point short of the lookahead in sight (the path's first node at the least): `aim.rs`;
//! - the target lies in the aim's direction, as far away as the path is long, so that
//!   `V = |p - target|^2` is the squared length of the way left: it asks the speed it would ask
//!   of a clear goal, and does not slow the robot at each corner.
//!
//! The graph is never built whole. The search looks only at the discs that meet the ellipse a
//! short enough path can use (foci the robot and the goal), tests an edge only when it would
//! improve a node, and a corner's cover only when the corner is first needed (`search.rs`).
//! The polygons' corners, what covers them and which segments between them are clear do not
//! depend on the robot: they are kept from step to step while the discs (and their inflated
//! radii) stay the same, and placed again when any disc moves, appears or goes. So are, while
//! the goal stays the same too, which polygon corners see the goal and the ways on to it from
//! the polygon corners of the ways found: they bound later searches (`search.rs`), and change
//! no target. The way is searched again every step, from the robot's new
//! position (its tangent points move with it), so the target is the one a planner built from
//! scratch would give. A step's work is bounded ([`WORK_BOUND`](super::WORK_BOUND)); where the
//! bound is hit the step keeps the way to the goal found so far, or aims at the goal itself.
//! Safety never depends on routing: the barriers are rows of the QP of their own, whatever the
//! CLF aims at, and a step whose routing is cut short is as safe as one without routing.
//!
//! Moving along a shortest path shortens it by the distance moved and any other path by at
//! most that, so the way chosen does not flip from step to step; ties are broken by the
//! nodes' order, deterministically.
//!
//! With a clear straight line to the goal the target is the goal itself, bit for bit: routing
//! changes nothing where nothing is in the way. A disc that holds the robot (a slip) or the goal
//! is shrunk to just exclude it for that step.
//!
//! What it cannot do, and does instead:
//! - a goal an obstacle covers whole, or enclosed by overlapping ones (no path): the target is
//!   the goal, and the shield parks as before (one an obstacle covers in part is aimed at at
//!   its free part, `free.rs`);
//! - it routes around discs only (balls over the CLF's two position dimensions, and unions of
//!   them), within walls: the half-planes the state is kept in (a half-space kept true, or
//!   kept false, over the position; `plane.rs`), whose far side holds no node. A convex
//!   polygon kept out of, and balls over other dimensions, are not routed around (the
//!   barriers still hold them);
//! - it is a path of the robot's reference point, not of its body, and does not look at the
//!   dynamics: a robot that cannot follow a corner is still kept safe by the barriers, and may
//!   be slowed by them.
//!
//! Allocation-free per step once its buffers have grown to the problem's size.

use std::collections::BinaryHeap;

use super::graph::{Corner, Cover, Edges, Near, Node};
use super::plane::{each_disc, each_wall, Disc, Wall};
use super::reach::{Routed, Scratch};
use super::search::{Onward, Open, Region};
use crate::automaton::Reading;
use crate::cnf::Literal;
use crate::predicate::Predicate;

/// What a shield routes around, and in which plane: enough to measure the way its CLF drives
/// without the shield (the progress reward's goal term, `Monitor::route_with`).
#[derive(Debug, Clone, PartialEq)]
pub struct Routing {
    /// The CLF's two position dimensions.
    pub pos: [usize; 2],
    /// The router's clearance (relative to each radius, >= 0).
    pub clearance: f64,
    /// The user's barriers that keep the state outside a predicate (routed when discs).
    pub avoid: Vec<Predicate>,
    /// The user's barriers that keep the state inside a predicate: not routed around, read
    /// only to tell a goal the robot may not be at ([`Router::reached`]'s complement).
    pub inside: Vec<Predicate>,
    /// Whether the safe set is the progress-preserving one (as the shield's).
    pub preserve_progress: bool,
}

impl Routing {
    /// The routed decision ([`Routed`]) at the state read by `reading` in FSA state `q` towards
    /// Eq. 5B1's `goal` (over [`Routing::pos`]), around the discs of the user's barriers and
    /// of the safe set's avoided literals, as the shield plans it: `|p - target|` is the length
    /// of the way left, towards a goal that can be reached where one can (`reach.rs`).
    /// `router` and the rest are scratch.
    pub fn target(
        &self,
        reading: &Reading<'_>,
        q: usize,
        goal: [f64; 2],
        router: &mut Router,
        (safe, scratch): (&mut Vec<(Literal, f64)>, &mut Scratch),
    ) -> Routed {
        self.safe_set(reading, q, safe);
        self.route(reading, q, goal, safe, (router, scratch))
    }

    /// The safe set this routing goes around at `(reading, q)` into `out`: the Eq. 5C1 one, or
    /// the progress-preserving one (as the shield's).
    pub(crate) fn safe_set(&self, reading: &Reading<'_>, q: usize, out: &mut Vec<(Literal, f64)>) {
        if self.preserve_progress {
            reading.progress_safe_set(q, out);
        } else {
            reading.safe_set(q, out);
        }
    }

    /// The router's target from state `s` towards `goal`, around the discs of the user's
    /// barriers and of the avoided literals of `safe` (atoms of `predicates`), and the goal it
    /// leads to: `goal`, or, when a disc covers it, the nearest point of its free part that
    /// `in_goal` (whether a point over [`Routing::pos`] lies in the goal's region) accepts.
    pub(crate) fn plan(
        &self,
        predicates: &[Predicate],
        safe: &[(Literal, f64)],
        s: &[f64],
        (goal, in_goal): ([f64; 2], &mut dyn FnMut([f64; 2]) -> bool),
        router: &mut Router,
    ) -> ([f64; 2], [f64; 2]) {
        let kept = safe
            .iter()
            .filter(|(lit, _)| !lit.positive)
            .map(|(lit, _)| &predicates[lit.atom]);
        router.load(&self.pos, s, self.avoid.iter().chain(kept));
        let kept = safe
            .iter()
            .map(|(lit, _)| (&predicates[lit.atom], lit.positive));
        let user = self.avoid.iter().map(|p| (p, false));
        let held = self.inside.iter().map(|p| (p, true));
        router.load_walls(&self.pos, s, kept.chain(user).chain(held));
        let p = [s[self.pos[0]], s[self.pos[1]]];
        let goal = match router.holds(goal) {
            true => router.free_part(p, goal, in_goal).unwrap_or(goal),
            false => goal,
        };
        (router.target(p, goal, self.clearance), goal)
    }
}

/// The planner's buffers (see the module docs). One per shield workspace.
#[derive(Debug, Clone, Default)]
pub struct Router {
    pub(super) discs: Vec<Disc>,
    /// Per disc: whether it stays put (its predicate reads only the position).
    pub(super) still: Vec<bool>,
    /// The half-planes the state is kept in this step (`plane.rs`): the corners beyond them are
    /// no nodes.
    pub(super) walls: Vec<Wall>,
    /// The walls the polygons' cover was tested against (kept with it).
    pub(super) placed_walls: Vec<Wall>,
    /// Per disc, the inflated radius used this step (`inflate.rs`).
    pub(super) inflated: Vec<f64>,
    /// The graph's ends this step: the robot's position and the goal.
    pub(super) robot: [f64; 2],
    pub(super) goal: [f64; 2],
    /// The graph's other nodes, [`CORNERS`](super::graph::CORNERS) per disc, each placed
    /// whether or not it is a node (`graph.rs`).
    pub(super) corners: Vec<Corner>,
    /// Per corner: whether it lies inside another inflated disc, as far as tested.
    pub(super) cover: Vec<Cover>,
    /// Per disc: whether the ways past it from the robot are placed this step.
    pub(super) tangents: Vec<bool>,
    /// The discs and inflated radii the corners were placed for: while this step's are the
    /// same, the polygons' corners and their cover are kept.
    pub(super) placed_discs: Vec<Disc>,
    pub(super) placed_inflated: Vec<f64>,
    /// The discs that meet the region searched (`search.rs`), in order.
    pub(super) near: Near,
    /// The disc that blocked the last segment this search found blocked (tested first; its
    /// place in [`Router::near`]).
    pub(super) blocker: Option<usize>,
    /// The nodes in the region searched, and the search's per-node buffers (`search.rs`).
    pub(super) region: Region,
    /// Per disc: how much longer than the straight line a way past it is at least (a region
    /// wider than that meets it, `search.rs`).
    pub(super) spans: Vec<f64>,
    /// The corners of the near discs not yet inside the region, each with its distances
    /// from the robot and the goal summed.
    pub(super) pending: Vec<(usize, f64)>,
    /// The search's open nodes.
    pub(super) heap: BinaryHeap<Open>,
    /// Tests of a point or a segment against a disc this step ([`WORK_BOUND`](super::WORK_BOUND)).
    pub(super) work: usize,
    /// Whether the last search was cut short by the work bound.
    pub(super) truncated: bool,
    /// Per node ([`Node::index`]) of the way found: the length of the way from the robot to
    /// it, and the node before it (written for the way's nodes only, `search.rs`).
    pub(super) dist: Vec<f64>,
    pub(super) prev: Vec<Option<Node>>,
    /// Which segments between two polygon corners are known to be clear of every inflated
    /// disc (`graph.rs`, [`Router::sees_between`]): kept, like the corners, while the discs
    /// stay put.
    pub(super) edges: Edges,
    /// The way found, goal first (`Router::measure_way`).
    pub(super) path: Vec<Node>,
    /// What the searches towards one goal learned that later searches towards it can prune
    /// with (`search.rs`): kept, like the corners, while the discs stay put and the goal is
    /// the same.
    pub(super) onward: Onward,
    /// Whether the last [`Router::target`] found the goal reachable: outside every disc, and
    /// joined to the robot by a way around them.
    reached: bool,
}

impl Router {
    /// Forgets the discs of the last step.
    pub fn clear(&mut self) {
        self.discs.clear();
        self.still.clear();
    }

    /// Adds a disc that stays put to route around this step (one with a radius that is not
    /// finite and > 0 is ignored).
    pub fn push(&mut self, disc: Disc) {
        self.push_moving(disc, false);
    }

    /// [`Router::push`] for a disc that may move (`moves`: its centre is read from the state):
    /// routed around alike, but a goal it covers is not aimed at at its rim (`free.rs`).
    pub fn push_moving(&mut self, disc: Disc, moves: bool) {
        if disc.radius.is_finite() && disc.radius > 0.0 {
            self.discs.push(disc);
            self.still.push(!moves);
        }
    }

    /// The discs of this step.
    pub fn discs(&self) -> &[Disc] {
        &self.discs
    }

    /// Whether the last step's search hit [`WORK_BOUND`](super::WORK_BOUND) (its target is the
    /// best found by then, or the goal).
    pub fn truncated(&self) -> bool {
        self.truncated
    }

    /// Forgets the last step's discs and adds those of `avoided` (predicates whose outside the
    /// state is kept in) over `pos` at `s` (`each_disc`).
    pub(crate) fn load<'a>(
        &mut self,
        pos: &[usize],
        s: &[f64],
        avoided: impl Iterator<Item = &'a Predicate>,
    ) {
        self.clear();
        for predicate in avoided {
            let moves = (0..s.len()).any(|d| !pos.contains(&d) && predicate.reads(d));
            each_disc(predicate, pos, s, &mut |disc| self.push_moving(disc, moves));
        }
    }

    /// Adds the walls of `kept` (predicates kept true, `true`, or false) over `pos` at `s`
    /// ([`each_wall`]): the corners on their far side are no nodes this step.
    pub(crate) fn load_walls<'a>(
        &mut self,
        pos: &[usize],
        s: &[f64],
        kept: impl Iterator<Item = (&'a Predicate, bool)>,
    ) {
        self.walls.clear();
        for predicate in kept {
            each_wall(predicate, pos, s, &mut |wall| self.walls.push(wall));
        }
    }

    /// The walls of this step.
    pub fn walls(&self) -> &[Wall] {
        &self.walls
    }

    /// The target for a robot at `p` heading for `goal`, around this step's discs inflated by
    /// `clearance` (relative to each radius, >= 0). See the module docs.
    pub fn target(&mut self, p: [f64; 2], goal: [f64; 2], clearance: f64) -> [f64; 2] {
        // A goal inside an obstacle cannot be reached: aim at it, the barriers hold the robot.
        self.truncated = false;
        self.reached = !self.holds(goal);
        if !self.reached {
            return goal;
        }
        self.inflate(p, goal, clearance);
        if self.visible(p, goal) {
            return goal;
        }
        let walls_moved = self.walls != self.placed_walls;
        if self.discs != self.placed_discs || self.inflated != self.placed_inflated || walls_moved {
            self.placed_discs.clone_from(&self.discs);
            self.placed_inflated.clone_from(&self.inflated);
            self.placed_walls.clone_from(&self.walls);
            self.place_polygons();
        }
        if !self.search(p, goal, clearance) {
            // Enclosed: no way around what is known, or none found within the work bound.
            // Aim at the goal (the shield parks, safe). Only a complete search tells that the
            // goal is unreachable.
            self.reached = self.truncated;
            return goal;
        }
        self.measure_way();
        self.place_target(p, clearance)
    }

    /// Whether the last [`Router::target`] left its goal reachable: false when the goal lies
    /// inside a disc, or when a complete search found no way around the discs to it (a search
    /// cut short by [`WORK_BOUND`](super::WORK_BOUND) tells nothing, and reports true); false
    /// before any target.
    pub fn reached(&self) -> bool {
        self.reached
    }
}

#[cfg(test)]
pub(super) mod tests {
    use std::f64::consts::PI;

    use super::super::graph::{crosses, norm, sub, ROBOT_SLACK, SIDES};
    use super::*;
    use proptest::prelude::*;
    use proptest::strategy::ValueTree;

    /// A router holding `discs` (centre, radius), each staying put.
    pub(in super::super) fn router(discs: &[([f64; 2], f64)]) -> Router {
        let mut r = Router::default();
        for &(center, radius) in discs {
            r.push(Disc { center, radius });
        }
        r
    }

    #[test]
    fn a_clear_line_aims_at_the_goal() {
        let mut r = router(&[([0.0, 3.0], 1.0)]);
        assert_eq!(r.target([-2.0, 0.0], [2.0, 0.0], 0.2), [2.0, 0.0]);
    }

    #[test]
    fn the_way_left_is_the_straight_line_or_a_way_around() {
        // The way left is |p - target| (the target lies as far as the path is long).
        let way = |r: &mut Router| norm(sub(r.target([-3.0, 0.0], [3.0, 0.0], 0.2), [-3.0, 0.0]));
        assert_eq!(way(&mut router(&[([0.0, 3.0], 1.0)])), 6.0);
        // Around a unit disc grown to 1.2: at least the tangents and the arc around the
        // circle (less the slack a segment from the robot may cut), at most around the
        // circumscribed octagon's circle.
        let mut r = router(&[([0.0, 0.0], 1.0)]);
        let around = |radius: f64| {
            let leg = (9.0 - radius * radius).sqrt();
            2.0 * leg + radius * (PI - 2.0 * (radius / 3.0).acos())
        };
        let way = way(&mut r);
        assert!(way > around((1.0 - ROBOT_SLACK) * 1.2) - 1e-9, "{way}");
        assert!(
            way < around(1.2 / (PI / SIDES as f64).cos()) + 1e-9,
            "{way}"
        );
    }

    #[test]
    fn a_disc_on_the_line_is_passed_on_one_side() {
        let mut r = router(&[([0.0, 0.0], 1.0)]);
        let t = r.target([-3.0, 0.0], [3.0, 0.0], 0.2);
        assert!(t[1].abs() > 0.1, "{t:?}");
        assert!(!crosses([-3.0, 0.0], t, [0.0, 0.0], 1.0));
    }

    #[test]
    fn an_enclosed_goal_is_aimed_at() {
        let ring: Vec<_> = (0..12)
            .map(|k| {
                let a = 2.0 * PI * k as f64 / 12.0;
                ([2.0 * a.cos(), 2.0 * a.sin()], 0.8)
            })
            .collect();
        let mut r = router(&ring);
        assert_eq!(r.target([5.0, 0.0], [0.0, 0.0], 0.2), [0.0, 0.0]);
    }

    proptest! {
        /// The target is in sight of the robot past every disc, and with a clear line it is the
        /// goal itself.
        #[test]
        fn the_target_is_in_sight(
            discs in proptest::collection::vec(((-4.0..4.0f64, -4.0..4.0f64), 0.2..1.2f64), 0..8),
            p in (-6.0..6.0f64, -6.0..6.0f64),
            goal in (-6.0..6.0f64, -6.0..6.0f64),
        ) {
            let discs: Vec<_> = discs.into_iter().map(|((x, y), r)| ([x, y], r)).collect();
            let (p, goal) = ([p.0, p.1], [goal.0, goal.1]);
            prop_assume!(discs.iter().all(|&(c, r)| norm(sub(p, c)) > r && norm(sub(goal, c)) > r));
            let mut r = router(&discs);
            let t = r.target(p, goal, 0.2);
            prop_assert!(t.iter().all(|v| v.is_finite()));
            let clear = discs.iter().all(|&(c, rad)| !crosses(p, goal, c, rad));
            if t != goal {
                // The target lies along a point of the path that the robot sees.
                let aim = r.aim(p, 0.2);
                for &(c, rad) in &discs {
                    prop_assert!(!crosses(p, aim, c, rad), "aim {:?} behind disc {:?}", aim, (c, rad));
                }
                let (u, v) = (sub(t, p), sub(aim, p));
                prop_assert!((u[0] * v[1] - u[1] * v[0]).abs() <= 1e-9 * norm(u) * norm(v));
                prop_assert!(u[0] * v[0] + u[1] * v[1] > 0.0);
                prop_assert!(norm(u) >= norm(sub(goal, p)) * (1.0 - 1e-9));
            } else if !clear {
                // Aiming at a goal behind a disc only when no path exists: check that the
                // inflated discs really close it off from the robot, by a grid flood fill.
                prop_assert!(!reachable(&discs, p, goal, 1.2 / (PI / SIDES as f64).cos() * 1.02));
            }
        }
    }

    /// Discs drawn from proptest's tuples.
    fn discs_of(discs: Vec<((f64, f64), f64)>) -> Vec<([f64; 2], f64)> {
        discs.into_iter().map(|((x, y), r)| ([x, y], r)).collect()
    }

    /// The target of the from-scratch planner (`reference.rs`), on a router of its own.
    fn reference(
        discs: &[([f64; 2], f64)],
        p: [f64; 2],
        goal: [f64; 2],
    ) -> ([f64; 2], Option<f64>) {
        router(discs).reference_target(p, goal, 0.2)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]
        /// Where the work bound is not hit, the bounded planner gives the from-scratch
        /// planner's target, bit for bit (same shortest way, ties broken the same way), with a
        /// router kept from step to step: its kept corners agree with freshly placed ones,
        /// and it places them again when the discs move.
        #[test]
        fn the_bounded_planner_agrees_with_the_reference(
            discs in proptest::collection::vec(((-4.0..4.0f64, -4.0..4.0f64), 0.2..1.2f64), 0..24),
            steps in proptest::collection::vec(
                ((-6.0..6.0f64, -6.0..6.0f64), (-6.0..6.0f64, -6.0..6.0f64)), 1..6),
            shift in (-0.5..0.5f64, -0.5..0.5f64),
        ) {
            let mut discs = discs_of(discs);
            let mut kept = router(&discs);
            for (k, (p, goal)) in steps.into_iter().enumerate() {
                if k == 3 {
                    // The discs move: the kept corners must be placed again.
                    for (c, _) in &mut discs {
                        *c = [c[0] + shift.0, c[1] + shift.1];
                    }
                    kept.clear();
                    for &(center, radius) in &discs {
                        kept.push(Disc { center, radius });
                    }
                }
                let (p, goal) = ([p.0, p.1], [goal.0, goal.1]);
                let t = kept.target(p, goal, 0.2);
                prop_assert!(!kept.truncated());
                let (want, way) = reference(&discs, p, goal);
                prop_assert_eq!(t, want, "step {} way {:?}", k, way);
                if let Some(way) = way {
                    prop_assert_eq!(kept.way_to(Node::Goal), way);
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        /// Searches towards one goal among the same discs bound their ways by what the earlier
        /// ones found (`search.rs`'s `Onward`): the targets are still the from-scratch
        /// planner's, bit for bit.
        #[test]
        fn what_earlier_searches_learned_leaves_the_targets_as_they_were(
            discs in proptest::collection::vec(((-4.0..4.0f64, -4.0..4.0f64), 0.2..1.2f64), 0..24),
            robots in proptest::collection::vec((-6.0..6.0f64, -6.0..6.0f64), 1..12),
            goal in (-6.0..6.0f64, -6.0..6.0f64),
        ) {
            let discs = discs_of(discs);
            let mut kept = router(&discs);
            let goal = [goal.0, goal.1];
            for (k, p) in robots.into_iter().enumerate() {
                let p = [p.0, p.1];
                let t = kept.target(p, goal, 0.2);
                prop_assert!(!kept.truncated());
                let (want, way) = reference(&discs, p, goal);
                prop_assert_eq!(t, want, "robot {} way {:?}", k, way);
                if let Some(way) = way {
                    prop_assert_eq!(kept.way_to(Node::Goal), way);
                }
            }
        }
    }

    #[test]
    fn independent_states_towards_one_goal_give_the_reference_targets() {
        // The routing bench's independent states among 64 discs: later searches are bounded by
        // the ways earlier ones found, and their targets stay the from-scratch planner's.
        let discs = field(64, 5);
        let mut r = router(&discs);
        let side = 64f64.sqrt() * 1.2;
        let goal = [side + 1.0, 0.3 * side];
        let mut routed = 0;
        for k in 0..60 {
            let y = (k as f64 * 0.618_034).fract() * 2.0 - 1.0;
            let p = [-side - 1.0 + 0.02 * k as f64, y * side];
            let t = r.target(p, goal, 0.2);
            routed += usize::from(t != goal);
            assert_eq!(
                t,
                router(&discs).reference_target(p, goal, 0.2).0,
                "state {k}"
            );
        }
        assert!(routed > 30, "{routed}");
        assert!(r.onward.learned() > 0);
    }

    #[test]
    fn the_same_discs_keep_their_corners_and_a_moved_one_is_placed_again() {
        let mut r = router(&[([0.0, 0.0], 1.0), ([0.0, 2.5], 1.0)]);
        r.target([-3.0, 0.0], [3.0, 0.0], 0.2);
        let corners = r.corners.as_ptr();
        let first = r.corners[0].at;
        r.target([-2.9, 0.1], [3.0, 0.0], 0.2);
        assert_eq!((r.corners.as_ptr(), r.corners[0].at), (corners, first));
        r.clear();
        r.push(Disc {
            center: [0.5, 0.0],
            radius: 1.0,
        });
        r.push(Disc {
            center: [0.0, 2.5],
            radius: 1.0,
        });
        let t = r.target([-2.9, 0.1], [3.0, 0.0], 0.2);
        assert_eq!(r.corners[0].at[0], first[0] + 0.5);
        assert_eq!(
            t,
            reference(
                &[([0.5, 0.0], 1.0), ([0.0, 2.5], 1.0)],
                [-2.9, 0.1],
                [3.0, 0.0]
            )
            .0
        );
    }

    /// `n` discs in the unit-spaced field the routing bench draws (centres in a box between
    /// the robot and the goal, no two overlapping), from a fixed seed.
    fn field(n: usize, seed: u64) -> Vec<([f64; 2], f64)> {
        let mut runner = proptest::test_runner::TestRunner::new_with_rng(
            ProptestConfig::default(),
            proptest::test_runner::TestRng::from_seed(
                proptest::test_runner::RngAlgorithm::ChaCha,
                &[seed as u8; 32],
            ),
        );
        let side = (n as f64).sqrt().max(1.0) * 1.2;
        let draw = ((-side..side, -side..side), 0.2..0.5f64);
        let mut discs = Vec::new();
        while discs.len() < n {
            let ((x, y), r) = draw.new_tree(&mut runner).unwrap().current();
            let c = [x, y];
            if discs
                .iter()
                .all(|&(o, ro): &([f64; 2], f64)| norm(sub(c, o)) > r + ro)
            {
                discs.push((c, r));
            }
        }
        discs
    }

    #[test]
    fn no_reallocation_after_warmup() {
        // Buffers grow on the first pass over these states, and are reused on the second.
        let discs = field(48, 7);
        let mut r = router(&discs);
        let side = 48f64.sqrt() * 1.2;
        let states: Vec<_> = (0..200)
            .map(|k| {
                let y = (k as f64 * 0.618_034).fract() * 2.0 - 1.0;
                ([-side - 1.0, y * side], [side + 1.0, -y * side])
            })
            .collect();
        let pointers = |r: &Router| {
            (
                [r.discs.as_ptr() as usize, r.inflated.as_ptr() as usize],
                [r.corners.as_ptr() as usize, r.cover.as_ptr() as usize],
                [r.tangents.as_ptr() as usize, r.near.x.as_ptr() as usize],
                [r.region.node.as_ptr() as usize, r.heap.capacity()],
                [
                    r.region.x.as_ptr() as usize,
                    r.region.through.as_ptr() as usize,
                ],
                [
                    r.region.rest.as_ptr() as usize,
                    r.region.open.as_ptr() as usize,
                ],
                [r.path.as_ptr() as usize, r.path.capacity()],
                [
                    r.dist.as_ptr() as usize,
                    r.region.prev.as_ptr() as usize,
                    r.spans.as_ptr() as usize,
                    r.pending.as_ptr() as usize,
                ],
                [
                    r.prev.as_ptr() as usize,
                    r.region.dist.as_ptr() as usize,
                    r.region.flags.as_ptr() as usize,
                    r.region.settled.as_ptr() as usize,
                ],
                [
                    r.placed_discs.as_ptr() as usize,
                    r.placed_inflated.as_ptr() as usize,
                ],
                [
                    r.edges.known.as_ptr() as usize,
                    r.edges.set.as_ptr() as usize,
                ],
            )
        };
        let mut routed = 0;
        for &(p, goal) in &states {
            routed += usize::from(r.target(p, goal, 0.2) != goal);
        }
        assert!(routed > 100, "{routed}");
        let before = pointers(&r);
        for &(p, goal) in &states {
            r.target(p, goal, 0.2);
            assert_eq!(pointers(&r), before);
        }
    }

    #[test]
    fn a_search_past_the_work_bound_keeps_what_it_found_or_aims_at_the_goal() {
        // A dense field of many discs between the robot and a goal far behind them.
        let discs = field(1500, 3);
        let mut r = router(&discs);
        let (p, goal) = ([-60.0, 0.3], [60.0, -0.2]);
        let t = r.target(p, goal, 0.2);
        assert!(r.truncated());
        assert!(t.iter().all(|v| v.is_finite()));
        if t != goal {
            assert!(r.visible_from_robot(p, r.aim(p, 0.2)));
        }
    }

    #[test]
    fn the_work_bound_is_not_hit_among_128_discs() {
        // The routing bench's largest field: every step searches to the end.
        let discs = field(128, 11);
        let mut r = router(&discs);
        let side = 128f64.sqrt() * 1.2;
        let (mut routed, mut cut) = (0, 0);
        for k in 0..100 {
            let y = (k as f64 * 0.618_034).fract() * 2.0 - 1.0;
            let (p, goal) = ([-side - 1.0, y * side], [side + 1.0, -y * side * 0.5]);
            routed += usize::from(r.target(p, goal, 0.2) != goal);
            cut += usize::from(r.truncated());
        }
        assert!(routed > 50, "{routed}");
        assert_eq!(cut, 0);
    }

    /// A brute-force reference: flood fill on a fine grid of the plane outside the discs
    /// (inflated by `inflate`), from `p` to `goal`.
    fn reachable(discs: &[([f64; 2], f64)], p: [f64; 2], goal: [f64; 2], inflate: f64) -> bool {
        let (lo, step, cells) = (-8.0, 0.05, 320usize);
        let free = |x: f64, y: f64| {
            discs
                .iter()
                .all(|&(c, r)| norm(sub([x, y], c)) >= r * inflate * 0.98)
        };
        let index = |v: f64| (((v - lo) / step).round() as usize).min(cells - 1);
        let mut seen = vec![false; cells * cells];
        let mut stack = vec![(index(p[0]), index(p[1]))];
        while let Some((i, j)) = stack.pop() {
            if seen[i * cells + j] {
                continue;
            }
            seen[i * cells + j] = true;
            if (i, j) == (index(goal[0]), index(goal[1])) {
                return true;
            }
            for (di, dj) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                let (ni, nj) = (i as i64 + di, j as i64 + dj);
                if ni < 0 || nj < 0 || ni >= cells as i64 || nj >= cells as i64 {
                    continue;
                }
                let (ni, nj) = (ni as usize, nj as usize);
                if !seen[ni * cells + nj] && free(lo + ni as f64 * step, lo + nj as f64 * step) {
                    stack.push((ni, nj));
                }
            }
        }
        false
    }
}
