//! The planner's search: A* from the robot to the goal over the visibility graph, with the
//! straight distance to the goal as its (consistent) heuristic, doing only the work the step
//! needs:
//! - it searches the region a path of length at most `reach` can use, the ellipse with foci the
//!   robot and the goal (`|x - robot| + |x - goal| <= reach`): only the discs that meet it
//!   ([`Router::near`]) and the corners inside it. A path that long never leaves the ellipse,
//!   and a segment inside it can only be blocked by a disc that meets it, so a way found no
//!   longer than `reach` is the shortest of the whole graph. The first reach is a little more
//!   than the straight line; where no such way is found, its excess over the straight line
//!   grows and the search starts again;
//! - an edge's visibility is tested only when it would improve a node that could still beat
//!   the way to the goal found so far and fit the reach (lazy: most of the `O(n^2)` edges are
//!   never tested), and a corner's cover only when the corner is first inside the region;
//! - the open nodes wait in a heap ordered by way so far plus way left, then by slot: the node
//!   of least sum first, ties to the lowest slot (the order the corners are numbered in),
//!   deterministically, as a scan of every node would pick it.
//!
//! Its work is bounded ([`WORK_BOUND`]); a search cut short keeps the way to the goal it has
//! found, if any, else the router aims at the goal. Safety never depends on the search: the
//! barriers are rows of the QP of their own, whatever the CLF aims at.

use std::cmp::Ordering;

use super::aim::lookahead;
use super::graph::{crosses, length, norm, sub, Node, CORNERS};
use super::router::Router;

/// The most tests of a point or a segment against a disc the planner makes in one step (the
/// search's unit of work: choosing the discs near the way, a corner's cover, an edge's
/// visibility). When hit, the step keeps the way to the goal found so far, or aims at the goal
/// itself where none was found; the barriers keep the robot safe either way.
pub const WORK_BOUND: usize = 1 << 18;
/// The first reach's excess over the straight distance from the robot to the goal, in inflated
/// radii of the largest disc across the straight line: a way around it is often not much
/// longer, and a region only as wide as needed holds few discs.
const FIRST_EXCESS: f64 = 0.25;
/// How much the excess grows when no way that short was found.
const GROW: f64 = 2.0;
/// Searches with a finite reach before the whole graph is searched (an excess that has grown
/// this often holds every disc in all but degenerate cases).
const MAX_REACHES: usize = 16;
/// Slack on the reach (relative) for a node to count as inside the region: the way to a node
/// is a sum of segments, which rounding can make a hair shorter than the straight line.
const NODE_SLACK: f64 = 1e-9;
/// Slack on the reach (relative) for a disc to count as meeting the region: larger than
/// [`NODE_SLACK`], so that every disc that holds a node inside it, or crosses a segment
/// between two, is among those tested.
const DISC_SLACK: f64 = 1e-6;

/// An open node waiting in the heap: its way so far plus way left when pushed, and its slot.
#[derive(Debug, Clone, Copy)]
pub(super) struct Open {
    /// Way so far plus way left.
    f: f64,
    /// The node's slot ([`Node::index`]).
    slot: usize,
}

impl PartialEq for Open {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Open {}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Open {
    /// Reversed (`BinaryHeap` is a max-heap): the least sum first, then the lowest slot.
    fn cmp(&self, other: &Self) -> Ordering {
        other.f.total_cmp(&self.f).then(other.slot.cmp(&self.slot))
    }
}

/// How one search within a reach ended.
enum Run {
    /// The goal was settled, no farther than the reach: the shortest way.
    Reached,
    /// No way to the goal within the reach.
    Exhausted,
    /// [`WORK_BOUND`] was hit.
    OutOfWork,
}

impl Router {
    /// Searches for the shortest way from the robot at `p` to `goal` around this step's
    /// inflated discs; whether one was found (the way to each node settled, and its
    /// predecessor, are left in the router's buffers). Sets [`Router::truncated`].
    pub(super) fn search(&mut self, p: [f64; 2], goal: [f64; 2], clearance: f64) -> bool {
        self.robot = p;
        self.goal = goal;
        self.work = 0;
        self.truncated = false;
        self.forget_tangents();
        let nodes = 2 + self.corners.len();
        for buffer in [&mut self.dist, &mut self.rest] {
            buffer.resize(nodes, f64::INFINITY);
        }
        self.prev.resize(nodes, None);
        self.done.resize(nodes, false);
        self.near.reserve(self.discs.len());
        self.slots.reserve(nodes);
        self.heap.reserve(nodes);
        // Past this reach the region holds every corner: a corner is at most its disc's
        // inflated radius plus a lookahead from the centre.
        let everything = self
            .discs
            .iter()
            .zip(&self.inflated)
            .map(|(d, &r)| {
                let around = r + lookahead(d.radius, clearance);
                length(sub(d.center, p)) + length(sub(d.center, goal)) + 2.0 * around
            })
            .fold(0.0, f64::max);
        let straight = length(sub(goal, p));
        let mut excess = FIRST_EXCESS
            * self
                .discs
                .iter()
                .zip(&self.inflated)
                .filter(|(d, &r)| crosses(p, goal, d.center, r))
                .map(|(_, &r)| r)
                .fold(0.0, f64::max);
        self.work += self.discs.len();
        for tries in 0.. {
            let mut reach = straight + excess;
            // A reach past every corner (or not a number) searches the whole graph.
            let short = reach < everything;
            if tries >= MAX_REACHES || !short {
                reach = f64::INFINITY;
            }
            // With every node inside, the reach prunes nothing the whole graph would keep: a
            // search without it tells an enclosed goal from a reach too short.
            let whole = self.gather(reach, clearance);
            match self.run(if whole { f64::INFINITY } else { reach }) {
                Run::Reached => return true,
                Run::OutOfWork => {
                    self.truncated = true;
                    return self.dist[Node::Goal.index()].is_finite();
                }
                Run::Exhausted if whole => return false,
                Run::Exhausted => excess *= GROW,
            }
        }
        unreachable!("the reach becomes infinite after MAX_REACHES tries")
    }

    /// The nodes within `reach` (infinite: all): the discs that meet the region into
    /// [`Router::near`], and the robot, the goal and the uncovered corners inside it into
    /// [`Router::slots`], in slot order. Whether nothing was left out.
    fn gather(&mut self, reach: f64, clearance: f64) -> bool {
        let (p, goal) = (self.robot, self.goal);
        let everything = reach == f64::INFINITY;
        let mut whole = true;
        self.near.clear();
        self.blocker = None;
        for (i, (d, &r)) in self.discs.iter().zip(&self.inflated).enumerate() {
            let span = length(sub(d.center, p)) + length(sub(d.center, goal)) - 2.0 * r;
            if everything || span <= reach * (1.0 + DISC_SLACK) {
                self.near.push(i);
            } else {
                whole = false;
            }
        }
        self.work += self.discs.len();
        self.slots.clear();
        self.slots
            .extend([(Node::Robot.index(), p), (Node::Goal.index(), goal)]);
        for n in 0..self.near.len() {
            let i = self.near[n];
            self.place_tangents(i, p, clearance);
            for k in CORNERS * i..CORNERS * (i + 1) {
                let v = self.corners[k].at;
                let span = length(sub(v, p)) + length(sub(v, goal));
                let inside = span <= reach * (1.0 + NODE_SLACK);
                if !everything && !inside {
                    whole = false;
                } else if self.uncovered(k) {
                    self.slots.push((Node::Corner(k).index(), v));
                }
            }
        }
        whole
    }

    /// A* over the nodes gathered for `reach`.
    fn run(&mut self, reach: f64) -> Run {
        let goal = self.goal;
        for &(i, at) in &self.slots {
            self.dist[i] = f64::INFINITY;
            self.prev[i] = None;
            self.done[i] = false;
            self.rest[i] = length(sub(goal, at));
        }
        let robot = Node::Robot.index();
        self.dist[robot] = 0.0;
        self.heap.clear();
        self.heap.push(Open {
            f: self.rest[robot],
            slot: robot,
        });
        while let Some(Open { f, slot }) = self.heap.pop() {
            // A node whose way was shortened after it was pushed waits again, nearer the top.
            if self.done[slot] || f != self.dist[slot] + self.rest[slot] {
                continue;
            }
            if slot == Node::Goal.index() {
                return Run::Reached;
            }
            self.done[slot] = true;
            if !self.relax(Node::at(slot), reach) {
                return Run::OutOfWork;
            }
        }
        Run::Exhausted
    }

    /// Shortens the way to every open node that `u` sees (the robot with its slack, see
    /// [`Router::visible_from_robot`]) through `u`, testing the edge only where the way
    /// through `u` would be shorter, fit the reach and could beat the way to the goal found so
    /// far (a node that cannot is never settled before the goal: ties go to the goal, the
    /// lower slot). Whether the work bound was kept.
    fn relax(&mut self, u: Node, reach: f64) -> bool {
        let best = self.dist[u.index()];
        let a = self.point(u);
        for s in 1..self.slots.len() {
            let (i, b) = self.slots[s];
            if self.done[i] {
                continue;
            }
            let through = best + length(sub(b, a));
            if through >= self.dist[i] {
                continue;
            }
            let f = through + self.rest[i];
            if f > reach || f >= self.dist[Node::Goal.index()] {
                continue;
            }
            if self.work >= WORK_BOUND {
                return false;
            }
            if self.sees_between(u, Node::at(i), a, b) {
                self.dist[i] = through;
                self.prev[i] = Some(u);
                self.heap.push(Open { f, slot: i });
            }
        }
        true
    }

    /// Measures the way found again with [`norm`], node by node from the robot, as a search
    /// on [`norm`] sums it: the search's own sums ([`length`]) may differ in the last bits.
    pub(super) fn measure_way(&mut self) {
        self.path.clear();
        let mut node = Node::Goal;
        while node != Node::Robot {
            self.path.push(node);
            node = self.before(node);
        }
        let (mut at, mut way) = (self.robot, 0.0);
        for k in (0..self.path.len()).rev() {
            let next = self.point(self.path[k]);
            way += norm(sub(next, at));
            self.dist[self.path[k].index()] = way;
            at = next;
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
