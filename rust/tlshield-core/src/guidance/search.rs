//! The planner's search: A* from the robot to the goal over the visibility graph, with the
//! straight distance to the goal as its (consistent) heuristic, doing only the work the step
//! needs:
//! - it searches the region a path of length at most `reach` can use, the ellipse with foci the
//!   robot and the goal (`|x - robot| + |x - goal| <= reach`): only the discs that meet it
//!   ([`Router::near`]) and the corners inside it. A path that long never leaves the ellipse,
//!   and a segment inside it can only be blocked by a disc that meets it, so a way found no
//!   longer than `reach` is the shortest of the whole graph. The first reach is a little more
//!   than the straight line; where no such way is found, its excess over the straight line
//!   grows, and the search goes on in the wider region without starting over: the nodes
//!   settled keep their ways (no way through the wider region to them is shorter), a segment
//!   tested keeps its answer (it lies inside the narrower region, whose discs were all
//!   tested), and only the ways the narrower reach left out are offered again;
//! - an edge's visibility is tested only when it would improve a node that could still beat
//!   the way to the goal found so far and fit the reach (lazy: most of the `O(n^2)` edges are
//!   never tested), and a corner's cover only when the corner is first inside the region;
//! - the open nodes wait in a heap ordered by way so far plus way left, then by slot: the node
//!   of least sum first, ties to the lowest slot (the order the corners are numbered in), and
//!   a node's way among equally short ones goes through the node settled first, whatever the
//!   order the ways were offered in. So the search settles the nodes in the order, and with
//!   the ways, of one search over the widest region, which is the from-scratch planner's
//!   (`reference.rs`): the same target, bit for bit;
//! - the ways through the node just settled are measured for every node of the region in one
//!   pass over its columns ([`Region`]), and only the few that could improve a node are looked
//!   at one by one;
//! - searches towards the same goal among the same discs learn from each other ([`Onward`]):
//!   the rest of each way found, from each of its polygon corners on, is a way of every later
//!   search's graph, so a later search that reaches such a corner knows a way to the goal at
//!   most that long, and neither offers a way nor widens its reach past it. Most independent
//!   states towards one goal (a batch, an env's episodes) soon meet a corner of an earlier
//!   way. A way or a node past the bound is never settled before the goal, so the target is
//!   the same, bit for bit.
//!
//! Its work is bounded ([`WORK_BOUND`]); a search cut short keeps the way to the goal it has
//! found, if any, else the router aims at the goal. Safety never depends on the search: the
//! barriers are rows of the QP of their own, whatever the CLF aims at.

use std::cmp::Ordering;

use super::aim::lookahead;
use super::graph::{crosses, length, norm, sub, Node, CORNERS, SIDES};
use super::router::Router;

/// The most tests of a point or a segment against a disc the planner makes in one step (the
/// search's unit of work: choosing the discs near the way, a corner's cover, an edge's
/// visibility). When hit, the step keeps the way to the goal found so far, or aims at the goal
/// itself where none was found; the barriers keep the robot safe either way.
pub const WORK_BOUND: usize = 1 << 18;
/// The first reach's excess over the straight distance from the robot to the goal, in inflated
/// radii of the largest disc across the straight line: a way around it is often not much
/// longer, a region only as wide as needed holds few discs and offers few ways, and a reach too
/// short costs only the ways offered again when it widens (the search does not start over).
const FIRST_EXCESS: f64 = 0.1;
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

/// An open node waiting in the heap: its way so far plus way left when pushed, its slot, and
/// its place in the [`Region`].
#[derive(Debug, Clone, Copy)]
pub(super) struct Open {
    /// Way so far plus way left.
    f: f64,
    /// The node's slot ([`Node::index`]): ties go to the lowest.
    slot: usize,
    /// The node's place in the region.
    at: usize,
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

/// The robot's and the goal's places in a [`Region`] (it holds them first).
const ROBOT: usize = 0;
const GOAL: usize = 1;
/// No predecessor.
const NONE: usize = usize::MAX;
/// A settled node's key in [`Region::open`]: no way is shorter.
const SETTLED: f64 = f64::NEG_INFINITY;

/// The nodes of the region searched, in the order they entered it (the robot, the goal, then
/// corners as the region grew), each field a column, so that the ways through the node just
/// settled are measured for all of them in one pass.
#[derive(Debug, Clone, Default)]
pub(super) struct Region {
    /// The graph's node.
    pub(super) node: Vec<Node>,
    /// Where it is.
    pub(super) x: Vec<f64>,
    pub(super) y: Vec<f64>,
    /// The straight distance to the goal (A*'s heuristic).
    pub(super) rest: Vec<f64>,
    /// The shortest way found from the robot.
    pub(super) dist: Vec<f64>,
    /// That way while the node is open, [`SETTLED`] once it is settled: what a way through
    /// the node just settled must beat.
    pub(super) open: Vec<f64>,
    /// The node before it on that way ([`NONE`]: none yet).
    pub(super) prev: Vec<usize>,
    /// When it was settled (the settled nodes' order).
    pub(super) rank: Vec<usize>,
    /// Scratch: each node's way through the node just settled.
    pub(super) through: Vec<f64>,
    /// The settled nodes, in the order they were settled.
    pub(super) settled: Vec<usize>,
    /// Scratch: per node (rounded up to eight), whether its way through the node just
    /// settled is worth a closer look.
    pub(super) flags: Vec<u8>,
}

impl Region {
    /// The per-node columns of numbers and of indices (one place to list them).
    fn columns(&mut self) -> ([&mut Vec<f64>; 6], [&mut Vec<usize>; 3]) {
        (
            [
                &mut self.x,
                &mut self.y,
                &mut self.rest,
                &mut self.dist,
                &mut self.open,
                &mut self.through,
            ],
            [&mut self.prev, &mut self.rank, &mut self.settled],
        )
    }

    fn clear(&mut self) {
        self.node.clear();
        let (numbers, indices) = self.columns();
        numbers.into_iter().for_each(Vec::clear);
        indices.into_iter().for_each(Vec::clear);
    }

    fn reserve(&mut self, nodes: usize) {
        self.node.reserve(nodes);
        let (numbers, indices) = self.columns();
        numbers.into_iter().for_each(|c| c.reserve(nodes));
        indices.into_iter().for_each(|c| c.reserve(nodes));
        self.flags.reserve(nodes.next_multiple_of(8));
    }

    /// Adds `node` at `at`, open and not reached yet, `goal` the goal.
    fn push(&mut self, node: Node, at: [f64; 2], goal: [f64; 2]) {
        self.node.push(node);
        self.x.push(at[0]);
        self.y.push(at[1]);
        self.rest.push(length(sub(goal, at)));
        self.dist.push(f64::INFINITY);
        self.open.push(f64::INFINITY);
        self.prev.push(NONE);
        self.rank.push(NONE);
        self.through.push(0.0);
    }

    fn len(&self) -> usize {
        self.node.len()
    }
}

/// Relative slack on a bound learned from a way found ([`Onward`]): the way's own sums, and
/// the sums a search makes along it from another robot, may differ in the last bits.
const ONWARD_SLACK: f64 = 1e-9;

/// What earlier searches towards the same goal (among the same discs) tell a search: per
/// polygon corner, the length of a way from it to the goal (the rest of a way found, or the
/// straight line where the corner sees the goal), and whether it sees the goal. Those ways
/// use only polygon corners and the goal, whose segments do not depend on the robot, so they
/// are ways of every later search's graph: a node reached at `d` with a way on of `w` bounds
/// the shortest way by `d + w`, and a way or a node whose sum exceeds that bound is never
/// settled before the goal (A*'s sums only grow along a way). Offering it changes nothing;
/// not offering it saves its test, and a reach past the bound is never needed.
#[derive(Debug, Clone, Default)]
pub(super) struct Onward {
    /// Per corner ([`Node::Corner`] index): the shortest way to the goal learned (infinite:
    /// none; the two ways past a disc from the robot are always infinite).
    way: Vec<f64>,
    /// Per corner: whether the segment to the goal is clear, once tested.
    pub(super) sees: Vec<Option<bool>>,
    /// The goal these are for.
    goal: [f64; 2],
    /// This search's bound on the shortest way, slack included (infinite: none yet).
    pub(super) bound: f64,
}

impl Onward {
    /// Forgets everything learned, for `corners` corners.
    pub(super) fn forget(&mut self, corners: usize) {
        self.way.clear();
        self.way.resize(corners, f64::INFINITY);
        self.sees.clear();
        self.sees.resize(corners, None);
    }

    /// How many corners have a way on learned (tests).
    #[cfg(test)]
    pub(super) fn learned(&self) -> usize {
        self.way.iter().filter(|w| w.is_finite()).count()
    }

    /// Learns that corner `k` has a way of `way` to the goal.
    pub(super) fn learn(&mut self, k: usize, way: f64) {
        self.way[k] = self.way[k].min(way);
    }

    /// Starts a search towards `goal` among `corners` corners: what was learned towards
    /// another goal is forgotten.
    fn start(&mut self, goal: [f64; 2], corners: usize) {
        if self.goal != goal || self.way.len() != corners {
            self.goal = goal;
            self.forget(corners);
        }
        self.bound = f64::INFINITY;
    }

    /// Corner `k` was reached at `dist`: the bound tightens where a way on from it is known.
    #[inline]
    fn reached(&mut self, k: usize, dist: f64) {
        let way = self.way[k];
        if way < f64::INFINITY {
            self.bound = self.bound.min((dist + way) * (1.0 + ONWARD_SLACK));
        }
    }
}

/// How the search within one reach ended.
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
    /// inflated discs; whether one was found (the way to the goal, node by node, is left in
    /// the router's buffers, [`Router::way_to`] and [`Router::before`]). Sets
    /// [`Router::truncated`].
    pub(super) fn search(&mut self, p: [f64; 2], goal: [f64; 2], clearance: f64) -> bool {
        self.robot = p;
        self.goal = goal;
        self.work = 0;
        self.truncated = false;
        self.forget_tangents();
        self.onward.start(goal, self.corners.len());
        let nodes = 2 + self.corners.len();
        self.dist.resize(nodes, f64::INFINITY);
        self.prev.resize(nodes, None);
        self.region.reserve(nodes);
        self.heap.reserve(nodes);
        self.pending.reserve(self.corners.len());
        // Each disc's distances from the ends: how wide a region must be to meet it, and, past
        // the widest, a region that holds every corner (a corner is at most its disc's
        // inflated radius plus a lookahead from the centre).
        self.spans.clear();
        let mut everything = 0.0;
        let mut widest = 0.0;
        for (d, &r) in self.discs.iter().zip(&self.inflated) {
            let ends = length(sub(d.center, p)) + length(sub(d.center, goal));
            self.spans.push(ends - 2.0 * r);
            everything = f64::max(
                everything,
                ends + 2.0 * (r + lookahead(d.radius, clearance)),
            );
            if crosses(p, goal, d.center, r) {
                widest = f64::max(widest, r);
            }
        }
        self.work += 2 * self.discs.len();
        let straight = length(sub(goal, p));
        let mut excess = FIRST_EXCESS * widest;
        self.near.clear(self.discs.len());
        self.blocker = None;
        self.pending.clear();
        self.region.clear();
        self.region.push(Node::Robot, p, goal);
        self.region.push(Node::Goal, goal, goal);
        self.region.dist[ROBOT] = 0.0;
        self.region.open[ROBOT] = 0.0;
        self.heap.clear();
        self.heap.push(Open {
            f: self.region.rest[ROBOT],
            slot: Node::Robot.index(),
            at: ROBOT,
        });
        let mut last = f64::NEG_INFINITY;
        for tries in 0.. {
            let mut reach = straight + excess;
            // A reach past every corner (or not a number) takes in the whole graph.
            let short = reach < everything;
            if tries >= MAX_REACHES || !short {
                reach = f64::INFINITY;
            } else {
                // A way no longer than the bound is known to exist: no wider reach is needed
                // (finite tries only, so that a reach that fails in rounding still widens).
                reach = reach.min(self.onward.bound);
            }
            // With every node inside, the reach prunes nothing the whole graph would keep: a
            // search without it tells an enclosed goal from a reach too short.
            let entered = self.region.len();
            if self.widen(reach, clearance) {
                reach = f64::INFINITY;
            }
            let run = self.offer_settled((last, entered), reach);
            let run = match run {
                Run::Exhausted => self.run(reach),
                stop => stop,
            };
            match run {
                Run::Reached => {
                    self.learn_onward();
                    return true;
                }
                Run::OutOfWork => {
                    self.truncated = true;
                    self.write_way();
                    return self.dist[Node::Goal.index()].is_finite();
                }
                Run::Exhausted if reach == f64::INFINITY => return false,
                Run::Exhausted => {
                    last = reach;
                    excess *= GROW;
                }
            }
        }
        unreachable!("the reach becomes infinite after MAX_REACHES tries")
    }

    /// Widens the region to `reach` (infinite: all): the discs that meet it join
    /// [`Router::near`] (their corners wait in [`Router::pending`]), and the uncovered corners
    /// inside it join the [`Router::region`], open. Whether nothing is left out.
    fn widen(&mut self, reach: f64, clearance: f64) -> bool {
        let (p, goal) = (self.robot, self.goal);
        let everything = reach == f64::INFINITY;
        let mut whole = true;
        for i in 0..self.discs.len() {
            if self.near.holds(i) {
                continue;
            }
            let meets = self.spans[i] <= reach * (1.0 + DISC_SLACK);
            if !everything && !meets {
                whole = false;
                continue;
            }
            self.near.push(i, &self.discs[i], self.inflated[i]);
            self.place_tangents(i, p, clearance);
            for k in CORNERS * i..CORNERS * (i + 1) {
                let v = self.corners[k].at;
                self.pending
                    .push((k, length(sub(v, p)) + length(sub(v, goal))));
            }
        }
        self.work += self.discs.len();
        // The corners inside the region are tested for cover once every disc that meets it is
        // near: a disc that holds a corner meets any region the corner is in.
        let mut j = 0;
        while j < self.pending.len() {
            let (k, span) = self.pending[j];
            let inside = span <= reach * (1.0 + NODE_SLACK);
            if !everything && !inside {
                whole = false;
                j += 1;
                continue;
            }
            self.pending.swap_remove(j);
            if self.uncovered(k) {
                self.region.push(Node::Corner(k), self.corners[k].at, goal);
            }
        }
        whole
    }

    /// After the region was widened from reach `last` to `reach` (the nodes from place
    /// `entered` on new to it): offers every settled node's ways that the narrower region
    /// left out, in the order they were settled. [`Run::Exhausted`] unless the work bound was
    /// hit.
    fn offer_settled(&mut self, (last, entered): (f64, usize), reach: f64) -> Run {
        for s in 0..self.region.settled.len() {
            let u = self.region.settled[s];
            if !self.relax(u, (last, entered), reach) {
                return Run::OutOfWork;
            }
        }
        Run::Exhausted
    }

    /// A* within `reach`, from the open nodes in the heap.
    fn run(&mut self, reach: f64) -> Run {
        while let Some(Open { f, at, .. }) = self.heap.pop() {
            let region = &mut self.region;
            // A node whose way was shortened after it was pushed waits again, nearer the top.
            if region.open[at] == SETTLED || f != region.dist[at] + region.rest[at] {
                continue;
            }
            if at == GOAL {
                self.write_way();
                return Run::Reached;
            }
            region.open[at] = SETTLED;
            region.rank[at] = region.settled.len();
            region.settled.push(at);
            if !self.relax(at, (f64::NEG_INFINITY, 0), reach) {
                return Run::OutOfWork;
            }
        }
        Run::Exhausted
    }

    /// Shortens the way to every open node that the settled node `u` (a region place) sees
    /// (the robot with its slack, see [`Router::visible_from_robot`]) through `u`, testing
    /// the edge only where the way through `u` would be shorter (or as short, through a node
    /// settled earlier: ties go to the node settled first, whatever the order the ways are
    /// offered in), fit the reach and could beat the way to the goal found so far (a node that
    /// cannot is never settled before the goal: ties go to the goal, the lower slot). Ways
    /// of a sum up to `last` to nodes before place `entered` were offered before, and are
    /// not offered again. Whether the work bound was kept.
    fn relax(&mut self, u: usize, (last, entered): (f64, usize), reach: f64) -> bool {
        let region = &mut self.region;
        let (best, a) = (region.dist[u], [region.x[u], region.y[u]]);
        // Every node's way through `u` first, in one pass the compiler vectorises, flagging
        // those that may be shorter than the way the node has and fit the reach (or whose
        // square overflowed): most are not, and the pass below skips them eight at a time.
        let m = region.len();
        let within = reach.min(self.onward.bound);
        region.flags.clear();
        region.flags.resize(m.next_multiple_of(8), 0);
        // Every column cut to the region's length: a loop without bounds checks, which the
        // compiler vectorises (the same arithmetic, node by node).
        let (x, y) = (&region.x[..m], &region.y[..m]);
        let (open, rest) = (&region.open[..m], &region.rest[..m]);
        let (through, flags) = (&mut region.through[..m], &mut region.flags[..m]);
        for i in 0..m {
            let (dx, dy) = (x[i] - a[0], y[i] - a[1]);
            let t = best + (dx * dx + dy * dy).sqrt();
            through[i] = t;
            let maybe = (t <= open[i]) & (t + rest[i] <= within);
            flags[i] = u8::from(maybe | (t == f64::INFINITY));
        }
        let (node_u, rank_u) = (region.node[u], region.rank[u]);
        for word in 0..region.flags.len() / 8 {
            let flags = &self.region.flags[8 * word..8 * word + 8];
            let mut set = u64::from_le_bytes(flags.try_into().expect("eight flags"));
            while set != 0 {
                let i = 8 * word + set.trailing_zeros() as usize / 8;
                set &= set - 1;
                if !self.offer(u, (node_u, rank_u), i, (last, entered), reach) {
                    return false;
                }
            }
        }
        true
    }

    /// [`Router::relax`] for node `i` (flagged), through `u` (its node and rank given).
    /// Whether the work bound was kept.
    #[inline]
    fn offer(
        &mut self,
        u: usize,
        (node_u, rank_u): (Node, usize),
        i: usize,
        (last, entered): (f64, usize),
        reach: f64,
    ) -> bool {
        let region = &mut self.region;
        let (open, mut through) = (region.open[i], region.through[i]);
        if through < open {
        } else if open == f64::INFINITY {
            // Not reached yet, and a square that overflowed: measured again as `length` does.
            let a = [region.x[u], region.y[u]];
            through = region.dist[u] + length([region.x[i] - a[0], region.y[i] - a[1]]);
            if through.partial_cmp(&open) != Some(Ordering::Less) {
                return true;
            }
        } else if through == open {
            // As short: through the node settled first.
            if region.rank[region.prev[i]] < rank_u {
                return true;
            }
        } else {
            return true;
        }
        let f = through + region.rest[i];
        if f > reach
            || f >= region.dist[GOAL]
            || f > self.onward.bound
            || (i < entered && f <= last)
        {
            return true;
        }
        if self.work >= WORK_BOUND {
            return false;
        }
        let (a, b) = ([region.x[u], region.y[u]], [region.x[i], region.y[i]]);
        let v = region.node[i];
        if self.sees_between(node_u, v, a, b) {
            let region = &mut self.region;
            region.dist[i] = through;
            region.open[i] = through;
            region.prev[i] = u;
            if let Node::Corner(k) = v {
                self.onward.reached(k, through);
            }
            self.heap.push(Open {
                f,
                slot: v.index(),
                at: i,
            });
        }
        true
    }

    /// Learns the ways on to the goal that the way just found gives its polygon corners: from
    /// the goal back to the first node that is not one (a way past a disc from the robot, or
    /// the robot).
    fn learn_onward(&mut self) {
        let region = &self.region;
        let (mut k, mut way) = (GOAL, 0.0);
        loop {
            let before = region.prev[k];
            let corner = match region.node.get(before) {
                Some(&Node::Corner(c)) if c % CORNERS < SIDES => c,
                _ => break,
            };
            way += length(sub(
                [region.x[k], region.y[k]],
                [region.x[before], region.y[before]],
            ));
            self.onward.learn(corner, way);
            k = before;
        }
    }

    /// Leaves the way found to the goal (if any) in the per-node buffers [`Router::way_to`]
    /// and [`Router::before`] read: only its nodes are written.
    fn write_way(&mut self) {
        let region = &self.region;
        let mut k = GOAL;
        self.dist[Node::Robot.index()] = 0.0;
        self.dist[Node::Goal.index()] = region.dist[GOAL];
        while k != ROBOT && region.prev[k] != NONE {
            let (node, before) = (region.node[k], region.prev[k]);
            self.prev[node.index()] = Some(region.node[before]);
            self.dist[node.index()] = region.dist[k];
            k = before;
        }
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
