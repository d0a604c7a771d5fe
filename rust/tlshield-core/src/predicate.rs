//! State predicates: real-valued functions of the full state vector whose sign says whether an
//! atom holds (`> 0` holds). Each has an exact value and gradient.
//!
//! Regions compose: a [`Predicate::Union`] holds where any part holds (robustness: the max of
//! the parts'), an [`Predicate::Intersection`] where every part holds (the min). Their gradient
//! and Hessian are those of the part that attains the max (min), the first on ties: exact
//! wherever that part is unique, and a valid one-sided choice on the seams.

use crate::check::StateLen;
use crate::error::{InputError, SpecError};

/// `rho(s) = w . s + b`: a half-space of the state space (the paper's channel constraints).
#[derive(Debug, Clone, PartialEq)]
pub struct Halfspace {
    w: Vec<f64>,
    b: f64,
    /// The non-zero entries of `w` as (dimension, weight): most constraints read few dimensions.
    terms: Vec<(usize, f64)>,
}

/// Where a [`Ball`]'s centre comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Center {
    /// A fixed point.
    Fixed(Vec<f64>),
    /// Read from these state dimensions (goals or obstacles that live in the state).
    Dims(Vec<usize>),
}

/// A point of the robot's body: `(along, across)` in the frame of the heading `s[heading]`.
/// The ball then holds the body point `s[pos] + R(s[heading]) (along, across)`, not `s[pos]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Offset {
    /// The state dimension of the heading (radians).
    pub heading: usize,
    /// Metres ahead of `s[pos]` along the heading.
    pub along: f64,
    /// Metres to the left of the heading.
    pub across: f64,
}

impl Offset {
    /// `R(theta) (along, across)`: where the body point sits relative to `s[pos]`.
    #[inline]
    fn rotated(&self, s: &[f64]) -> [f64; 2] {
        let (sin, cos) = s[self.heading].sin_cos();
        [
            self.along * cos - self.across * sin,
            self.along * sin + self.across * cos,
        ]
    }

    /// The distance from `s[pos]` to the body point (the same at every heading).
    pub fn length(&self) -> f64 {
        self.along.hypot(self.across)
    }
}

/// `rho(s) = radius - |p(s) - c|`: inside a ball around a fixed or state-dependent centre,
/// where `p(s)` is `s[pos]`, or a point of the body (`offset`) for barriers that protect more
/// than the reference point.
#[derive(Debug, Clone, PartialEq)]
pub struct Ball {
    pos: Vec<usize>,
    radius: f64,
    center: Center,
    offset: Option<Offset>,
}

/// A state predicate.
#[derive(Debug, Clone, PartialEq)]
pub enum Predicate {
    /// See [`Halfspace`].
    Halfspace(Halfspace),
    /// See [`Ball`].
    Ball(Ball),
    /// Holds where any part holds (a red region made of two discs).
    Union(Vec<Predicate>),
    /// Holds where every part holds.
    Intersection(Vec<Predicate>),
}

/// A predicate's parameters must be finite ([`crate::check::check_finite`], in the words of a
/// predicate's error).
fn finite(what: &str, values: &[f64]) -> Result<(), SpecError> {
    crate::check::check_finite(what, values, values.len()).map_err(|err| match err {
        InputError::NonFinite { what, value } => {
            SpecError::InvalidPredicate(format!("{what} is {value} (must be finite)"))
        }
        other => SpecError::InvalidPredicate(other.to_string()),
    })
}

fn check_distinct(what: &str, dims: &[usize]) -> Result<(), SpecError> {
    for (i, d) in dims.iter().enumerate() {
        if dims[..i].contains(d) {
            return Err(SpecError::InvalidPredicate(format!(
                "{what} lists dimension {d} twice"
            )));
        }
    }
    Ok(())
}

impl Predicate {
    /// A half-space predicate `w . s + b`. `w` must be non-empty and finite, `b` finite.
    pub fn halfspace(w: Vec<f64>, b: f64) -> Result<Self, SpecError> {
        if w.is_empty() {
            return Err(SpecError::InvalidPredicate(
                "Halfspace w must have at least one entry".into(),
            ));
        }
        finite("Halfspace w", &w)?;
        finite("Halfspace b", &[b])?;
        let terms = w
            .iter()
            .enumerate()
            .filter(|(_, v)| **v != 0.0)
            .map(|(i, v)| (i, *v))
            .collect();
        Ok(Predicate::Halfspace(Halfspace { w, b, terms }))
    }

    /// A ball predicate `radius - |s[pos] - c|`. `pos` must be non-empty with distinct
    /// dimensions, `radius` finite and non-negative, and the centre as long as `pos` (a state
    /// centre must not share dimensions with `pos`).
    pub fn ball(pos: Vec<usize>, radius: f64, center: Center) -> Result<Self, SpecError> {
        if pos.is_empty() {
            return Err(SpecError::InvalidPredicate(
                "Ball pos must name at least one dimension".into(),
            ));
        }
        check_distinct("Ball pos", &pos)?;
        if !radius.is_finite() || radius < 0.0 {
            return Err(SpecError::InvalidPredicate(format!(
                "Ball radius must be finite and >= 0, got {radius}"
            )));
        }
        let center_len = match &center {
            Center::Fixed(c) => {
                finite("Ball center", c)?;
                c.len()
            }
            Center::Dims(d) => {
                check_distinct("Ball center_dims", d)?;
                if let Some(shared) = d.iter().find(|x| pos.contains(x)) {
                    return Err(SpecError::InvalidPredicate(format!(
                        "Ball center_dims shares dimension {shared} with pos"
                    )));
                }
                d.len()
            }
        };
        if center_len != pos.len() {
            return Err(SpecError::InvalidPredicate(format!(
                "Ball centre has {center_len} entries but pos has {}",
                pos.len()
            )));
        }
        Ok(Predicate::Ball(Ball {
            pos,
            radius,
            center,
            offset: None,
        }))
    }

    /// A ball that holds a point of the body, `offset` from `s[pos]` in the frame of the
    /// heading (see [`Offset`]): as [`Predicate::ball`], with `pos` two-dimensional, the
    /// offset finite, and the heading a dimension apart from `pos` and a state centre.
    pub fn body_ball(
        pos: Vec<usize>,
        radius: f64,
        center: Center,
        offset: Offset,
    ) -> Result<Self, SpecError> {
        let Predicate::Ball(mut ball) = Predicate::ball(pos, radius, center)? else {
            unreachable!("Predicate::ball builds a ball")
        };
        if ball.pos.len() != 2 {
            return Err(SpecError::InvalidPredicate(format!(
                "Ball offset needs a planar pos (2 dimensions), got {}",
                ball.pos.len()
            )));
        }
        finite("Ball offset", &[offset.along, offset.across])?;
        let centre_dims = match &ball.center {
            Center::Dims(d) => d.as_slice(),
            Center::Fixed(_) => &[],
        };
        if ball.pos.contains(&offset.heading) || centre_dims.contains(&offset.heading) {
            return Err(SpecError::InvalidPredicate(format!(
                "Ball heading dimension {} is also a pos or center_dims dimension",
                offset.heading
            )));
        }
        ball.offset = Some(offset);
        Ok(Predicate::Ball(ball))
    }

    /// A union of regions: holds where any part holds. `parts` must be non-empty, and parts
    /// that fix the state length must agree on it.
    pub fn union(parts: Vec<Predicate>) -> Result<Self, SpecError> {
        check_parts("Union", &parts)?;
        Ok(Predicate::Union(parts))
    }

    /// An intersection of regions: holds where every part holds. `parts` as for
    /// [`Predicate::union`].
    pub fn intersection(parts: Vec<Predicate>) -> Result<Self, SpecError> {
        check_parts("Intersection", &parts)?;
        Ok(Predicate::Intersection(parts))
    }

    /// The parts of a union or intersection (empty for a half-space or ball).
    pub fn parts(&self) -> &[Predicate] {
        match self {
            Predicate::Union(p) | Predicate::Intersection(p) => p,
            _ => &[],
        }
    }

    /// The exact state length this predicate needs, if it fixes one (a half-space does).
    pub fn exact_dim(&self) -> Option<usize> {
        match self {
            Predicate::Halfspace(h) => Some(h.w.len()),
            Predicate::Ball(_) => None,
            Predicate::Union(p) | Predicate::Intersection(p) => {
                p.iter().find_map(Predicate::exact_dim)
            }
        }
    }

    /// The part that decides the value at `s`: the first largest (union) or smallest
    /// (intersection) part, recursively down to a half-space or ball.
    fn active(&self, s: &[f64]) -> &Predicate {
        match self {
            Predicate::Union(parts) | Predicate::Intersection(parts) => {
                let union = matches!(self, Predicate::Union(_));
                let mut best = &parts[0];
                let mut best_value = best.value(s);
                for p in &parts[1..] {
                    let v = p.value(s);
                    if (union && v > best_value) || (!union && v < best_value) {
                        best = p;
                        best_value = v;
                    }
                }
                best.active(s)
            }
            leaf => leaf,
        }
    }

    /// The smallest state length this predicate can read (largest index used + 1).
    pub fn min_dim(&self) -> usize {
        match self {
            Predicate::Halfspace(h) => h.w.len(),
            Predicate::Ball(b) => {
                let center_max = match &b.center {
                    Center::Fixed(_) => 0,
                    Center::Dims(d) => d.iter().copied().max().map_or(0, |m| m + 1),
                };
                let heading_max = b.offset.map_or(0, |o| o.heading + 1);
                b.pos
                    .iter()
                    .copied()
                    .max()
                    .map_or(0, |m| m + 1)
                    .max(center_max)
                    .max(heading_max)
            }
            Predicate::Union(p) | Predicate::Intersection(p) => {
                p.iter().map(Predicate::min_dim).max().unwrap_or(0)
            }
        }
    }

    /// Checks that a state of length `n` can be read by this predicate.
    pub fn check_dim(&self, n: usize) -> Result<(), InputError> {
        crate::check::check_state_len("state", n, &[self.state_len()])
    }

    /// What this predicate needs of a state's length (see [`crate::check::check_state_len`]).
    pub(crate) fn state_len(&self) -> StateLen {
        match self.exact_dim() {
            Some(d) => StateLen::new(d, true),
            None => StateLen::new(self.min_dim(), false),
        }
    }

    /// Robustness at state `s` after checking its length and that it is finite.
    pub fn robustness(&self, s: &[f64]) -> Result<f64, InputError> {
        self.check_dim(s.len())?;
        crate::check::check_finite("s", s, s.len())?;
        Ok(self.value(s))
    }

    /// Gradient at state `s` after checking its length and that it is finite.
    pub fn gradient(&self, s: &[f64]) -> Result<Vec<f64>, InputError> {
        self.check_dim(s.len())?;
        crate::check::check_finite("s", s, s.len())?;
        let mut out = vec![0.0; s.len()];
        self.gradient_into(s, &mut out);
        Ok(out)
    }

    /// Robustness at state `s`. The caller guarantees `check_dim(s.len())`.
    #[inline]
    pub fn value(&self, s: &[f64]) -> f64 {
        match self {
            Predicate::Halfspace(h) => h.terms.iter().map(|&(i, w)| w * s[i]).sum::<f64>() + h.b,
            Predicate::Ball(b) => b.radius - b.distance(s),
            Predicate::Union(p) => p
                .iter()
                .map(|x| x.value(s))
                .fold(f64::NEG_INFINITY, f64::max),
            Predicate::Intersection(p) => {
                p.iter().map(|x| x.value(s)).fold(f64::INFINITY, f64::min)
            }
        }
    }

    /// Robustness at every state of a row-major trajectory (`out.len()` states of `dim` values),
    /// with the predicate's shape resolved once outside the loop over time.
    pub fn values_into(&self, states: &[f64], dim: usize, out: &mut [f64]) {
        let rows = states.chunks_exact(dim);
        match self {
            Predicate::Halfspace(h) => match h.terms.as_slice() {
                [(i, wi), (j, wj)] => {
                    for (o, s) in out.iter_mut().zip(rows) {
                        *o = wi * s[*i] + wj * s[*j] + h.b;
                    }
                }
                _ => {
                    for (o, s) in out.iter_mut().zip(rows) {
                        *o = self.value(s);
                    }
                }
            },
            Predicate::Ball(b) => match (b.pos.as_slice(), &b.center) {
                _ if b.offset.is_some() => {
                    for (o, s) in out.iter_mut().zip(rows) {
                        *o = self.value(s);
                    }
                }
                ([px, py], Center::Dims(c)) => {
                    let (cx, cy) = (c[0], c[1]);
                    for (o, s) in out.iter_mut().zip(rows) {
                        let (dx, dy) = (s[*px] - s[cx], s[*py] - s[cy]);
                        *o = b.radius - norm2(dx, dy);
                    }
                }
                ([px, py], Center::Fixed(c)) => {
                    let (cx, cy) = (c[0], c[1]);
                    for (o, s) in out.iter_mut().zip(rows) {
                        let (dx, dy) = (s[*px] - cx, s[*py] - cy);
                        *o = b.radius - norm2(dx, dy);
                    }
                }
                _ => {
                    for (o, s) in out.iter_mut().zip(rows) {
                        *o = self.value(s);
                    }
                }
            },
            Predicate::Union(_) | Predicate::Intersection(_) => {
                for (o, s) in out.iter_mut().zip(rows) {
                    *o = self.value(s);
                }
            }
        }
    }

    /// Whether the value depends on state dimension `d` (its gradient may be non-zero there).
    pub fn reads(&self, d: usize) -> bool {
        match self {
            Predicate::Halfspace(h) => h.terms.iter().any(|&(i, _)| i == d),
            Predicate::Ball(b) => {
                b.pos.contains(&d)
                    || matches!(&b.center, Center::Dims(c) if c.contains(&d))
                    || b.offset.is_some_and(|o| o.heading == d)
            }
            Predicate::Union(p) | Predicate::Intersection(p) => p.iter().any(|x| x.reads(d)),
        }
    }

    /// A bound on how fast the value changes along state dimension `d`, everywhere:
    /// `|value(s + t e_d) - value(s)| <= lipschitz(d) |t|` (0 where it does not read `d`). A
    /// ball's distance moves at most as fast as its difference vector, one per place `d` enters
    /// it (and the body point's lever arm through the heading); a union's or intersection's
    /// max or min no faster than its fastest part.
    pub fn lipschitz(&self, d: usize) -> f64 {
        match self {
            Predicate::Halfspace(h) => h
                .terms
                .iter()
                .filter(|&&(i, _)| i == d)
                .map(|&(_, w)| w.abs())
                .sum(),
            Predicate::Ball(b) => {
                let centre = match &b.center {
                    Center::Dims(c) => c.iter().filter(|&&i| i == d).count(),
                    Center::Fixed(_) => 0,
                };
                let lever = b
                    .offset
                    .filter(|o| o.heading == d)
                    .map_or(0.0, |o| o.along.hypot(o.across));
                (b.pos.iter().filter(|&&i| i == d).count() + centre) as f64 + lever
            }
            Predicate::Union(p) | Predicate::Intersection(p) => {
                p.iter().map(|x| x.lipschitz(d)).fold(0.0, f64::max)
            }
        }
    }

    /// `out = H(s) v`: the Hessian of [`Predicate::value`] at `s` times `v` (lengths n), for
    /// second-order barrier rows. Zero for a half-space. For a ball, `value = r - |d|` with
    /// `d = s[pos] - c(s)` linear in `s`, so `H = -J^T (I - u u^T) J / |d|` (`u = d / |d|`,
    /// `J` the map `s -> d`); zero at the centre, where it is undefined (never NaN). A body
    /// point (`Offset`) adds the heading's column `w = dR/dtheta o` to `J` and the curvature
    /// term `(u . R o) v_theta` on the heading (`d^2 d / dtheta^2 = -R o`).
    pub fn hessian_times(&self, s: &[f64], v: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        let Predicate::Ball(b) = self.active(s) else {
            return;
        };
        let ro = b.shift(s);
        let dist = b.distance_shifted(s, &ro);
        if dist == 0.0 {
            return;
        }
        // dR/dtheta o = R(theta + pi/2) o.
        let w = [-ro[1], ro[0]];
        let v_heading = b.offset.map_or(0.0, |o| v[o.heading]);
        // J v and u . J v.
        let jv = |k: usize| {
            let turn = if b.offset.is_some() {
                w[k] * v_heading
            } else {
                0.0
            };
            turn + match &b.center {
                Center::Fixed(_) => v[b.pos[k]],
                Center::Dims(c) => v[b.pos[k]] - v[c[k]],
            }
        };
        let unit = |k: usize| b.diff(s, k, &ro) / dist;
        let along: f64 = (0..b.pos.len()).map(|k| unit(k) * jv(k)).sum();
        for k in 0..b.pos.len() {
            let z = (jv(k) - unit(k) * along) / dist;
            out[b.pos[k]] -= z;
            if let Center::Dims(c) = &b.center {
                out[c[k]] += z;
            }
            if let Some(o) = b.offset {
                out[o.heading] -= w[k] * z;
            }
        }
        if let Some(o) = b.offset {
            out[o.heading] += (unit(0) * ro[0] + unit(1) * ro[1]) * v_heading;
        }
    }

    /// Gradient of [`Predicate::value`] at `s`, written into `out` (length `s.len()`).
    /// At the centre of a ball the gradient is zero (never NaN).
    pub fn gradient_into(&self, s: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        match self.active(s) {
            Predicate::Halfspace(h) => out[..h.w.len()].copy_from_slice(&h.w),
            Predicate::Ball(b) => {
                let ro = b.shift(s);
                let dist = b.distance_shifted(s, &ro);
                if dist == 0.0 {
                    return;
                }
                for (k, &p) in b.pos.iter().enumerate() {
                    let unit = b.diff(s, k, &ro) / dist;
                    out[p] -= unit;
                    if let Center::Dims(d) = &b.center {
                        out[d[k]] += unit;
                    }
                    if let Some(o) = b.offset {
                        // d p / d theta = R(theta + pi/2) o = (-ro_y, ro_x).
                        out[o.heading] -= unit * if k == 0 { -ro[1] } else { ro[0] };
                    }
                }
            }
            Predicate::Union(_) | Predicate::Intersection(_) => {
                unreachable!("active() returns a half-space or ball")
            }
        }
    }
}

fn check_parts(what: &str, parts: &[Predicate]) -> Result<(), SpecError> {
    if parts.is_empty() {
        return Err(SpecError::InvalidPredicate(format!(
            "{what} needs at least one part"
        )));
    }
    let dims: Vec<usize> = parts.iter().filter_map(Predicate::exact_dim).collect();
    if let Some(d) = dims.iter().find(|&&d| d != dims[0]) {
        return Err(SpecError::InvalidPredicate(format!(
            "{what} parts fix different state lengths ({} and {d})",
            dims[0]
        )));
    }
    Ok(())
}

/// `|(dx, dy)|`: the plain formula, or `hypot` where the squares overflow.
#[inline]
fn norm2(dx: f64, dy: f64) -> f64 {
    let sq = dx * dx + dy * dy;
    if sq.is_finite() {
        sq.sqrt()
    } else {
        dx.hypot(dy)
    }
}

impl Ball {
    #[inline]
    fn center_at(&self, s: &[f64], k: usize) -> f64 {
        match &self.center {
            Center::Fixed(c) => c[k],
            Center::Dims(d) => s[d[k]],
        }
    }

    /// `p(s) - s[pos]` (zero without a body point), worked out once per call: the heading's
    /// sine and cosine.
    #[inline]
    fn shift(&self, s: &[f64]) -> [f64; 2] {
        self.offset.map_or([0.0; 2], |o| o.rotated(s))
    }

    /// Entry `k` of `p(s) - c`: the body point (or `s[pos]`) less the centre, `shift` from
    /// [`Ball::shift`].
    #[inline]
    fn diff(&self, s: &[f64], k: usize, shift: &[f64; 2]) -> f64 {
        let shift = if self.offset.is_some() { shift[k] } else { 0.0 };
        s[self.pos[k]] + shift - self.center_at(s, k)
    }

    /// `|p(s) - c|`, finite for every finite difference (the squares of differences above
    /// ~1e154 overflow, so those are summed rescaled by the largest).
    #[inline]
    fn distance(&self, s: &[f64]) -> f64 {
        self.distance_shifted(s, &self.shift(s))
    }

    /// [`Ball::distance`] with the body point's shift already worked out.
    #[inline]
    fn distance_shifted(&self, s: &[f64], shift: &[f64; 2]) -> f64 {
        let diff = |k: usize| self.diff(s, k, shift);
        let sq: f64 = (0..self.pos.len()).map(|k| diff(k) * diff(k)).sum();
        if sq.is_finite() {
            return sq.sqrt();
        }
        let scale = (0..self.pos.len()).fold(0.0_f64, |a, k| a.max(diff(k).abs()));
        let scaled: f64 = (0..self.pos.len()).map(|k| (diff(k) / scale).powi(2)).sum();
        scale * scaled.sqrt()
    }

    /// State dimensions of the point that must be inside the ball.
    pub fn pos(&self) -> &[usize] {
        &self.pos
    }

    /// The radius.
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// Where the centre comes from.
    pub fn center(&self) -> &Center {
        &self.center
    }

    /// The body point the ball holds, if not `s[pos]` itself.
    pub fn offset(&self) -> Option<Offset> {
        self.offset
    }
}

impl Halfspace {
    /// The normal vector.
    pub fn w(&self) -> &[f64] {
        &self.w
    }

    /// The offset.
    pub fn b(&self) -> f64 {
        self.b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    proptest::proptest! {
        #![proptest_config(crate::tests_support::seeded(300))]

        /// `H v` equals central finite differences of the gradient along `v`.
        #[test]
        fn hessian_times_matches_finite_differences(
            s in proptest::collection::vec(-3.0..3.0f64, 6),
            v in proptest::collection::vec(-2.0..2.0f64, 6),
        ) {
            let predicates = [
                Predicate::ball(vec![0, 1], 0.5, Center::Fixed(vec![0.3, -0.2])).unwrap(),
                Predicate::ball(vec![0, 1], 0.5, Center::Dims(vec![4, 5])).unwrap(),
                Predicate::ball(vec![2], 0.5, Center::Fixed(vec![1.0])).unwrap(),
                Predicate::halfspace(vec![1.0, -1.0, 0.0, 0.0, 0.0, 0.0], 1.5).unwrap(),
                body(Center::Fixed(vec![0.3, -0.2])),
                body(Center::Dims(vec![4, 5])),
            ];
            for p in &predicates {
                if let Predicate::Ball(b) = p {
                    proptest::prop_assume!(b.distance(&s) > 1e-2);
                }
                let h = 1e-6;
                let plus: Vec<f64> = s.iter().zip(&v).map(|(a, b)| a + h * b).collect();
                let minus: Vec<f64> = s.iter().zip(&v).map(|(a, b)| a - h * b).collect();
                let (mut gp, mut gm, mut hv) = (vec![0.0; 6], vec![0.0; 6], vec![0.0; 6]);
                p.gradient_into(&plus, &mut gp);
                p.gradient_into(&minus, &mut gm);
                p.hessian_times(&s, &v, &mut hv);
                for i in 0..6 {
                    let fd = (gp[i] - gm[i]) / (2.0 * h);
                    proptest::prop_assert!((hv[i] - fd).abs() < 1e-5 * (1.0 + fd.abs()), "{p:?} {i}");
                }
                for i in 0..6 {
                    let mut g = vec![0.0; 6];
                    p.gradient_into(&s, &mut g);
                    if !p.reads(i) {
                        proptest::prop_assert_eq!(g[i], 0.0);
                    }
                }
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(crate::tests_support::seeded(300))]

        /// No predicate's value moves along a dimension faster than its `lipschitz` bound (any
        /// step, compounds and body points included), and the bound is 0 off what it reads.
        #[test]
        fn values_move_no_faster_than_the_lipschitz_bound(
            s in proptest::collection::vec(-3.0..3.0f64, 6),
            d in 0..6usize,
            t in -4.0..4.0f64,
        ) {
            let ball = Predicate::ball(vec![0, 1], 0.5, Center::Dims(vec![4, 5])).unwrap();
            let line = Predicate::ball(vec![3], 0.5, Center::Dims(vec![4])).unwrap();
            let wall = Predicate::halfspace(vec![1.0, -2.5, 0.0, 0.0, 0.5, 0.0], 1.5).unwrap();
            let predicates = [
                Predicate::Union(vec![ball.clone(), wall.clone()]),
                Predicate::Intersection(vec![body(Center::Dims(vec![4, 5])), wall.clone()]),
                ball,
                line,
                wall,
                body(Center::Fixed(vec![0.3, -0.2])),
            ];
            let mut moved = s.clone();
            moved[d] += t;
            for p in &predicates {
                let bound = p.lipschitz(d);
                let change = (p.value(&moved) - p.value(&s)).abs();
                proptest::prop_assert!(change <= bound * t.abs() * (1.0 + 1e-12) + 1e-12,
                    "{p:?} d={d}: {change} > {bound} * {t}");
                proptest::prop_assert_eq!(bound == 0.0, !p.reads(d), "{:?} d={}", p, d);
            }
        }
    }

    /// A ball on a body point 1.2 m ahead and 0.4 m left of `s[0..2]`, heading `s[2]`.
    fn body(center: Center) -> Predicate {
        let offset = Offset {
            heading: 2,
            along: 1.2,
            across: 0.4,
        };
        Predicate::body_ball(vec![0, 1], 0.5, center, offset).unwrap()
    }

    proptest::proptest! {
        #![proptest_config(crate::tests_support::seeded(300))]

        /// A body ball's value is the plain ball's at the body point worked out by hand, and
        /// its gradient matches central finite differences of the value.
        #[test]
        fn body_ball_matches_the_point_and_finite_differences(
            s in proptest::collection::vec(-3.0..3.0f64, 6),
        ) {
            let p = body(Center::Dims(vec![4, 5]));
            let q = [
                s[0] + 1.2 * s[2].cos() - 0.4 * s[2].sin(),
                s[1] + 1.2 * s[2].sin() + 0.4 * s[2].cos(),
            ];
            let by_hand = 0.5 - ((q[0] - s[4]).powi(2) + (q[1] - s[5]).powi(2)).sqrt();
            proptest::prop_assert!((p.value(&s) - by_hand).abs() < 1e-12);
            proptest::prop_assume!(by_hand < 0.49);
            let mut g = vec![0.0; 6];
            p.gradient_into(&s, &mut g);
            for i in 0..6 {
                let h = 1e-6;
                let (mut plus, mut minus) = (s.clone(), s.clone());
                plus[i] += h;
                minus[i] -= h;
                let fd = (p.value(&plus) - p.value(&minus)) / (2.0 * h);
                proptest::prop_assert!((g[i] - fd).abs() < 1e-6, "{i}: {} vs {fd}", g[i]);
            }
            proptest::prop_assert!(p.reads(2) && !p.reads(3));
            proptest::prop_assert_eq!(p.min_dim(), 6);
        }
    }

    #[test]
    fn body_ball_settings_are_checked() {
        let offset = |heading| Offset {
            heading,
            along: 1.0,
            across: 0.0,
        };
        let err = |p: Result<Predicate, SpecError>| p.unwrap_err().to_string();
        let fixed = || Center::Fixed(vec![0.0, 0.0]);
        assert!(err(Predicate::body_ball(vec![0, 1], 1.0, fixed(), offset(1))).contains("heading"));
        let moving = Center::Dims(vec![3, 4]);
        assert!(err(Predicate::body_ball(vec![0, 1], 1.0, moving, offset(3))).contains("heading"));
        let line = Center::Fixed(vec![0.0]);
        assert!(err(Predicate::body_ball(vec![0], 1.0, line, offset(2))).contains("planar"));
        let far = Offset {
            along: f64::NAN,
            ..offset(2)
        };
        assert!(err(Predicate::body_ball(vec![0, 1], 1.0, fixed(), far)).contains("offset"));
    }

    #[test]
    fn halfspace_value_and_gradient() {
        let p = Predicate::halfspace(vec![1.0, -1.0], 1.5).unwrap();
        assert_eq!(p.value(&[2.0, 1.0]), 2.5);
        let mut g = [9.0; 2];
        p.gradient_into(&[2.0, 1.0], &mut g);
        assert_eq!(g, [1.0, -1.0]);
    }

    #[test]
    fn ball_with_state_centre_value_and_gradient() {
        let p = Predicate::ball(vec![0, 1], 1.0, Center::Dims(vec![2, 3])).unwrap();
        let s = [3.0, 4.0, 0.0, 0.0];
        assert_eq!(p.value(&s), -4.0);
        let mut g = [0.0; 4];
        p.gradient_into(&s, &mut g);
        assert_eq!(g, [-0.6, -0.8, 0.6, 0.8]);
    }

    #[test]
    fn ball_gradient_at_centre_is_zero() {
        let p = Predicate::ball(vec![0, 1], 1.0, Center::Fixed(vec![1.0, 1.0])).unwrap();
        let mut g = [f64::NAN; 2];
        p.gradient_into(&[1.0, 1.0], &mut g);
        assert_eq!(g, [0.0, 0.0]);
        assert_eq!(p.value(&[1.0, 1.0]), 1.0);
    }

    #[test]
    fn invalid_predicates_are_rejected() {
        crate::tests_support::assert_error(
            Predicate::ball(vec![0], -1.0, Center::Fixed(vec![0.0])),
            "InvalidPredicate",
            "Ball radius",
        );
        crate::tests_support::assert_error(
            Predicate::ball(vec![0], 1.0, Center::Fixed(vec![0.0, 1.0])),
            "InvalidPredicate",
            "Ball centre",
        );
        crate::tests_support::assert_error(
            Predicate::ball(vec![0, 0], 1.0, Center::Fixed(vec![0.0, 1.0])),
            "InvalidPredicate",
            "Ball pos",
        );
        crate::tests_support::assert_error(
            Predicate::ball(vec![0], 1.0, Center::Dims(vec![0])),
            "InvalidPredicate",
            "Ball center_dims",
        );
        crate::tests_support::assert_error(
            Predicate::ball(vec![], 1.0, Center::Fixed(vec![])),
            "InvalidPredicate",
            "Ball pos",
        );
        crate::tests_support::assert_error(
            Predicate::halfspace(vec![], 0.0),
            "InvalidPredicate",
            "Halfspace w",
        );
        crate::tests_support::assert_error(
            Predicate::halfspace(vec![f64::NAN], 0.0),
            "InvalidPredicate",
            "Halfspace w[0]",
        );
        crate::tests_support::assert_error(
            Predicate::halfspace(vec![1.0], f64::INFINITY),
            "InvalidPredicate",
            "Halfspace b[0]",
        );
    }

    #[test]
    fn dimension_checks_name_expected_and_got() {
        let p = Predicate::ball(vec![0, 5], 1.0, Center::Fixed(vec![0.0, 0.0])).unwrap();
        let err = p.check_dim(3).unwrap_err().to_string();
        assert!(err.contains("at least 6") && err.contains("got 3"), "{err}");
        let h = Predicate::halfspace(vec![1.0; 4], 0.0).unwrap();
        assert!(h.check_dim(4).is_ok());
        crate::tests_support::assert_error(h.check_dim(5), "Shape", "state length");
    }
}
