//! Guidance that routes (beyond the paper): the target the CLF aims at, leading around the discs
//! the shield keeps the robot out of.
//!
//! A CLF aimed straight at a goal behind an obstacle makes the CLF-CBF QP park the robot in
//! front of it: where the barrier's gradient is parallel to the CLF's, the QP cancels the push
//! and the closed loop has an equilibrium on the barrier's rim (Reis, Aguiar and Silvestre 2021).
//! The router removes that equilibrium by construction: the CLF's target is a point the robot
//! can reach in a straight line without entering any known disc, on a shortest path around
//! them. Where the robot stands on a disc's rim, that line is tangent to the disc (or points
//! away from it), so the barrier never cancels it: the CLF's push always has a component the
//! barrier leaves free, and the robot slides around instead of stopping.
//!
//! The planner is a visibility graph, re-built each step from the discs' current centres (so
//! moving obstacles are re-read every step):
//! - each disc of radius `r` is inflated to `R = r (1 + clearance)` and circumscribed by a
//!   regular polygon of [`SIDES`] sides, whose vertices are the graph's nodes (a vertex inside
//!   another inflated disc is dropped);
//! - two nodes are joined when the segment between them keeps out of every inflated disc (a
//!   polygon's own sides touch its disc and are allowed);
//! - the robot's position and the goal are nodes too, and Dijkstra gives the shortest path;
//! - the target is the first corner of that path, or, once the robot is closer than a
//!   lookahead ([`LOOKAHEAD`] of the corner's disc radius) to it, the point that far along the
//!   path (a carrot), so that the robot does not slow down at each corner.
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

/// Sides of the polygon circumscribing each inflated disc.
pub const SIDES: usize = 8;
/// The carrot's distance along the path, in radii of the disc whose corner comes first.
pub const LOOKAHEAD: f64 = 1.0;
/// How far into the clearance (a fraction of the inflated radius) a segment from the robot may
/// cut.
pub const ROBOT_SLACK: f64 = 0.05;
/// The extra length, relative to the straight distance to the goal, charged to a path whose
/// first leg passes right of that line: ties go left, and a way right must be clearly shorter.
pub const SIDE_BIAS: f64 = 0.1;
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

/// The planner's buffers (see the module docs). One per shield workspace.
#[derive(Debug, Clone, Default)]
pub struct Router {
    discs: Vec<Disc>,
    /// Per disc, the inflated radius used this step.
    inflated: Vec<f64>,
    /// Graph nodes: 0 is the robot, 1 the goal, then polygon corners with their disc.
    nodes: Vec<([f64; 2], usize)>,
    dist: Vec<f64>,
    prev: Vec<usize>,
    done: Vec<bool>,
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
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
            let rim = sub(p, d.center);
            let near = norm(rim);
            // A robot within the clearance of a disc stands on its (shrunk) rim, where only the
            // tangent leaves it without entering: two nodes along the tangent, a lookahead away.
            let tangents = (near < d.radius * (1.0 + clearance) && near > 0.0).then(|| {
                let step = LOOKAHEAD * d.radius * (1.0 + clearance) / near;
                [
                    [p[0] - rim[1] * step, p[1] + rim[0] * step],
                    [p[0] + rim[1] * step, p[1] - rim[0] * step],
                ]
            });
            let corners = (0..SIDES).map(|k| {
                let angle = 2.0 * PI * k as f64 / SIDES as f64;
                [d.center[0] + r * angle.cos(), d.center[1] + r * angle.sin()]
            });
            for v in corners.chain(tangents.into_iter().flatten()) {
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
        // Dijkstra on the dense visibility graph from the robot (node 0) to the goal (node 1).
        // Passing on the right costs a little more, so that the side taken does not flip from
        // step to step where both ways are about as long (a disc straight ahead).
        let side = SIDE_BIAS * norm(sub(goal, p));
        let n = self.nodes.len();
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
                if !done && d < best {
                    (u, best) = (i, d);
                }
            }
            if u == usize::MAX || u == 1 {
                break;
            }
            self.done[u] = true;
            let a = self.nodes[u].0;
            for v in 1..n {
                if self.done[v] {
                    continue;
                }
                let b = self.nodes[v].0;
                let mut through = best + norm(sub(b, a));
                if u == 0 && cross(sub(goal, p), sub(b, p)) < 0.0 {
                    through += side;
                }
                let seen = match u {
                    0 => self.visible_from_robot(a, b),
                    _ => self.visible(a, b),
                };
                if through < self.dist[v] && seen {
                    self.dist[v] = through;
                    self.prev[v] = u;
                }
            }
        }
        if !self.dist[1].is_finite() {
            // Enclosed: no way around what is known. Aim at the goal (the shield parks).
            return goal;
        }
        // The graph decides the way: around which disc first, and turning which way. The target
        // is then exact: along the tangent from the robot to that disc's inflated circle on that
        // side, at least a lookahead away (on the rim, the tangent at the robot).
        let mut first = 1;
        while self.prev[first] != 0 {
            first = self.prev[first];
        }
        let (corner_at, disc) = self.nodes[first];
        if disc == usize::MAX {
            return goal;
        }
        let (c, r) = (self.discs[disc].center, self.inflated[disc]);
        let rim = sub(p, c);
        let d = norm(rim);
        let lookahead = LOOKAHEAD * self.discs[disc].radius * (1.0 + clearance);
        // Which way round: towards the first node of the path a little way off (a corner the
        // robot is passing may lie just behind it).
        let mut ahead = corner_at;
        let mut node = 1;
        while node != 0 {
            let v = self.nodes[node].0;
            if norm(sub(v, p)) >= 0.5 * lookahead {
                ahead = v;
            }
            node = self.prev[node];
        }
        let turn = cross(rim, sub(ahead, p));
        let direction = if d <= r || d == 0.0 {
            let sign = if turn >= 0.0 { 1.0 } else { -1.0 };
            [
                -rim[1] * sign / d.max(f64::MIN_POSITIVE),
                rim[0] * sign / d.max(f64::MIN_POSITIVE),
            ]
        } else {
            let beta = (r / d).acos();
            let (u, (sin, cos)) = ([rim[0] / d, rim[1] / d], beta.sin_cos());
            let touch = |sin: f64| {
                let w = [u[0] * cos - u[1] * sin, u[0] * sin + u[1] * cos];
                [c[0] + r * w[0], c[1] + r * w[1]]
            };
            let (a, b) = (touch(sin), touch(-sin));
            let t = if cross(rim, sub(a, p)) * turn >= 0.0 {
                a
            } else {
                b
            };
            let to = sub(t, p);
            let len = norm(to).max(f64::MIN_POSITIVE);
            if len > lookahead {
                return self.in_sight_or(p, t, corner_at);
            }
            [to[0] / len, to[1] / len]
        };
        let target = [
            p[0] + lookahead * direction[0],
            p[1] + lookahead * direction[1],
        ];
        self.in_sight_or(p, target, corner_at)
    }

    /// `target` if the robot sees it, else `corner` (the path's first corner, which it sees).
    fn in_sight_or(&self, p: [f64; 2], target: [f64; 2], corner: [f64; 2]) -> [f64; 2] {
        if self.visible_from_robot(p, target) {
            target
        } else {
            corner
        }
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
    fn a_disc_on_the_line_is_passed_on_one_side() {
        let mut r = router(&[([0.0, 0.0], 1.0)]);
        let t = r.target([-3.0, 0.0], [3.0, 0.0], 0.2);
        assert!(t[1].abs() > 0.5, "{t:?}");
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
                for &(c, rad) in &discs {
                    prop_assert!(!crosses(p, t, c, rad), "target {:?} behind disc {:?}", t, (c, rad));
                }
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
