//! The planner's visibility graph: its nodes (the robot, the goal, and the corners past each
//! inflated disc) and which segments between them keep out of the discs, with the plane
//! geometry they are built from.

use std::f64::consts::PI;

use super::aim::lookahead;
use super::plane::Disc;
use super::router::Router;

/// Sides of the polygon circumscribing each inflated disc.
pub const SIDES: usize = 8;
/// The unit vectors to the corners of the octagon, at multiples of 45 degrees.
pub(super) const OCTAGON: [[f64; 2]; SIDES] = {
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
/// How far into the clearance (a fraction of the inflated radius) a segment from the robot may
/// cut.
pub const ROBOT_SLACK: f64 = 0.05;
/// How close (a fraction of the radius) a segment may pass a disc's rim and still only touch
/// it: a polygon's side touches its inflated circle in exact arithmetic, and rounding must not
/// make it cross.
const TOUCH: f64 = 1e-9;

/// Corners per disc: the polygon's, then the two ways past it from the robot.
pub(super) const CORNERS: usize = SIDES + 2;

/// Whether a corner lies inside another inflated disc (and so is no node), as far as known.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Cover {
    /// Not tested since the corner was placed.
    Unknown,
    /// Outside every other inflated disc: a node.
    Free,
    /// Inside another inflated disc: dropped.
    Covered,
}

/// Polygon corners up to which [`Edges`] remembers every segment between two of them (the
/// memory is two bits per ordered pair: under 3 MiB here); past it, every segment is tested.
const REMEMBERED_CORNERS: usize = 4096;

/// What is known of the segments between polygon corners (the graph's edges that do not
/// depend on the robot or the goal): whether each was tested, and whether it was clear. A
/// segment's visibility is the same from step to step while the discs stay put, and a search
/// along a trajectory tests mostly the same ones. Two bits per ordered pair `(from, to)` (the
/// test is not symmetric in rounding: the pair is tested as the search first met it).
#[derive(Debug, Clone, Default)]
pub(super) struct Edges {
    /// Per ordered pair of polygon corners: tested, and clear (bits of `2 * pair` and
    /// `2 * pair + 1`).
    pub(super) known: Vec<u64>,
    /// The words of `known` written since the corners were placed (cleared word by word when
    /// few, so that moving discs do not clear the whole table each step).
    pub(super) set: Vec<usize>,
    /// Polygon corners remembered (0: none, past [`REMEMBERED_CORNERS`]).
    corners: usize,
}

impl Edges {
    /// Forgets every segment, for `corners` polygon corners.
    fn reset(&mut self, corners: usize) {
        let corners = if corners <= REMEMBERED_CORNERS {
            corners
        } else {
            0
        };
        let words = (2 * corners * corners).div_ceil(64);
        if self.set.len() * 4 < self.known.len() && words == self.known.len() {
            for &w in &self.set {
                self.known[w] = 0;
            }
        } else {
            self.known.clear();
            self.known.resize(words, 0);
        }
        self.set.clear();
        self.corners = corners;
    }

    /// The bit pair of the segment from corner `k` to corner `l` (both [`Node::Corner`]
    /// indices), if both are polygon corners and remembered.
    fn pair(&self, k: usize, l: usize) -> Option<usize> {
        let (pk, pl) = (k % CORNERS, l % CORNERS);
        if pk >= SIDES || pl >= SIDES || self.corners == 0 {
            return None;
        }
        let (pk, pl) = (k / CORNERS * SIDES + pk, l / CORNERS * SIDES + pl);
        Some(2 * (pk * self.corners + pl))
    }
}

/// A node of the visibility graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Node {
    /// The robot's position, where every path starts.
    Robot,
    /// The goal, where every path ends.
    Goal,
    /// A corner ([`Corner`]): the `k % CORNERS`-th of disc `k / CORNERS` (the order that breaks
    /// the search's ties).
    Corner(usize),
}

impl Node {
    /// The node's slot in the search's per-node buffers: the robot, the goal, then the corners
    /// in order (the order that breaks the search's ties).
    pub(super) fn index(self) -> usize {
        match self {
            Node::Robot => 0,
            Node::Goal => 1,
            Node::Corner(k) => 2 + k,
        }
    }

    /// The node in slot `i` (the inverse of [`Node::index`]; the reference planner numbers its
    /// nodes by slot).
    #[cfg(test)]
    pub(super) fn at(i: usize) -> Node {
        match i {
            0 => Node::Robot,
            1 => Node::Goal,
            i => Node::Corner(i - 2),
        }
    }
}

/// A way point past a disc: a vertex of its circumscribed polygon, or a point along a tangent
/// from the robot.
#[derive(Debug, Clone, Copy)]
pub(super) struct Corner {
    /// Where it is.
    pub(super) at: [f64; 2],
    /// The disc it leads past.
    pub(super) disc: usize,
}

/// `a - b`.
pub(super) fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// `|a|` (libm's `hypot`): the lengths the target is placed with.
pub(super) fn norm(a: [f64; 2]) -> f64 {
    a[0].hypot(a[1])
}

/// `|a|` by the plain formula (`hypot` where the squares overflow): the search's many
/// distances, which only order and prune (`hypot` cost more than the rest of the search).
/// The way found is measured again with [`norm`] (`Router::measure_way`), so the target is
/// the one a search on [`norm`] gives.
#[inline]
pub(super) fn length(a: [f64; 2]) -> f64 {
    let sq = a[0] * a[0] + a[1] * a[1];
    if sq.is_finite() {
        sq.sqrt()
    } else {
        a[0].hypot(a[1])
    }
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

/// [`past_tangent`] on both sides (`+1` then `-1`), sharing the distance, the angle and its sine
/// and cosine (libm's are odd and even in the angle: the same points, bit for bit).
pub(super) fn past_tangents(p: [f64; 2], c: [f64; 2], r: f64, lookahead: f64) -> [[f64; 2]; 2] {
    let rim = sub(p, c);
    let d = norm(rim);
    if d <= r || d == 0.0 {
        return [1.0, -1.0].map(|side| past_tangent(p, c, r, side, lookahead));
    }
    let (sin, cos) = (r / d).acos().sin_cos();
    let u = [rim[0] / d, rim[1] / d];
    [sin, -sin].map(|sin| {
        let at = [
            c[0] + r * (u[0] * cos - u[1] * sin),
            c[1] + r * (u[0] * sin + u[1] * cos),
        ];
        let v = sub(at, p);
        let len = norm(v).max(f64::MIN_POSITIVE);
        let to = len.max(lookahead);
        [p[0] + to * v[0] / len, p[1] + to * v[1] / len]
    })
}

/// The point on the tangent from `p` to the circle (`c`, `r`) on `side`, at least `lookahead`
/// from `p` (past the tangent point when that is nearer).
pub(super) fn past_tangent(
    p: [f64; 2],
    c: [f64; 2],
    r: f64,
    side: f64,
    lookahead: f64,
) -> [f64; 2] {
    let u = sub(tangent(p, c, r, side), p);
    let len = norm(u).max(f64::MIN_POSITIVE);
    let to = len.max(lookahead);
    [p[0] + to * u[0] / len, p[1] + to * u[1] / len]
}

/// Whether the segment `a`-`b` passes strictly inside the disc at `c` of radius `r` (touching
/// it, as a polygon's side does, is allowed).
#[inline]
pub(super) fn crosses(a: [f64; 2], b: [f64; 2], c: [f64; 2], r: f64) -> bool {
    Segment::new(a, b).crosses(c, r)
}

/// A segment, with its bounding box, tested against many discs.
#[derive(Debug, Clone, Copy)]
pub(super) struct Segment {
    a: [f64; 2],
    b: [f64; 2],
    /// The bounding box: least and greatest x, least and greatest y.
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Segment {
    #[inline]
    pub(super) fn new(a: [f64; 2], b: [f64; 2]) -> Segment {
        Segment {
            a,
            b,
            lo: [a[0].min(b[0]), a[1].min(b[1])],
            hi: [a[0].max(b[0]), a[1].max(b[1])],
        }
    }

    /// Whether it passes strictly inside the disc at `c` of radius `r` (touching it, as a
    /// polygon's side does, is allowed).
    #[inline]
    pub(super) fn crosses(&self, c: [f64; 2], r: f64) -> bool {
        // Most discs a segment is tested against lie far from it: a centre more than `r`
        // outside the segment's bounding box on either axis is more than `r` from every point
        // of it, which four comparisons tell (exactly) before the projection's division.
        if c[0] + r < self.lo[0]
            || c[0] - r > self.hi[0]
            || c[1] + r < self.lo[1]
            || c[1] - r > self.hi[1]
        {
            return false;
        }
        // The nearest point is an end, or the foot of the perpendicular, whose squared
        // distance `(ac x d)^2 / |d|^2` is compared without the division.
        let cut = r * (1.0 - TOUCH);
        let cut2 = cut * cut;
        let (a, b) = (self.a, self.b);
        let d = sub(b, a);
        let ac = sub(c, a);
        let along = ac[0] * d[0] + ac[1] * d[1];
        if along <= 0.0 {
            return ac[0] * ac[0] + ac[1] * ac[1] < cut2;
        }
        let len2 = d[0] * d[0] + d[1] * d[1];
        if along >= len2 {
            let bc = sub(c, b);
            return bc[0] * bc[0] + bc[1] * bc[1] < cut2;
        }
        let cross = ac[0] * d[1] - ac[1] * d[0];
        cross * cross < cut2 * len2
    }
}

/// The discs that meet the region searched (`search.rs`), in order, each field a column: every
/// segment the search tests is tested against them.
#[derive(Debug, Clone, Default)]
pub(super) struct Near {
    /// The disc's index among the step's.
    pub(super) disc: Vec<usize>,
    /// Its centre.
    pub(super) x: Vec<f64>,
    pub(super) y: Vec<f64>,
    /// Its inflated radius, and the radius a segment from the robot may not cut into
    /// ([`Router::visible_from_robot`]).
    pub(super) r: Vec<f64>,
    pub(super) robot: Vec<f64>,
    /// Per disc of the step: its place among these (meaningful for these only).
    pub(super) place: Vec<usize>,
}

impl Near {
    pub(super) fn clear(&mut self, discs: usize) {
        for column in [&mut self.disc, &mut self.place] {
            column.clear();
        }
        for column in [&mut self.x, &mut self.y, &mut self.r, &mut self.robot] {
            column.clear();
        }
        self.place.resize(discs, usize::MAX);
    }

    pub(super) fn push(&mut self, i: usize, disc: &Disc, inflated: f64) {
        self.place[i] = self.disc.len();
        self.disc.push(i);
        self.x.push(disc.center[0]);
        self.y.push(disc.center[1]);
        self.r.push(inflated);
        self.robot.push(robot_cut(disc, inflated));
    }

    pub(super) fn len(&self) -> usize {
        self.disc.len()
    }

    /// Whether disc `i` of the step is among these.
    pub(super) fn holds(&self, i: usize) -> bool {
        self.place[i] != usize::MAX
    }

    /// Whether one of these other than disc `i` (one of these) holds `v` strictly inside its
    /// inflated radius.
    fn covers(&self, v: [f64; 2], i: usize) -> bool {
        // Every disc in one pass without early exits, which the compiler vectorises: most
        // corners tested (the ways past a disc from the robot, tested every step) are covered
        // by none, so every disc is looked at anyway.
        let own = self.place[i];
        let n = self.x.len();
        let (x, y, r) = (&self.x[..n], &self.y[..n], &self.r[..n]);
        let (mut covered, mut overflow) = (false, false);
        for j in 0..n {
            // A component as long as the radius tells a point outside without the root (the
            // root of a sum of squares is at least either component, exactly).
            let e = [v[0] - x[j], v[1] - y[j]];
            let near = (e[0].abs() < r[j]) & (e[1].abs() < r[j]) & (j != own);
            let sq = e[0] * e[0] + e[1] * e[1];
            covered |= near & (sq.sqrt() < r[j]);
            overflow |= near & (sq == f64::INFINITY);
        }
        if overflow {
            // A square that overflowed: measured again as `length` does.
            return (0..n).any(|j| {
                let e = sub(v, [x[j], y[j]]);
                e[0].abs() < r[j] && e[1].abs() < r[j] && j != own && length(e) < r[j]
            });
        }
        covered
    }
}

/// The radius of `disc` (inflated to `inflated`) a segment from the robot may not cut into: it
/// may cut [`ROBOT_SLACK`] into the clearance, never into the disc.
#[inline]
fn robot_cut(disc: &Disc, inflated: f64) -> f64 {
    ((1.0 - ROBOT_SLACK) * inflated)
        .max(disc.radius)
        .min(inflated)
}

impl Router {
    /// Places the corners of every disc's circumscribed polygon (they do not depend on the
    /// robot: kept while the discs stay put) and marks every corner's cover unknown.
    pub(super) fn place_polygons(&mut self) {
        let corner = 1.0 / (PI / SIDES as f64).cos();
        self.corners.clear();
        for (i, d) in self.discs.iter().enumerate() {
            let r = self.inflated[i] * corner;
            let polygon = OCTAGON.map(|[c, s]| [d.center[0] + r * c, d.center[1] + r * s]);
            // The two ways past the disc from the robot are placed when the disc is first
            // needed in a step ([`Router::place_tangents`]).
            let ways = [d.center; 2];
            for at in polygon.into_iter().chain(ways) {
                self.corners.push(Corner { at, disc: i });
            }
        }
        self.cover.clear();
        self.cover.resize(self.corners.len(), Cover::Unknown);
        self.edges.reset(SIDES * self.discs.len());
        self.onward.forget(self.corners.len());
    }

    /// Forgets the ways past each disc from the last step's robot position: they are placed
    /// again when needed.
    pub(super) fn forget_tangents(&mut self) {
        self.tangents.clear();
        self.tangents.resize(self.discs.len(), false);
        for k in (SIDES..self.cover.len()).step_by(CORNERS) {
            self.cover[k] = Cover::Unknown;
            self.cover[k + 1] = Cover::Unknown;
        }
    }

    /// Places the two ways past disc `i` from the robot at `p` (along each tangent from it to
    /// the inflated circle, at least a lookahead far: continuous in the robot's position, so
    /// the shortest way does not jump as the robot moves), once per step.
    pub(super) fn place_tangents(&mut self, i: usize, p: [f64; 2], clearance: f64) {
        if self.tangents[i] {
            return;
        }
        self.tangents[i] = true;
        let d = self.discs[i];
        let lookahead = lookahead(d.radius, clearance);
        let ways = past_tangents(p, d.center, self.inflated[i], lookahead);
        for (j, at) in ways.into_iter().enumerate() {
            self.corners[CORNERS * i + SIDES + j].at = at;
        }
    }

    /// Whether corner `k` is a node: on the kept side of every wall, and not inside another
    /// inflated disc. Only the discs of
    /// [`Router::near`] are tested, which is exact for a corner in the region they were chosen
    /// for (a disc that holds the corner meets that region). Remembered until the corner moves.
    pub(super) fn uncovered(&mut self, k: usize) -> bool {
        if self.cover[k] == Cover::Unknown {
            let (v, i) = (self.corners[k].at, self.corners[k].disc);
            let near = &self.near;
            self.work += near.len();
            self.work += self.walls.len();
            let covered = self.walls.iter().any(|w| !w.keeps(v)) || near.covers(v, i);
            self.cover[k] = if covered { Cover::Covered } else { Cover::Free };
        }
        self.cover[k] == Cover::Free
    }

    /// Where `node` is.
    pub(super) fn point(&self, node: Node) -> [f64; 2] {
        match node {
            Node::Robot => self.robot,
            Node::Goal => self.goal,
            Node::Corner(k) => self.corners[k].at,
        }
    }

    /// Whether the segment `a`-`b` keeps out of every inflated disc (a polygon's own sides
    /// touch its disc and are allowed).
    pub(super) fn visible(&self, a: [f64; 2], b: [f64; 2]) -> bool {
        !self
            .discs
            .iter()
            .zip(&self.inflated)
            .any(|(d, &r)| crosses(a, b, d.center, r))
    }

    /// [`Router::visible`] (or, from the robot, [`Router::visible_from_robot`]) from node `u`
    /// to node `v` (at `a` and `b`) tested against the discs of [`Router::near`] only: exact
    /// for a segment inside the region they were chosen for (a disc that crosses it meets that
    /// region).
    ///
    /// Most segments the search tests are blocked, and most of those by a disc it can guess:
    /// the disc an end leads past (a corner's segment to a node behind its own disc crosses
    /// it), or the one that blocked the last segment. Those are tested first; the answer is
    /// the same in any order.
    pub(super) fn sees(&mut self, (u, v): (Node, Node), a: [f64; 2], b: [f64; 2]) -> bool {
        let near = &self.near;
        let radii = match u {
            Node::Robot => &near.robot,
            _ => &near.r,
        };
        let place = |n: Node| match n {
            Node::Corner(k) => Some(near.place[self.corners[k].disc]),
            _ => None,
        };
        let segment = Segment::new(a, b);
        let hints = [self.blocker, place(v), place(u)];
        let mut tests = 0;
        let mut blocker = None;
        for j in hints.into_iter().flatten() {
            tests += 1;
            if segment.crosses([near.x[j], near.y[j]], radii[j]) {
                blocker = Some(j);
                break;
            }
        }
        if blocker.is_none() {
            // The guesses are tested again with the rest: cheaper than skipping them.
            tests += near.x.len();
            blocker = near
                .x
                .iter()
                .zip(&near.y)
                .zip(radii)
                .position(|((&x, &y), &r)| segment.crosses([x, y], r));
        }
        self.work += tests;
        match blocker {
            Some(j) => {
                self.blocker = Some(j);
                false
            }
            None => true,
        }
    }

    /// [`Router::sees`] from node `u` to node `v` (at `a` and `b`), remembered between two
    /// polygon corners (exact: a segment the search tests lies inside the region searched, so
    /// the discs of [`Router::near`] are every disc that could cross it, and its answer holds
    /// for the whole graph while the discs stay put).
    pub(super) fn sees_between(&mut self, u: Node, v: Node, a: [f64; 2], b: [f64; 2]) -> bool {
        let pair = match (u, v) {
            (Node::Corner(k), Node::Corner(l)) => self.edges.pair(k, l),
            (Node::Corner(k), Node::Goal) if k % CORNERS < SIDES => {
                return self.sees_goal(k, a, b);
            }
            _ => None,
        };
        let Some(bit) = pair else {
            return self.sees((u, v), a, b);
        };
        let (word, shift) = (bit / 64, bit % 64);
        let known = self.edges.known[word] >> shift;
        if known & 1 == 1 {
            return known & 2 == 2;
        }
        let clear = self.sees((u, v), a, b);
        if self.edges.known[word] == 0 {
            self.edges.set.push(word);
        }
        self.edges.known[word] |= (1 | u64::from(clear) << 1) << shift;
        clear
    }

    /// [`Router::sees`] from polygon corner `k` (at `a`) to the goal (at `b`), remembered while
    /// the discs stay put and the goal is the same (exact, as [`Router::sees_between`]'s). A
    /// corner that sees the goal is at most the straight line from it
    /// ([`Onward::way`](super::search::Onward)).
    fn sees_goal(&mut self, k: usize, a: [f64; 2], b: [f64; 2]) -> bool {
        if let Some(clear) = self.onward.sees[k] {
            return clear;
        }
        let clear = self.sees((Node::Corner(k), Node::Goal), a, b);
        self.onward.sees[k] = Some(clear);
        if clear {
            self.onward.learn(k, length(sub(b, a)));
        }
        clear
    }

    /// [`Router::visible`] for a segment from the robot, which may cut [`ROBOT_SLACK`] into
    /// the clearance (never into a disc): a robot that has reached a corner, or stands a hair
    /// inside its polygon, still sees the next corner, instead of creeping onto the corner.
    pub(super) fn visible_from_robot(&self, a: [f64; 2], b: [f64; 2]) -> bool {
        !self
            .discs
            .iter()
            .zip(&self.inflated)
            .any(|(d, &r)| crosses(a, b, d.center, robot_cut(d, r)))
    }
}
