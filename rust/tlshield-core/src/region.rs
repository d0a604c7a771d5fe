//! The geometry of regions, for guidance (beyond the paper): the convex pieces of a predicate,
//! the deepest point of an intersection of pieces, and which atoms can hold together.
//!
//! A union is a choice among its parts and an intersection needs all of them, so a positive
//! predicate is a DNF of convex pieces (balls, half-spaces): its *alternatives*. The deepest
//! point of an alternative maximises the least robustness of its pieces,
//! `max_x min_i rho_i(x)`: a second-order cone program, solved exactly by Clarabel. Its value
//! (the depth) is > 0 iff the pieces have a common interior point, so it also tells whether a
//! conjunction of regions is geometrically empty.
//!
//! Only pieces in one coordinate space take part: balls over the same `pos` dimensions and
//! half-spaces that read no other dimension. A piece whose centre is read from the state
//! (a moving region) is *dynamic*: it has a deepest point at every state but none fixed.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus,
    SupportedConeT::{NonnegativeConeT, SecondOrderConeT},
};

use smallvec::SmallVec;

use crate::predicate::{Ball, Center, Predicate};

/// Most alternatives one conjunction may expand into (the product of its unions' sizes).
pub const MAX_ALTERNATIVES: usize = 256;

/// Depths at or below this count as empty: atoms hold strictly inside, so regions that only
/// touch share no point, and the solver's tolerance must not make them overlap.
pub const EMPTY_DEPTH: f64 = 1e-7;

/// A convex piece in the coordinates of a goal space (`dims`).
#[derive(Debug, Clone, PartialEq)]
pub enum Piece {
    /// `radius - |x - centre|`.
    Ball {
        /// The centre.
        centre: Vec<f64>,
        /// The radius.
        radius: f64,
    },
    /// `w . x + b`.
    Halfspace {
        /// The normal.
        w: Vec<f64>,
        /// The offset.
        b: f64,
    },
}

impl Piece {
    /// Robustness at `x` (goal coordinates).
    pub fn value(&self, x: &[f64]) -> f64 {
        match self {
            Piece::Ball { centre, radius } => {
                let sq: f64 = x.iter().zip(centre).map(|(a, c)| (a - c) * (a - c)).sum();
                radius - sq.sqrt()
            }
            Piece::Halfspace { w, b } => w.iter().zip(x).map(|(w, x)| w * x).sum::<f64>() + b,
        }
    }
}

/// The convex leaves of a positive predicate as a DNF: the predicate holds iff every leaf of
/// some alternative holds. `None` when the expansion exceeds [`MAX_ALTERNATIVES`].
pub fn alternatives(p: &Predicate) -> Option<Vec<Vec<&Predicate>>> {
    match p {
        Predicate::Halfspace(_) | Predicate::Ball(_) => Some(vec![vec![p]]),
        Predicate::Union(parts) => {
            let mut out = Vec::new();
            for part in parts {
                out.extend(alternatives(part)?);
                if out.len() > MAX_ALTERNATIVES {
                    return None;
                }
            }
            Some(out)
        }
        Predicate::Intersection(parts) => {
            let mut out: Vec<Vec<&Predicate>> = vec![Vec::new()];
            for part in parts {
                out = product(&out, &alternatives(part)?)?;
            }
            Some(out)
        }
    }
}

/// Every concatenation of one alternative of `a` with one of `b`.
pub fn product<'a>(
    a: &[Vec<&'a Predicate>],
    b: &[Vec<&'a Predicate>],
) -> Option<Vec<Vec<&'a Predicate>>> {
    if a.len() * b.len() > MAX_ALTERNATIVES {
        return None;
    }
    Some(
        a.iter()
            .flat_map(|x| b.iter().map(move |y| x.iter().chain(y).copied().collect()))
            .collect(),
    )
}

/// The goal space of a set of leaves: the `pos` of their first ball (`None` without a ball).
pub fn goal_dims<'a>(leaves: &[&'a Predicate]) -> Option<&'a [usize]> {
    leaves.iter().find_map(|p| match p {
        Predicate::Ball(b) if b.offset().is_none() => Some(b.pos()),
        _ => None,
    })
}

/// A ball of a predicate read as geometry of the coordinate space `dims` (a plane for the
/// router): the one reading of a ball as a shape, shared by the goal's pieces ([`piece`],
/// [`centre_if_deepest`], [`separated`]) and the discs the router goes around
/// (`guidance::plane`). It says where the centre is at a state and how far the point the ball
/// holds sits from `s[dims]`: a body point is a region of the body, not of `dims`, so the
/// goal's pieces leave it out, while the router grows its disc by that distance.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Round<'p> {
    ball: &'p Ball,
}

impl<'p> Round<'p> {
    /// `leaf` when it is a ball over exactly `dims` (the point it holds `s[dims]` or a body
    /// point); `None` for anything else.
    pub(crate) fn over(leaf: &'p Predicate, dims: &[usize]) -> Option<Self> {
        match leaf {
            Predicate::Ball(ball) if ball.pos() == dims => Some(Round { ball }),
            _ => None,
        }
    }

    /// Coordinate `k` of the centre at state `s` (read from `s` when the ball moves).
    pub(crate) fn centre_at(self, k: usize, s: &[f64]) -> f64 {
        match self.ball.center() {
            Center::Fixed(c) => c[k],
            Center::Dims(d) => s[d[k]],
        }
    }

    /// Coordinate `k` of the centre, placed at `s` when there is one: `None` for a moving ball
    /// without a state (it has no place of its own).
    pub(crate) fn centre(self, k: usize, s: Option<&[f64]>) -> Option<f64> {
        match (self.ball.center(), s) {
            (Center::Fixed(c), _) => Some(c[k]),
            (Center::Dims(_), Some(s)) => Some(self.centre_at(k, s)),
            (Center::Dims(_), None) => None,
        }
    }

    /// The radius.
    pub(crate) fn radius(self) -> f64 {
        self.ball.radius()
    }

    /// The distance from `s[dims]` to the body point the ball holds (the same at every
    /// heading); `None` when it holds `s[dims]` itself.
    pub(crate) fn body_reach(self) -> Option<f64> {
        self.ball.offset().map(|o| o.length())
    }

    /// Whether the ball holds `s[dims]` itself: a region of the space `dims`.
    fn of_the_point(self) -> bool {
        self.ball.offset().is_none()
    }
}

/// `leaf` as a piece over `dims`: a ball over exactly `dims` (its centre read from `s` when it
/// moves; `None` for a moving ball without `s`), or a half-space reading only `dims`.
/// `Some(None)`: the leaf does not live in this space (it takes no part).
pub fn piece(leaf: &Predicate, dims: &[usize], s: Option<&[f64]>) -> Option<Option<Piece>> {
    if let Some(round) = Round::over(leaf, dims).filter(|r| r.of_the_point()) {
        let centre = (0..dims.len())
            .map(|k| round.centre(k, s))
            .collect::<Option<Vec<f64>>>()?;
        return Some(Some(Piece::Ball {
            centre,
            radius: round.radius(),
        }));
    }
    match leaf {
        Predicate::Halfspace(h)
            if (0..h.w().len()).all(|d| h.w()[d] == 0.0 || dims.contains(&d)) =>
        {
            Some(Some(Piece::Halfspace {
                w: dims
                    .iter()
                    .map(|&d| h.w().get(d).copied().unwrap_or(0.0))
                    .collect(),
                b: h.b(),
            }))
        }
        _ => Some(None),
    }
}

/// The allocation-free common case of [`deepest_point`] for leaves placed at state `s`: one
/// ball over `dims` whose centre (read from `s` when it moves) lies at least its radius inside
/// every half-space leaf. Writes the centre into `out` and returns `true`; `false` (and `out`
/// unspecified) otherwise, when the general solve is needed.
pub fn centre_if_deepest(
    leaves: &[Predicate],
    dims: &[usize],
    s: &[f64],
    out: &mut Vec<f64>,
) -> bool {
    let mut ball = None;
    for round in leaves
        .iter()
        .filter_map(|leaf| Round::over(leaf, dims))
        .filter(|r| r.of_the_point())
    {
        if ball.is_some() {
            return false;
        }
        ball = Some(round);
    }
    let Some(b) = ball else {
        return false;
    };
    out.clear();
    out.extend((0..dims.len()).map(|k| b.centre_at(k, s)));
    leaves.iter().all(|leaf| match leaf {
        Predicate::Halfspace(h) => {
            let w = h.w();
            // Only half-spaces that read the goal space alone take part (as in `piece`).
            if (0..w.len()).any(|d| w[d] != 0.0 && !dims.contains(&d)) {
                return true;
            }
            let at: f64 = dims
                .iter()
                .zip(out.iter())
                .map(|(&d, x)| w.get(d).copied().unwrap_or(0.0) * x)
                .sum::<f64>()
                + h.b();
            at >= b.radius()
        }
        _ => true,
    })
}

/// Whether two of `leaves` (placed at state `s`) are separated in the goal space `dims`, so that
/// no point holds them all (the region is empty), decided in closed form: a ball wholly on the
/// negative side of a half-space (`w . c + b + r |w| <= 0`), or two balls no closer than the sum
/// of their radii. A cheap exact test before the cone program (`false` says nothing). Only the
/// pieces [`piece`] would keep take part.
pub fn separated(leaves: &[Predicate], dims: &[usize], s: &[f64]) -> bool {
    let centre = |b: Round<'_>, k: usize| b.centre_at(k, s);
    let balls = || {
        leaves
            .iter()
            .filter_map(|leaf| Round::over(leaf, dims))
            .filter(|r| r.of_the_point())
    };
    for leaf in leaves {
        let Predicate::Halfspace(h) = leaf else {
            continue;
        };
        let w = h.w();
        if (0..w.len()).any(|d| w[d] != 0.0 && !dims.contains(&d)) {
            continue;
        }
        let wd: SmallVec<[f64; 4]> = dims
            .iter()
            .map(|&d| w.get(d).copied().unwrap_or(0.0))
            .collect();
        let norm = wd.iter().map(|v| v * v).sum::<f64>().sqrt();
        for b in balls() {
            let at: f64 = wd
                .iter()
                .enumerate()
                .map(|(k, v)| v * centre(b, k))
                .sum::<f64>();
            if at + h.b() + b.radius() * norm <= 0.0 {
                return true;
            }
        }
    }
    let all: SmallVec<[Round<'_>; 4]> = balls().collect();
    for (i, a) in all.iter().enumerate() {
        for b in &all[i + 1..] {
            let gap = (0..dims.len())
                .map(|k| (centre(*a, k) - centre(*b, k)).powi(2))
                .sum::<f64>()
                .sqrt();
            if gap >= a.radius() + b.radius() {
                return true;
            }
        }
    }
    false
}

/// The pieces of `leaves` over `dims` (`None`: a moving ball and no state to place it).
pub fn pieces(leaves: &[&Predicate], dims: &[usize], s: Option<&[f64]>) -> Option<Vec<Piece>> {
    let mut out = Vec::with_capacity(leaves.len());
    for leaf in leaves {
        if let Some(p) = piece(leaf, dims, s)? {
            out.push(p);
        }
    }
    Some(out)
}

/// The deepest point of the intersection of `pieces` and its depth,
/// `argmax_x min_i rho_i(x)`; `None` without a ball (the depth may be unbounded) or when the
/// solver fails. Goals inside walls, straddling one wall or overlapping another goal are
/// answered in closed form ([`closed_form`]); the rest is the cone program.
pub fn deepest_point(pieces: &[Piece]) -> Option<(Vec<f64>, f64)> {
    closed_form(pieces).or_else(|| cone_program(pieces))
}

/// The deepest point of one or two balls and half-spaces in closed form, or `None` when none
/// applies (the cone program decides). Dropping pieces can only raise the optimum, so the
/// optimum of a subset of the pieces at which every other piece is at least as robust is the
/// optimum of all. The subsets tried, each solved exactly:
/// - one ball: its centre, depth `r` (nothing is deeper than a ball's own centre);
/// - a ball and a half-space `w . x + b` (value `a` at the centre): from the centre along
///   `w`, where the ball's `r - s` meets the half-space's `a + s |w|`,
///   `s = (r - a) / (1 + |w|)` (moving off that line only lowers the ball's robustness);
/// - two balls: on the segment between the centres, where `r1 - s` meets `r2 - (d - s)`,
///   `s = (r1 - r2 + d) / 2`, depth `(r1 + r2 - d) / 2` (no point does better, by the
///   triangle inequality).
pub fn closed_form(pieces: &[Piece]) -> Option<(Vec<f64>, f64)> {
    let mut balls: SmallVec<[(&[f64], f64); 2]> = SmallVec::new();
    for p in pieces {
        if let Piece::Ball { centre, radius } = p {
            if balls.len() == 2 {
                return None;
            }
            balls.push((centre, *radius));
        }
    }
    let dim = balls.first()?.0.len();
    if balls.iter().any(|(c, _)| c.len() != dim) {
        return None;
    }
    // A subset's optimum `x` of depth `t` is the optimum of all when no piece is less robust.
    let optimal = |x: Vec<f64>, t: f64| {
        let depth = pieces
            .iter()
            .map(|p| p.value(&x))
            .fold(f64::INFINITY, f64::min);
        (depth >= t - 1e-12 * (1.0 + t.abs())).then_some((x, depth))
    };
    for &(centre, radius) in &balls {
        if let Some(found) = optimal(centre.to_vec(), radius) {
            return Some(found);
        }
    }
    for &(centre, radius) in &balls {
        for p in pieces {
            let Piece::Halfspace { w, .. } = p else {
                continue;
            };
            let a = p.value(centre);
            let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt();
            if a >= radius || norm == 0.0 || !norm.is_finite() || w.len() != dim {
                continue;
            }
            let s = (radius - a) / (1.0 + norm);
            let x = centre
                .iter()
                .zip(w)
                .map(|(c, wi)| c + s * wi / norm)
                .collect();
            if let Some(found) = optimal(x, radius - s) {
                return Some(found);
            }
        }
    }
    if let [(c1, r1), (c2, r2)] = balls[..] {
        let d = c1
            .iter()
            .zip(c2)
            .map(|(a, b)| (b - a) * (b - a))
            .sum::<f64>()
            .sqrt();
        if d > 0.0 {
            // Past the segment's ends one ball holds the other's centre: tried above.
            let s = ((r1 - r2 + d) / 2.0).clamp(0.0, d);
            let x = c1
                .iter()
                .zip(c2)
                .map(|(a, b)| a + s * (b - a) / d)
                .collect();
            if let Some(found) = optimal(x, (r1 + r2 - d) / 2.0) {
                return Some(found);
            }
        }
    }
    None
}

/// The deepest point by the cone program (Clarabel), for any pieces with a ball.
pub fn cone_program(pieces: &[Piece]) -> Option<(Vec<f64>, f64)> {
    if !pieces.iter().any(|p| matches!(p, Piece::Ball { .. })) {
        return None;
    }
    let d = pieces.iter().find_map(|p| match p {
        Piece::Ball { centre, .. } => Some(centre.len()),
        _ => None,
    })?;
    // Variables z = (x, t); minimise -t subject to, per ball, (r - t, x - c) in the second-order
    // cone, and per half-space w . x + b - t >= 0. Clarabel's form: A z + s = b, s in K.
    let n = d + 1;
    let mut rows: Vec<(Vec<f64>, f64)> = Vec::new(); // (row of A, b)
    let mut cones = Vec::new();
    let mut halfspaces = 0;
    for p in pieces {
        if let Piece::Halfspace { w, b } = p {
            let mut a: Vec<f64> = w.iter().map(|v| -v).collect();
            a.push(1.0);
            rows.push((a, *b));
            halfspaces += 1;
        }
    }
    if halfspaces > 0 {
        cones.push(NonnegativeConeT(halfspaces));
    }
    for p in pieces {
        if let Piece::Ball { centre, radius } = p {
            let mut a = vec![0.0; n];
            a[d] = 1.0;
            rows.push((a, *radius));
            for (k, c) in centre.iter().enumerate() {
                let mut a = vec![0.0; n];
                a[k] = -1.0;
                rows.push((a, -c));
            }
            cones.push(SecondOrderConeT(d + 1));
        }
    }
    let m = rows.len();
    let mut dense = vec![vec![0.0; n]; m];
    for (i, (a, _)) in rows.iter().enumerate() {
        dense[i].copy_from_slice(a);
    }
    let a = CscMatrix::from(&dense);
    let b: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let p = CscMatrix::zeros((n, n));
    let mut q = vec![0.0; n];
    q[d] = -1.0;
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .build()
        .ok()?;
    let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings).ok()?;
    solver.solve();
    if !matches!(
        solver.solution.status,
        SolverStatus::Solved | SolverStatus::AlmostSolved
    ) {
        return None;
    }
    let z = &solver.solution.x;
    let x = z[..d].to_vec();
    // The depth at the returned point, exactly (not the solver's t).
    let depth = pieces
        .iter()
        .map(|p| p.value(&x))
        .fold(f64::INFINITY, f64::min);
    Some((x, depth))
}

/// Whether the atoms' regions can hold at one point, per pair: `Some(false)` when every
/// alternative pair is geometrically disjoint, `Some(true)` when one has a common interior
/// point, `None` when the geometry does not say (moving regions, no ball, other dimensions).
pub fn can_hold_together(a: &Predicate, b: &Predicate) -> Option<bool> {
    let (alts_a, alts_b) = (alternatives(a)?, alternatives(b)?);
    let joint = product(&alts_a, &alts_b)?;
    region_nonempty(&joint)
}

/// Whether some alternative of `alts` (a DNF of leaves) has a common interior point; `None`
/// when the geometry does not say for some alternative that is not known empty.
pub fn region_nonempty(alts: &[Vec<&Predicate>]) -> Option<bool> {
    let mut unknown = false;
    for leaves in alts {
        let Some(dims) = goal_dims(leaves) else {
            unknown = true;
            continue;
        };
        // Every leaf must live in the goal space, fixed, for the answer to be exact.
        let mut all = true;
        let mut placed = Vec::with_capacity(leaves.len());
        for leaf in leaves {
            match piece(leaf, dims, None) {
                Some(Some(p)) => placed.push(p),
                _ => all = false,
            }
        }
        match deepest_point(&placed) {
            Some((_, depth)) if depth > EMPTY_DEPTH => {
                if all {
                    return Some(true);
                }
                unknown = true;
            }
            // The known pieces alone are disjoint: so is the whole alternative.
            Some(_) => {}
            None => unknown = true,
        }
    }
    if unknown {
        None
    } else {
        Some(false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ball(c: [f64; 2], r: f64) -> Piece {
        Piece::Ball {
            centre: c.to_vec(),
            radius: r,
        }
    }

    /// Brute-force depth over a fine grid around the pieces.
    fn grid_depth(pieces: &[Piece]) -> f64 {
        let mut best = f64::NEG_INFINITY;
        let steps = 400;
        for i in 0..=steps {
            for j in 0..=steps {
                let x = [
                    -3.0 + 6.0 * i as f64 / steps as f64,
                    -3.0 + 6.0 * j as f64 / steps as f64,
                ];
                let v = pieces
                    .iter()
                    .map(|p| p.value(&x))
                    .fold(f64::INFINITY, f64::min);
                best = best.max(v);
            }
        }
        best
    }

    proptest::proptest! {
        #![proptest_config(crate::tests_support::seeded(40))]

        /// The solver's depth is at least the grid's (it is the maximum) and within the grid's
        /// resolution of it; the point returned attains it.
        #[test]
        fn deepest_point_matches_brute_force(
            discs in proptest::collection::vec((-1.5..1.5f64, -1.5..1.5f64, 0.1..1.2f64), 1..4),
            half in proptest::option::of((-1.0..1.0f64, -1.0..1.0f64, -0.5..1.5f64)),
        ) {
            let mut pieces: Vec<Piece> = discs.iter().map(|&(x, y, r)| ball([x, y], r)).collect();
            if let Some((a, b, c)) = half {
                proptest::prop_assume!(a.abs() + b.abs() > 0.1);
                pieces.push(Piece::Halfspace { w: vec![a, b], b: c });
            }
            let (x, depth) = deepest_point(&pieces).expect("solved");
            let grid = grid_depth(&pieces);
            let exact = pieces.iter().map(|p| p.value(&x)).fold(f64::INFINITY, f64::min);
            proptest::prop_assert!((exact - depth).abs() < 1e-12);
            proptest::prop_assert!(depth >= grid - 1e-6, "{depth} < grid {grid}");
            // The grid spacing is 0.015; every piece is 1-Lipschitz up to |w| <= 1.42.
            proptest::prop_assert!(depth <= grid + 0.015, "{depth} vs grid {grid}");
        }
    }

    proptest::proptest! {
        #![proptest_config(crate::tests_support::seeded(200))]

        /// The closed-form separation never calls a region empty that the cone program finds
        /// room in.
        #[test]
        fn separation_agrees_with_the_cone_program(
            discs in proptest::collection::vec((-2.0..2.0f64, -2.0..2.0f64, 0.1..1.0f64), 1..3),
            half in proptest::option::of((-1.5..1.5f64, -1.5..1.5f64, -2.0..2.0f64)),
        ) {
            // Moving discs: centres read from s[2..], goal space s[0..2].
            let mut s = vec![0.0; 2];
            let mut leaves = Vec::new();
            for (k, &(x, y, r)) in discs.iter().enumerate() {
                s.extend([x, y]);
                let dims = vec![2 + 2 * k, 3 + 2 * k];
                leaves.push(Predicate::ball(vec![0, 1], r, Center::Dims(dims)).unwrap());
            }
            if let Some((a, b, c)) = half {
                proptest::prop_assume!(a.abs() + b.abs() > 0.1);
                let mut w = vec![0.0; s.len()];
                w[0] = a;
                w[1] = b;
                leaves.push(Predicate::halfspace(w, c).unwrap());
            }
            let refs: Vec<&Predicate> = leaves.iter().collect();
            let pieces = pieces(&refs, &[0, 1], Some(&s)).expect("pieces");
            let (_, depth) = deepest_point(&pieces).expect("solved");
            if separated(&leaves, &[0, 1], &s) {
                proptest::prop_assert!(depth <= 1e-9, "separated but depth {depth}");
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(crate::tests_support::seeded(400))]

        /// Where the closed form answers (one or two balls, up to three half-spaces), it finds
        /// the cone program's depth, and its point is that deep.
        #[test]
        fn the_closed_form_agrees_with_the_cone_program(
            discs in proptest::collection::vec((-2.0..2.0f64, -2.0..2.0f64, 0.1..1.5f64), 1..3),
            walls in proptest::collection::vec((-1.5..1.5f64, -1.5..1.5f64, -2.0..2.0f64), 0..4),
        ) {
            let mut pieces: Vec<Piece> = discs
                .iter()
                .map(|&(x, y, r)| Piece::Ball { centre: vec![x, y], radius: r })
                .collect();
            for &(a, b, c) in &walls {
                proptest::prop_assume!(a.abs() + b.abs() > 0.1);
                pieces.push(Piece::Halfspace { w: vec![a, b], b: c });
            }
            let (x, depth) = cone_program(&pieces).expect("solved");
            let exact = pieces.iter().map(|p| p.value(&x)).fold(f64::INFINITY, f64::min);
            proptest::prop_assert!((exact - depth).abs() < 1e-12);
            if let Some((y, closed)) = closed_form(&pieces) {
                let at = pieces.iter().map(|p| p.value(&y)).fold(f64::INFINITY, f64::min);
                proptest::prop_assert!((at - closed).abs() < 1e-12);
                proptest::prop_assert!((closed - depth).abs() < 1e-6, "{closed} vs {depth}");
            }
        }
    }

    #[test]
    fn a_goal_straddling_one_wall_of_a_channel_has_a_closed_form() {
        // The channel |x - y| < 1.5 and a goal disc of radius 0.5 whose centre is 1.3 across
        // the axis: it sticks out of the wall -x + y + 1.5 > 0.
        let walls = [
            Piece::Halfspace {
                w: vec![1.0, -1.0],
                b: 1.5,
            },
            Piece::Halfspace {
                w: vec![-1.0, 1.0],
                b: 1.5,
            },
        ];
        let ball = Piece::Ball {
            centre: vec![2.0, 3.3],
            radius: 0.5,
        };
        let pieces = [ball, walls[0].clone(), walls[1].clone()];
        let (x, depth) = closed_form(&pieces).expect("a closed form");
        let (y, solved) = cone_program(&pieces).expect("solved");
        assert!((depth - solved).abs() < 1e-7, "{depth} vs {solved}");
        assert!((x[0] - y[0]).abs() < 1e-6 && (x[1] - y[1]).abs() < 1e-6);
        // A channel narrower than the ball, with the ball across both walls: no closed form.
        let narrow = [
            Piece::Ball {
                centre: vec![0.0, 0.0],
                radius: 2.0,
            },
            Piece::Halfspace {
                w: vec![1.0, -1.0],
                b: 0.2,
            },
            Piece::Halfspace {
                w: vec![-1.0, 1.0],
                b: 0.2,
            },
        ];
        assert!(closed_form(&narrow).is_none());
        assert!(cone_program(&narrow).is_some());
    }

    #[test]
    fn separated_pieces_are_found_in_closed_form() {
        let wall = Predicate::halfspace(vec![1.0, -1.0, 0.0, 0.0], 1.5).unwrap();
        let disc = || Predicate::ball(vec![0, 1], 0.5, Center::Dims(vec![2, 3])).unwrap();
        // A goal disc wholly outside the channel wall x - y + 1.5 > 0 (centre 1.66 beyond it).
        let outside = [0.0, 0.0, 0.0, 3.9];
        assert!(separated(&[disc(), wall.clone()], &[0, 1], &outside));
        // Straddling the wall: not separated (the cone program decides).
        let straddling = [0.0, 0.0, 0.0, 1.8];
        assert!(!separated(&[disc(), wall], &[0, 1], &straddling));
        let a = Predicate::ball(vec![0, 1], 0.3, Center::Fixed(vec![0.0, 0.0])).unwrap();
        let b = Predicate::ball(vec![0, 1], 0.3, Center::Fixed(vec![0.6, 0.0])).unwrap();
        let c = Predicate::ball(vec![0, 1], 0.3, Center::Fixed(vec![0.5, 0.0])).unwrap();
        assert!(separated(&[a.clone(), b], &[0, 1], &[0.0, 0.0]));
        assert!(!separated(&[a, c], &[0, 1], &[0.0, 0.0]));
    }

    #[test]
    fn a_ball_deep_inside_its_half_spaces_has_its_centre_as_deepest_point() {
        let inside = [
            ball([1.0, 1.0], 0.5),
            Piece::Halfspace {
                w: vec![1.0, -1.0],
                b: 1.5,
            },
        ];
        assert_eq!(deepest_point(&inside), Some((vec![1.0, 1.0], 0.5)));
        // Near the wall the deepest point moves away from it (solved, not the centre).
        let near = [
            ball([1.0, 1.0], 0.5),
            Piece::Halfspace {
                w: vec![1.0, 0.0],
                b: -0.8,
            },
        ];
        let (x, depth) = deepest_point(&near).unwrap();
        assert!(x[0] > 1.0 && depth < 0.5 && depth > 0.0, "{x:?} {depth}");
    }

    #[test]
    fn the_allocation_free_centre_agrees_with_the_solve() {
        // A moving goal disc (centre in s[2..4]) inside a wall x - y + 1.5 > 0, and near it.
        let goal = Predicate::ball(vec![0, 1], 0.5, Center::Dims(vec![2, 3])).unwrap();
        let wall = Predicate::halfspace(vec![1.0, -1.0, 0.0, 0.0], 1.5).unwrap();
        let leaves = [goal, wall];
        let refs: Vec<&Predicate> = leaves.iter().collect();
        let mut out = Vec::new();
        for (centre, fast) in [([2.0, 2.0], true), ([0.0, 1.2], false)] {
            let s = [0.0, 0.0, centre[0], centre[1]];
            assert_eq!(centre_if_deepest(&leaves, &[0, 1], &s, &mut out), fast);
            let (x, _) = deepest_point(&pieces(&refs, &[0, 1], Some(&s)).unwrap()).unwrap();
            if fast {
                assert_eq!(out, x);
            } else {
                assert!(x != centre.to_vec());
            }
        }
    }

    #[test]
    fn two_discs_deepest_point_is_on_the_segment() {
        // Blue (0.1, 0) r 0.8 and aqua (0.8, 0.2) r 0.3: the mean of the centres is outside aqua.
        let pieces = [ball([0.1, 0.0], 0.8), ball([0.8, 0.2], 0.3)];
        let (x, depth) = deepest_point(&pieces).unwrap();
        assert!(depth > 0.0 && pieces.iter().all(|p| p.value(&x) >= depth - 1e-9));
        // Aqua lies inside blue's disc (|c| = 0.728 + 0.3 > 0.8 just): depth below aqua's radius.
        assert!(depth <= 0.3 + 1e-9);
    }

    #[test]
    fn disjoint_discs_are_empty() {
        let a = Predicate::ball(vec![0, 1], 0.3, Center::Fixed(vec![0.0, 0.0])).unwrap();
        let b = Predicate::ball(vec![0, 1], 0.3, Center::Fixed(vec![1.0, 0.0])).unwrap();
        let c = Predicate::ball(vec![0, 1], 0.8, Center::Fixed(vec![0.5, 0.0])).unwrap();
        assert_eq!(can_hold_together(&a, &b), Some(false));
        assert_eq!(can_hold_together(&a, &c), Some(true));
        let ab = Predicate::union(vec![a.clone(), b.clone()]).unwrap();
        assert_eq!(can_hold_together(&ab, &c), Some(true));
        let far = Predicate::ball(vec![0, 1], 0.1, Center::Fixed(vec![5.0, 5.0])).unwrap();
        assert_eq!(can_hold_together(&ab, &far), Some(false));
        // Touching discs share no interior point (atoms hold strictly inside).
        let touch = Predicate::ball(vec![0, 1], 0.7, Center::Fixed(vec![1.0, 0.0])).unwrap();
        assert_eq!(can_hold_together(&a, &touch), Some(false));
        let moving = Predicate::ball(vec![0, 1], 0.3, Center::Dims(vec![2, 3])).unwrap();
        assert_eq!(can_hold_together(&a, &moving), None);
    }
}
