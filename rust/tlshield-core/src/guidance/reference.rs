//! The planner as it was before its search was bounded (test only): the whole visibility graph
//! built every step and searched by A* over every node and every disc, kept as the reference
//! the bounded planner must agree with where its work bound is not hit.

use std::f64::consts::PI;

use super::aim::lookahead;
use super::graph::{norm, past_tangent, sub, Corner, Node, OCTAGON, SIDES};
use super::router::Router;

impl Router {
    /// The target the from-scratch planner gives (as [`Router::target`] did before the work
    /// bound), and the length of its shortest way (`None` where it aims at the goal).
    pub(super) fn reference_target(
        &mut self,
        p: [f64; 2],
        goal: [f64; 2],
        clearance: f64,
    ) -> ([f64; 2], Option<f64>) {
        if self.holds(goal) {
            return (goal, None);
        }
        self.inflate(p, goal, clearance);
        if self.visible(p, goal) {
            return (goal, None);
        }
        self.reference_graph(p, goal, clearance);
        if !self.reference_search() {
            return (goal, None);
        }
        (
            self.place_target(p, clearance),
            Some(self.way_to(Node::Goal)),
        )
    }

    /// Every corner of every disc, those inside another inflated disc dropped (numbered in
    /// order, without gaps).
    fn reference_graph(&mut self, p: [f64; 2], goal: [f64; 2], clearance: f64) {
        self.robot = p;
        self.goal = goal;
        self.corners.clear();
        let corner = 1.0 / (PI / SIDES as f64).cos();
        for (i, d) in self.discs.iter().enumerate() {
            let r = self.inflated[i] * corner;
            let lookahead = lookahead(d.radius, clearance);
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
                    self.corners.push(Corner { at: v, disc: i });
                }
            }
        }
    }

    /// A* over every node, each edge tested against every disc when it would improve a node.
    fn reference_search(&mut self) -> bool {
        let n = 2 + self.corners.len();
        let (robot, goal) = (self.robot, self.goal);
        let mut rest = vec![norm(sub(goal, robot)), 0.0];
        rest.extend(self.corners.iter().map(|c| norm(sub(goal, c.at))));
        self.dist.clear();
        self.dist.resize(n, f64::INFINITY);
        self.prev.clear();
        self.prev.resize(n, None);
        let mut done = vec![false; n];
        self.dist[0] = 0.0;
        loop {
            let mut u = None;
            let mut best = f64::INFINITY;
            for i in 0..n {
                if !done[i] && self.dist[i] + rest[i] < best {
                    (u, best) = (Some(i), self.dist[i] + rest[i]);
                }
            }
            let Some(u) = u.map(Node::at) else { break };
            if u == Node::Goal {
                break;
            }
            done[u.index()] = true;
            let base = self.dist[u.index()];
            let a = self.point(u);
            for (i, &settled) in done.iter().enumerate().skip(1) {
                let b = self.point(Node::at(i));
                let through = base + norm(sub(b, a));
                if settled || through >= self.dist[i] {
                    continue;
                }
                let seen = match u {
                    Node::Robot => self.visible_from_robot(a, b),
                    _ => self.visible(a, b),
                };
                if seen {
                    self.dist[i] = through;
                    self.prev[i] = Some(u);
                }
            }
        }
        self.dist[1].is_finite()
    }
}
