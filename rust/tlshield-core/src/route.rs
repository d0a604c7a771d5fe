//! Guidance that routes (beyond the paper): the target the CLF aims at, leading around the discs
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
//! The planner is a visibility graph, re-built each step from the discs' current centres (so
//! moving obstacles are re-read every step):
//! - each disc of radius `r` is inflated to `R = r (1 + clearance)` and circumscribed by a
//!   regular polygon of [`SIDES`] sides, whose vertices are the graph's nodes, with the two
//!   points along the tangents from the robot to the inflated circle, at least a lookahead
//!   ([`LOOKAHEAD`] radii) away (a node inside another inflated disc is dropped);
//! - two nodes are joined when the segment between them keeps out of every inflated disc (a
//!   polygon's own sides touch its disc and are allowed; a segment from the robot may cut
//!   [`ROBOT_SLACK`] into the clearance, never into a disc);
//! - the robot's position and the goal are nodes too, and A* (the straight distance to the goal
//!   as its heuristic) gives the shortest path;
//! - the aim is the point a lookahead along that path if the robot sees it, else the point
//!   along the tangent on the side the path wraps the disc it meets first, else the farthest
//!   point short of the lookahead in sight (the path's first node at the least);
//! - the target lies in the aim's direction, as far away as the path is long, so that
//!   `V = |p - target|^2` is the squared length of the way left: it asks the speed it would ask
//!   of a clear goal, and does not slow the robot at each corner.
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
//! - a goal inside an obstacle, or enclosed by overlapping ones (no path): the target is the
//!   goal, and the shield parks as before;
//! - it routes around discs only (balls over the CLF's two position dimensions, and unions of
//!   them); half-spaces, intersections and balls over other dimensions are not routed around
//!   (the barriers still hold them);
//! - it is a path of the robot's reference point, not of its body, and does not look at the
//!   dynamics: a robot that cannot follow a corner is still kept safe by the barriers, and may
//!   be slowed by them.
//!
//! Allocation-free per step once its buffers have grown to the problem's size.

use std::f64::consts::PI;

use crate::automaton::Reading;
use crate::cnf::Literal;
use crate::predicate::{Center, Predicate};

/// Sides of the polygon circumscribing each inflated disc.
pub const SIDES: usize = 8;
/// The unit vectors to the corners of the octagon, at multiples of 45 degrees.
const OCTAGON: [[f64; 2]; SIDES] = {
    const H: f64 = std::f64::consts::FRAC_1_SQRT_2;
    [
        [1.0, 0.0],
        [H, H],
        [0.0, 1.0],
        [-H, H],
        [-1.0, 0.0],
        [-H, -H],
        [0.0, -1.0],
        [H, -H],
    ]
};
/// The aim's distance along the path, in inflated radii of the disc the path meets first.
pub const LOOKAHEAD: f64 = 1.0;
/// How far into the clearance (a fraction of the inflated radius) a segment from the robot may
/// cut.
pub const ROBOT_SLACK: f64 = 0.05;
/// The default inflation of each disc, relative to its radius.
pub const DEFAULT_CLEARANCE: f64 = 0.2;

/// A disc to route around: a centre in the plane of the CLF's position and a radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disc {
    /// The centre.
    pub center: [f64; 2],
    /// The radius (> 0).
    pub radius: f64,
}

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
    /// Whether the safe set is the progress-preserving one (as the shield's).
    pub preserve_progress: bool,
}

impl Routing {
    /// The router's target ([`Router::target`]) from the state read by `reading` in FSA state
    /// `q` towards `goal` (over [`Routing::pos`]), around the discs of the user's barriers and
    /// of the safe set's avoided literals, as the shield plans it: `|p - target|` is the length
    /// of the way left. `router` and `safe` are scratch.
    pub fn target(
        &self,
        reading: &Reading<'_>,
        q: usize,
        goal: [f64; 2],
        router: &mut Router,
        safe: &mut Vec<(Literal, f64)>,
    ) -> [f64; 2] {
        if self.preserve_progress {
            reading.progress_safe_set(q, safe);
        } else {
            reading.safe_set(q, safe);
        }
        let s = reading.state();
        let predicates = reading.automaton().spec().predicates();
        let kept = safe
            .iter()
            .filter(|(lit, _)| !lit.positive)
            .map(|(lit, _)| &predicates[lit.atom]);
        router.load(&self.pos, s, self.avoid.iter().chain(kept));
        let p = [s[self.pos[0]], s[self.pos[1]]];
        router.target(p, goal, self.clearance)
    }
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
    match predicate {
        Predicate::Ball(b) if b.pos() == pos => {
            let center = match b.center() {
                Center::Fixed(c) => [c[0], c[1]],
                Center::Dims(d) => [s[d[0]], s[d[1]]],
            };
            // A body point keeps the ball's radius from the centre, so the reference point
            // is safe from that disc grown by the point's distance from it.
            found(Disc {
                center,
                radius: b.radius() + b.offset().map_or(0.0, |o| o.length()),
            });
        }
        Predicate::Union(parts) => {
            for part in parts {
                each_disc(part, pos, s, found);
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

/// The planner's buffers (see the module docs). One per shield workspace.
#[derive(Debug, Clone, Default)]
pub struct Router {
    discs: Vec<Disc>,
    /// Per disc, the inflated radius used this step.
    inflated: Vec<f64>,
    /// Graph nodes: 0 is the robot, 1 the goal, then polygon corners with their disc.
    nodes: Vec<([f64; 2], usize)>,
    dist: Vec<f64>,
    /// Per node, the straight distance to the goal (A*'s heuristic).
    rest: Vec<f64>,
    prev: Vec<usize>,
    done: Vec<bool>,
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// A point on the tangent from `p` to the circle at `c` of radius `r` on `side` (+1: passing the
/// circle counter-clockwise about `c`): the tangent point, or, from on or inside the circle, a
/// point a unit along the circle's tangent at `p`.
fn tangent(p: [f64; 2], c: [f64; 2], r: f64, side: f64) -> [f64; 2] {
    let rim = sub(p, c);
    let d = norm(rim);
    if d <= r || d == 0.0 {
        let d = d.max(f64::MIN_POSITIVE);
        return [p[0] - side * rim[1] / d, p[1] + side * rim[0] / d];
    }
    // The tangent point is at angle +-acos(r / d) from the direction c -> p.
    let (sin, cos) = (side * (r / d).acos()).sin_cos();
    let u = [rim[0] / d, rim[1] / d];
    [
        c[0] + r * (u[0] * cos - u[1] * sin),
        c[1] + r * (u[0] * sin + u[1] * cos),
    ]
}

/// The point on the tangent from `p` to the circle (`c`, `r`) on `side`, at least `lookahead`
/// from `p` (past the tangent point when that is nearer).
fn past_tangent(p: [f64; 2], c: [f64; 2], r: f64, side: f64, lookahead: f64) -> [f64; 2] {
    let u = sub(tangent(p, c, r, side), p);
    let len = norm(u).max(f64::MIN_POSITIVE);
    let to = len.max(lookahead);
    [p[0] + to * u[0] / len, p[1] + to * u[1] / len]
}

fn norm(a: [f64; 2]) -> f64 {
    a[0].hypot(a[1])
}

/// Whether the segment `a`-`b` passes strictly inside the disc at `c` of radius `r` (touching
/// it, as a polygon's side does, is allowed).
fn crosses(a: [f64; 2], b: [f64; 2], c: [f64; 2], r: f64) -> bool {
    let d = sub(b, a);
    let len2 = d[0] * d[0] + d[1] * d[1];
    let ac = sub(c, a);
    let t = if len2 > 0.0 {
        ((ac[0] * d[0] + ac[1] * d[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let closest = [a[0] + t * d[0], a[1] + t * d[1]];
    norm(sub(c, closest)) < r * (1.0 - 1e-9)
}

impl Router {
    /// Forgets the discs of the last step.
    pub fn clear(&mut self) {
        self.discs.clear();
    }

    /// Adds a disc to route around this step (one with a radius that is not finite and > 0 is
    /// ignored).
    pub fn push(&mut self, disc: Disc) {
        if disc.radius.is_finite() && disc.radius > 0.0 {
            self.discs.push(disc);
        }
    }

    /// The discs of this step.
    pub fn discs(&self) -> &[Disc] {
        &self.discs
    }

    /// Forgets the last step's discs and adds those of `avoided` (predicates whose outside the
    /// state is kept in) over `pos` at `s` ([`each_disc`]).
    pub(crate) fn load<'a>(
        &mut self,
        pos: &[usize],
        s: &[f64],
        avoided: impl Iterator<Item = &'a Predicate>,
    ) {
        self.clear();
        for predicate in avoided {
            each_disc(predicate, pos, s, &mut |disc| self.push(disc));
        }
    }

    fn visible(&self, a: [f64; 2], b: [f64; 2]) -> bool {
        !self
            .discs
            .iter()
            .zip(&self.inflated)
            .any(|(d, &r)| crosses(a, b, d.center, r))
    }

    /// [`Router::visible`] for a segment from the robot, which may cut [`ROBOT_SLACK`] into
    /// the clearance (never into a disc): a robot that has reached a corner, or stands a hair
    /// inside its polygon, still sees the next corner, instead of creeping onto the corner.
    fn visible_from_robot(&self, a: [f64; 2], b: [f64; 2]) -> bool {
        !self.discs.iter().zip(&self.inflated).any(|(d, &r)| {
            let cut = ((1.0 - ROBOT_SLACK) * r).max(d.radius).min(r);
            crosses(a, b, d.center, cut)
        })
    }

    /// The target for a robot at `p` heading for `goal`, around this step's discs inflated by
    /// `clearance` (relative to each radius, >= 0). See the module docs.
    pub fn target(&mut self, p: [f64; 2], goal: [f64; 2], clearance: f64) -> [f64; 2] {
        // A goal inside an obstacle cannot be reached: aim at it, the barriers hold the robot.
        if self
            .discs
            .iter()
            .any(|d| norm(sub(goal, d.center)) < d.radius)
        {
            return goal;
        }
        self.inflated.clear();
        for d in &self.discs {
            // Shrink a disc that holds the robot or the goal, so both stay outside it.
            let keep = norm(sub(p, d.center)).min(norm(sub(goal, d.center))) * (1.0 - 1e-6);
            self.inflated.push((d.radius * (1.0 + clearance)).min(keep));
        }
        if self.visible(p, goal) {
            return goal;
        }
        self.nodes.clear();
        self.nodes.push((p, usize::MAX));
        self.nodes.push((goal, usize::MAX));
        let corner = 1.0 / (PI / SIDES as f64).cos();
        for (i, d) in self.discs.iter().enumerate() {
            let r = self.inflated[i] * corner;
            // The two ways past the disc from the robot: along each tangent from it to the
            // inflated circle, at least a lookahead far (continuous in the robot's position,
            // so the shortest way does not jump as the robot moves).
            let lookahead = LOOKAHEAD * d.radius * (1.0 + clearance);
            let tangents = [1.0, -1.0]
                .map(|side| past_tangent(p, d.center, self.inflated[i], side, lookahead));
            let corners = OCTAGON.map(|[c, s]| [d.center[0] + r * c, d.center[1] + r * s]);
            for v in corners.into_iter().chain(tangents) {
                let covered = self
                    .discs
                    .iter()
                    .zip(&self.inflated)
                    .enumerate()
                    .any(|(j, (o, &ro))| j != i && norm(sub(v, o.center)) < ro);
                if !covered {
                    self.nodes.push((v, i));
                }
            }
        }
        // A* on the dense visibility graph from the robot (node 0) to the goal (node 1), with
        // the straight distance to the goal as the (consistent) heuristic, and an edge's
        // visibility tested only when it would improve a node.
        let n = self.nodes.len();
        self.rest.clear();
        self.rest
            .extend(self.nodes.iter().map(|&(v, _)| norm(sub(goal, v))));
        self.dist.clear();
        self.dist.resize(n, f64::INFINITY);
        self.prev.clear();
        self.prev.resize(n, usize::MAX);
        self.done.clear();
        self.done.resize(n, false);
        self.dist[0] = 0.0;
        loop {
            let mut u = usize::MAX;
            let mut best = f64::INFINITY;
            for (i, (&d, &done)) in self.dist.iter().zip(&self.done).enumerate() {
                if !done && d + self.rest[i] < best {
                    (u, best) = (i, d + self.rest[i]);
                }
            }
            if u == usize::MAX || u == 1 {
                break;
            }
            self.done[u] = true;
            let best = self.dist[u];
            let a = self.nodes[u].0;
            for v in 1..n {
                if self.done[v] {
                    continue;
                }
                let b = self.nodes[v].0;
                let through = best + norm(sub(b, a));
                if through >= self.dist[v] {
                    continue;
                }
                let seen = match u {
                    0 => self.visible_from_robot(a, b),
                    _ => self.visible(a, b),
                };
                if seen {
                    self.dist[v] = through;
                    self.prev[v] = u;
                }
            }
        }
        if !self.dist[1].is_finite() {
            // Enclosed: no way around what is known. Aim at the goal (the shield parks).
            return goal;
        }
        // The way to go: the direction to a point of the path the robot sees (see
        // `Router::aim`); the target is that far along it as the path is long, so that
        // `V = |p - target|^2` is the squared length of the way left (a CLF whose gradient
        // points along the path, and which asks the speed it would ask of a clear goal).
        let aim = self.aim(p, clearance);
        let u = sub(aim, p);
        let len = norm(u);
        if len <= 1e-12 {
            return aim;
        }
        let left = self.dist[1];
        [p[0] + left * u[0] / len, p[1] + left * u[1] / len]
    }

    /// A point of the last path found that the robot at `p` sees (see the module docs): the
    /// point a lookahead along the path, or, hidden behind the disc the path wraps around, the
    /// way along the tangent on its side; else the farthest point short of it in sight; the
    /// first node at the least, which the robot sees by construction.
    fn aim(&self, p: [f64; 2], clearance: f64) -> [f64; 2] {
        let mut first = 1;
        while self.prev[first] != 0 {
            first = self.prev[first];
        }
        let (corner_at, disc) = self.nodes[first];
        if disc == usize::MAX {
            return corner_at;
        }
        let lookahead = LOOKAHEAD * self.discs[disc].radius * (1.0 + clearance);
        let carrot = self.along_path(lookahead);
        if self.visible_from_robot(p, carrot) {
            return carrot;
        }
        // Hidden behind the disc the path wraps around (the robot on its rim): the way along
        // the tangent from the robot on the carrot's side, which it sees.
        let (c, r) = (self.discs[disc].center, self.inflated[disc]);
        let [a, b] = [1.0, -1.0].map(|side| past_tangent(p, c, r, side, lookahead));
        let toward = if norm(sub(a, carrot)) <= norm(sub(b, carrot)) {
            a
        } else {
            b
        };
        if self.visible_from_robot(p, toward) {
            return toward;
        }
        let mut along = 0.8 * lookahead;
        while along > self.dist[first] {
            let carrot = self.along_path(along);
            if self.visible_from_robot(p, carrot) {
                return carrot;
            }
            along *= 0.8;
        }
        corner_at
    }

    /// The point at length `along` on the last path found (robot to goal; the goal past its
    /// end).
    fn along_path(&self, along: f64) -> [f64; 2] {
        let mut node = 1;
        while self.prev[node] != 0 && self.dist[self.prev[node]] >= along {
            node = self.prev[node];
        }
        if self.dist[node] <= along {
            return self.nodes[node].0;
        }
        let before = self.prev[node];
        let (a, b) = (self.nodes[before].0, self.nodes[node].0);
        let t = (along - self.dist[before]) / (self.dist[node] - self.dist[before]);
        [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn router(discs: &[([f64; 2], f64)]) -> Router {
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
