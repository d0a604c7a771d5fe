//! The planner's search: A* on the dense visibility graph from the robot to the goal, with the
//! straight distance to the goal as its (consistent) heuristic, and an edge's visibility tested
//! only when it would improve a node. Ties go to the node found first, deterministically.

use super::graph::{norm, sub, Node};
use super::router::Router;

impl Router {
    /// Searches the last graph built; whether a path reaches the goal (the way to each node
    /// settled, and its predecessor, are left in the router's buffers).
    pub(super) fn search(&mut self) -> bool {
        let n = self.nodes();
        let (robot, goal) = (self.robot, self.goal);
        self.rest.clear();
        self.rest.push(norm(sub(goal, robot)));
        self.rest.push(norm(sub(goal, goal)));
        self.rest
            .extend(self.corners.iter().map(|c| norm(sub(goal, c.at))));
        self.dist.clear();
        self.dist.resize(n, f64::INFINITY);
        self.prev.clear();
        self.prev.resize(n, None);
        self.done.clear();
        self.done.resize(n, false);
        self.dist[Node::Robot.index()] = 0.0;
        while let Some(u) = self.nearest_open() {
            if u == Node::Goal {
                break;
            }
            self.done[u.index()] = true;
            self.relax(u);
        }
        self.dist[Node::Goal.index()].is_finite()
    }

    /// The open node of least way so far plus way left (the first on ties); `None` when no
    /// open node is reachable.
    fn nearest_open(&self) -> Option<Node> {
        let mut u = None;
        let mut best = f64::INFINITY;
        for (i, (&d, &done)) in self.dist.iter().zip(&self.done).enumerate() {
            if !done && d + self.rest[i] < best {
                (u, best) = (Some(i), d + self.rest[i]);
            }
        }
        u.map(Node::at)
    }

    /// Shortens the way to every open node that `u` sees (the robot with its slack, see
    /// [`Router::visible_from_robot`]) through `u`.
    fn relax(&mut self, u: Node) {
        let best = self.dist[u.index()];
        let a = self.point(u);
        for i in Node::Goal.index()..self.nodes() {
            if self.done[i] {
                continue;
            }
            let b = self.point(Node::at(i));
            let through = best + norm(sub(b, a));
            if through >= self.dist[i] {
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

    /// The length of the shortest way found from the robot to `node`.
    pub(super) fn way_to(&self, node: Node) -> f64 {
        self.dist[node.index()]
    }

    /// The node before `node` on the shortest path found (`node` is on it, not the robot).
    pub(super) fn before(&self, node: Node) -> Node {
        self.prev[node.index()].expect("every node of the path but the robot has a predecessor")
    }
}
