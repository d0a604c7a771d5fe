//! Quantitative (robustness) and Boolean semantics of scTLTL over finite trajectories.
//!
//! The window is CLOSED: a trajectory `s_0..s_T` is read including `s_T`, so `rho > 0` agrees
//! with an automaton that reads every state. (The paper's example `rho(s_0:3, F(s<4))` takes the
//! max over `s_0..s_2`; we take it over `s_0..s_3`.)
//!
//! The formula is compiled once into post-order instructions with shared subformulas merged
//! (an atom used twice is evaluated once). Evaluation is node-major: each instruction fills one
//! array over time, so propositional operators are element-wise loops the compiler vectorises
//! and temporal ones are single backward scans (`F a = max(a, (F a)')`,
//! `a U b = max(b, min(a, (a U b)'))`, `X a = a'`). Buffers live in a reusable [`Scratch`].

use std::collections::HashMap;

use rayon::prelude::*;

use crate::check::{check_finite, first_non_finite};
use crate::error::InputError;
use crate::formula::Formula;
use crate::predicate::Predicate;

/// One instruction of a compiled formula; operands are indices of earlier instructions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Op {
    True,
    False,
    Atom(usize),
    Not(usize),
    And(usize, usize),
    Or(usize, usize),
    Implies(usize, usize),
    Until(usize, usize),
    Eventually(usize),
    Next(usize),
}

/// A formula compiled to post-order instructions (the root is last).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Program {
    ops: Vec<Op>,
    /// Whether each instruction's value is needed at every time step (`false`: only at t = 0,
    /// e.g. the root and `F` directly under a conjunction, which then reduce instead of scan).
    full: Vec<bool>,
}

impl Program {
    pub(crate) fn compile(formula: &Formula) -> Self {
        let mut ops = Vec::new();
        let mut seen = HashMap::new();
        Self::emit(formula, &mut ops, &mut seen);
        // Consumers come after their operands, so one reverse pass settles every need.
        let mut full = vec![false; ops.len()];
        for i in (0..ops.len()).rev() {
            match ops[i] {
                Op::Not(a) => full[a] |= full[i],
                Op::And(a, b) | Op::Or(a, b) | Op::Implies(a, b) => {
                    full[a] |= full[i];
                    full[b] |= full[i];
                }
                Op::Eventually(a) | Op::Next(a) => full[a] = true,
                Op::Until(a, b) => {
                    full[a] = true;
                    full[b] = true;
                }
                Op::True | Op::False | Op::Atom(_) => {}
            }
        }
        Program { ops, full }
    }

    /// Emits `formula` (reusing an identical earlier subformula) and returns its slot.
    fn emit<'f>(
        formula: &'f Formula,
        ops: &mut Vec<Op>,
        seen: &mut HashMap<&'f Formula, usize>,
    ) -> usize {
        if let Some(&slot) = seen.get(formula) {
            return slot;
        }
        let op = match formula {
            Formula::True => Op::True,
            Formula::False => Op::False,
            Formula::Atom(i) => Op::Atom(*i),
            Formula::Not(a) => Op::Not(Self::emit(a, ops, seen)),
            Formula::Eventually(a) => Op::Eventually(Self::emit(a, ops, seen)),
            Formula::Next(a) => Op::Next(Self::emit(a, ops, seen)),
            Formula::Implies(a, b) => {
                let a = Self::emit(a, ops, seen);
                Op::Implies(a, Self::emit(b, ops, seen))
            }
            Formula::Until(a, b) => {
                let a = Self::emit(a, ops, seen);
                Op::Until(a, Self::emit(b, ops, seen))
            }
            Formula::And(parts) | Formula::Or(parts) => {
                let conj = matches!(formula, Formula::And(_));
                let mut acc = Self::emit(&parts[0], ops, seen);
                for part in &parts[1..] {
                    let next = Self::emit(part, ops, seen);
                    ops.push(if conj {
                        Op::And(acc, next)
                    } else {
                        Op::Or(acc, next)
                    });
                    acc = ops.len() - 1;
                }
                seen.insert(formula, acc);
                return acc;
            }
        };
        ops.push(op);
        seen.insert(formula, ops.len() - 1);
        ops.len() - 1
    }
}

/// A value domain for the backward sweep: real robustness or Boolean truth.
trait Semantics {
    type Value: Copy + PartialEq;
    const TOP: Self::Value;
    const BOTTOM: Self::Value;
    /// Fills `out` with the atom's value at every state (`reals` is spare room for robustness).
    fn atom_values(
        p: &Predicate,
        traj: Trajectory<'_>,
        out: &mut [Self::Value],
        reals: &mut Vec<f64>,
    );
    fn not(a: Self::Value) -> Self::Value;
    fn and(a: Self::Value, b: Self::Value) -> Self::Value;
    fn or(a: Self::Value, b: Self::Value) -> Self::Value;
}

struct Quantitative;

impl Semantics for Quantitative {
    type Value = f64;
    const TOP: f64 = f64::INFINITY;
    const BOTTOM: f64 = f64::NEG_INFINITY;
    fn atom_values(p: &Predicate, traj: Trajectory<'_>, out: &mut [f64], _: &mut Vec<f64>) {
        p.values_into(traj.data, traj.dim, out);
    }
    #[inline]
    fn not(a: f64) -> f64 {
        -a
    }
    #[inline]
    fn and(a: f64, b: f64) -> f64 {
        // Values are finite or infinite, never NaN, so a plain comparison is exact (and maps
        // to one SIMD instruction, unlike f64::min's NaN handling).
        if a < b {
            a
        } else {
            b
        }
    }
    #[inline]
    fn or(a: f64, b: f64) -> f64 {
        if a > b {
            a
        } else {
            b
        }
    }
}

struct Boolean;

impl Semantics for Boolean {
    type Value = bool;
    const TOP: bool = true;
    const BOTTOM: bool = false;
    fn atom_values(p: &Predicate, traj: Trajectory<'_>, out: &mut [bool], reals: &mut Vec<f64>) {
        reals.resize(out.len(), 0.0);
        p.values_into(traj.data, traj.dim, reals);
        for (o, &rho) in out.iter_mut().zip(reals.iter()) {
            *o = rho > 0.0;
        }
    }
    #[inline]
    fn not(a: bool) -> bool {
        !a
    }
    #[inline]
    fn and(a: bool, b: bool) -> bool {
        a && b
    }
    #[inline]
    fn or(a: bool, b: bool) -> bool {
        a || b
    }
}

/// A validated, row-major view of states `s_0..s_T` (T + 1 rows of `dim` values).
#[derive(Debug, Clone, Copy)]
pub struct Trajectory<'a> {
    data: &'a [f64],
    dim: usize,
}

impl<'a> Trajectory<'a> {
    /// Wraps `data` as rows of `dim` values. Needs at least one row and finite values.
    pub fn new(data: &'a [f64], dim: usize) -> Result<Self, InputError> {
        if dim == 0 || data.is_empty() || data.len() % dim != 0 {
            return Err(InputError::Shape {
                what: "trajectory".into(),
                expected: "at least one state of at least one value".into(),
                got: format!("{} values in rows of {dim}", data.len()),
            });
        }
        check_finite("traj", data, dim)?;
        Ok(Trajectory { data, dim })
    }

    /// Number of states (T + 1).
    pub fn len(&self) -> usize {
        self.data.len() / self.dim
    }

    /// Always false: a trajectory holds at least one state.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// State `t`.
    #[inline]
    pub fn state(&self, t: usize) -> &'a [f64] {
        &self.data[t * self.dim..(t + 1) * self.dim]
    }

    /// Length of each state.
    pub fn dim(&self) -> usize {
        self.dim
    }
}

/// A batch of equally long trajectories, `(B, T + 1, dim)` in C order. The shape is checked
/// here; values are checked for NaN/inf by the batch evaluators while they read each
/// trajectory (one pass over memory instead of two), which report the first bad value.
#[derive(Debug, Clone, Copy)]
pub struct TrajectoryBatch<'a> {
    data: &'a [f64],
    steps: usize,
    pub(crate) dim: usize,
}

impl<'a> TrajectoryBatch<'a> {
    /// Wraps `data` as `batch` trajectories of `steps` states of `dim` values each.
    pub fn new(
        data: &'a [f64],
        batch: usize,
        steps: usize,
        dim: usize,
    ) -> Result<Self, InputError> {
        if steps == 0 || dim == 0 {
            return Err(InputError::Shape {
                what: "trajs".into(),
                expected: "at least one state of at least one value per trajectory".into(),
                got: format!("({batch}, {steps}, {dim})"),
            });
        }
        if crate::alloc::checked_len("trajs", &[batch, steps, dim])? != data.len() {
            return Err(InputError::Shape {
                what: "trajs".into(),
                expected: format!(
                    "{} values for shape ({batch}, {steps}, {dim})",
                    batch * steps * dim
                ),
                got: data.len().to_string(),
            });
        }
        Ok(TrajectoryBatch { data, steps, dim })
    }

    /// Number of trajectories.
    pub fn len(&self) -> usize {
        self.data.len() / (self.steps * self.dim)
    }

    /// Whether the batch holds no trajectory.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    fn non_finite(&self, i: usize) -> InputError {
        let (b, rest) = (i / (self.steps * self.dim), i % (self.steps * self.dim));
        InputError::NonFinite {
            what: format!("trajs[{b}, {}, {}]", rest / self.dim, rest % self.dim),
            value: self.data[i],
        }
    }

    /// Applies `f` to every trajectory in parallel, checking each one's values just before
    /// evaluating it (while it is in cache).
    pub(crate) fn map<V, F>(&self, fill: V, f: F) -> Result<Vec<V>, InputError>
    where
        V: Copy + Send,
        F: Fn(Trajectory<'_>, &mut Scratch) -> V + Sync,
    {
        let stride = self.steps * self.dim;
        let mut out = crate::alloc::try_vec("trajs", self.len(), fill)?;
        if stride == 0 || out.is_empty() {
            return Ok(out);
        }
        let first_bad = crate::parallel::install(|| {
            out.par_iter_mut()
                .zip(self.data.par_chunks(stride))
                .enumerate()
                .map_init(Scratch::default, |scratch, (b, (o, data))| {
                    if let Some(i) = first_non_finite(data) {
                        return Some(b * stride + i);
                    }
                    *o = f(
                        Trajectory {
                            data,
                            dim: self.dim,
                        },
                        scratch,
                    );
                    None
                })
                .filter_map(|bad| bad)
                .min()
        });
        match first_bad {
            Some(i) => Err(self.non_finite(i)),
            None => Ok(out),
        }
    }
}

/// Reusable buffers for evaluation, so repeated calls allocate nothing once warm.
#[derive(Debug, Default, Clone)]
pub struct Scratch {
    real: Vec<f64>,
    truth: Vec<bool>,
    atom: Vec<f64>,
}

trait Buffer<V> {
    /// The value buffer for this semantics and a spare robustness buffer.
    fn buffers(&mut self) -> (&mut Vec<V>, &mut Vec<f64>);
}

impl Buffer<f64> for Scratch {
    fn buffers(&mut self) -> (&mut Vec<f64>, &mut Vec<f64>) {
        (&mut self.real, &mut self.atom)
    }
}

impl Buffer<bool> for Scratch {
    fn buffers(&mut self) -> (&mut Vec<bool>, &mut Vec<f64>) {
        (&mut self.truth, &mut self.atom)
    }
}

/// `out[t] = f(a[t], b[t])`, written so the compiler can vectorise it.
#[inline(always)]
fn zip_with<V: Copy>(out: &mut [V], a: &[V], b: &[V], f: impl Fn(V, V) -> V) {
    for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
        *o = f(x, y);
    }
}

/// `max`/`or` of all values, with four independent accumulators (no serial dependency chain).
fn any_of<S: Semantics>(a: &[S::Value]) -> S::Value {
    let mut acc = [S::BOTTOM; 4];
    let mut quads = a.chunks_exact(4);
    for q in &mut quads {
        for k in 0..4 {
            acc[k] = S::or(acc[k], q[k]);
        }
    }
    let tail = quads
        .remainder()
        .iter()
        .fold(S::BOTTOM, |x, &y| S::or(x, y));
    S::or(S::or(acc[0], acc[1]), S::or(S::or(acc[2], acc[3]), tail))
}

/// `a U b` at t = 0 by a forward scan: the best `min(b[t], min a[..t])` so far, stopping as
/// soon as the running `min a` cannot beat it any more.
fn until_at_start<S: Semantics>(a: &[S::Value], b: &[S::Value]) -> S::Value {
    let mut best = S::BOTTOM;
    let mut prefix = S::TOP;
    for (&x, &y) in a.iter().zip(b) {
        best = S::or(best, S::and(y, prefix));
        prefix = S::and(prefix, x);
        if S::or(best, prefix) == best {
            break;
        }
    }
    best
}

/// Evaluates the compiled formula over `traj` and returns its value at `t = 0`.
fn evaluate<S: Semantics>(
    program: &Program,
    predicates: &[Predicate],
    traj: Trajectory<'_>,
    scratch: &mut Scratch,
) -> S::Value
where
    Scratch: Buffer<S::Value>,
{
    let Program { ops, full } = program;
    let len = traj.len();
    let last = len - 1;
    let (values, reals) = scratch.buffers();
    values.clear();
    values.resize(ops.len() * len, S::BOTTOM);
    for (i, op) in ops.iter().enumerate() {
        // Operands always precede the instruction, so they live in `done`.
        let (done, rest) = values.split_at_mut(i * len);
        let slot = |k: usize| &done[k * len..(k + 1) * len];
        if !full[i] {
            // Only the value at t = 0 is read by anyone.
            rest[0] = match *op {
                Op::True => S::TOP,
                Op::False => S::BOTTOM,
                Op::Atom(k) => {
                    let first = Trajectory {
                        data: traj.state(0),
                        dim: traj.dim,
                    };
                    S::atom_values(&predicates[k], first, &mut rest[..1], reals);
                    rest[0]
                }
                Op::Not(a) => S::not(slot(a)[0]),
                Op::And(a, b) => S::and(slot(a)[0], slot(b)[0]),
                Op::Or(a, b) => S::or(slot(a)[0], slot(b)[0]),
                Op::Implies(a, b) => S::or(S::not(slot(a)[0]), slot(b)[0]),
                Op::Eventually(a) => any_of::<S>(slot(a)),
                Op::Until(a, b) => until_at_start::<S>(slot(a), slot(b)),
                Op::Next(a) if len > 1 => slot(a)[1],
                Op::Next(_) => S::BOTTOM,
            };
            continue;
        }
        let out = &mut rest[..len];
        match *op {
            Op::True => out.fill(S::TOP),
            Op::False => out.fill(S::BOTTOM),
            Op::Atom(k) => S::atom_values(&predicates[k], traj, out, reals),
            Op::Not(a) => {
                for (o, &x) in out.iter_mut().zip(slot(a)) {
                    *o = S::not(x);
                }
            }
            Op::And(a, b) => zip_with(out, slot(a), slot(b), S::and),
            Op::Or(a, b) => zip_with(out, slot(a), slot(b), S::or),
            Op::Implies(a, b) => zip_with(out, slot(a), slot(b), |x, y| S::or(S::not(x), y)),
            Op::Eventually(a) => {
                let a = slot(a);
                let mut acc = S::BOTTOM;
                for t in (0..len).rev() {
                    acc = S::or(a[t], acc);
                    out[t] = acc;
                }
            }
            Op::Until(a, b) => {
                let (a, b) = (slot(a), slot(b));
                let mut acc = S::BOTTOM;
                for t in (0..len).rev() {
                    acc = S::or(b[t], S::and(a[t], acc));
                    out[t] = acc;
                }
            }
            Op::Next(a) => {
                out[..last].copy_from_slice(&slot(a)[1..]);
                out[last] = S::BOTTOM;
            }
        }
    }
    values[(ops.len() - 1) * len]
}

/// Robustness at `t = 0` of a compiled formula over `traj` (closed window); the caller has
/// checked the state length.
pub(crate) fn robustness(
    program: &Program,
    predicates: &[Predicate],
    traj: Trajectory<'_>,
    scratch: &mut Scratch,
) -> f64 {
    evaluate::<Quantitative>(program, predicates, traj, scratch)
}

/// Boolean satisfaction of a compiled formula over `traj`; the caller has checked the length.
pub(crate) fn satisfied(
    program: &Program,
    predicates: &[Predicate],
    traj: Trajectory<'_>,
    scratch: &mut Scratch,
) -> bool {
    evaluate::<Boolean>(program, predicates, traj, scratch)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{co_safe, spec_for, trajectory, NAMES};
    use crate::predicate::Center;
    use crate::spec::Spec;
    use proptest::prelude::*;

    /// Direct transcription of the semantics (DESIGN.md), O(T^2) per operator: the oracle.
    fn brute(spec: &Spec, f: &Formula, traj: &Trajectory<'_>, t: usize) -> f64 {
        let last = traj.len() - 1;
        match f {
            Formula::True => f64::INFINITY,
            Formula::False => f64::NEG_INFINITY,
            Formula::Atom(k) => spec.predicates()[*k].value(traj.state(t)),
            Formula::Not(a) => -brute(spec, a, traj, t),
            Formula::And(v) => v
                .iter()
                .map(|g| brute(spec, g, traj, t))
                .fold(f64::INFINITY, f64::min),
            Formula::Or(v) => v
                .iter()
                .map(|g| brute(spec, g, traj, t))
                .fold(f64::NEG_INFINITY, f64::max),
            Formula::Implies(a, b) => (-brute(spec, a, traj, t)).max(brute(spec, b, traj, t)),
            Formula::Eventually(a) => (t..=last)
                .map(|u| brute(spec, a, traj, u))
                .fold(f64::NEG_INFINITY, f64::max),
            Formula::Next(a) if t < last => brute(spec, a, traj, t + 1),
            Formula::Next(_) => f64::NEG_INFINITY,
            Formula::Until(a, b) => (t..=last)
                .map(|u| {
                    let before = (t..u)
                        .map(|v| brute(spec, a, traj, v))
                        .fold(f64::INFINITY, f64::min);
                    brute(spec, b, traj, u).min(before)
                })
                .fold(f64::NEG_INFINITY, f64::max),
        }
    }

    /// Boolean oracle: quantifiers over time, atoms hold iff robustness > 0.
    fn brute_bool(spec: &Spec, f: &Formula, traj: &Trajectory<'_>, t: usize) -> bool {
        let last = traj.len() - 1;
        match f {
            Formula::True => true,
            Formula::False => false,
            Formula::Atom(k) => spec.predicates()[*k].value(traj.state(t)) > 0.0,
            Formula::Not(a) => !brute_bool(spec, a, traj, t),
            Formula::And(v) => v.iter().all(|g| brute_bool(spec, g, traj, t)),
            Formula::Or(v) => v.iter().any(|g| brute_bool(spec, g, traj, t)),
            Formula::Implies(a, b) => !brute_bool(spec, a, traj, t) || brute_bool(spec, b, traj, t),
            Formula::Eventually(a) => (t..=last).any(|u| brute_bool(spec, a, traj, u)),
            Formula::Next(a) => t < last && brute_bool(spec, a, traj, t + 1),
            Formula::Until(a, b) => (t..=last).any(|u| {
                brute_bool(spec, b, traj, u) && (t..u).all(|v| brute_bool(spec, a, traj, v))
            }),
        }
    }

    proptest! {
        #![proptest_config(crate::tests_support::seeded(3000))]

        #[test]
        fn sweep_matches_brute_force(f in co_safe(), data in trajectory()) {
            let spec = spec_for(&f);
            let traj = Trajectory::new(&data, 3).unwrap();
            let rho = spec.robustness(traj).unwrap();
            let expected = brute(&spec, spec.formula(), &traj, 0);
            prop_assert_eq!(rho, expected);
            let sat = spec.satisfied(traj).unwrap();
            prop_assert_eq!(sat, brute_bool(&spec, spec.formula(), &traj, 0));
            if rho > 0.0 { prop_assert!(sat, "rho = {} > 0 but not satisfied", rho); }
            if rho < 0.0 { prop_assert!(!sat, "rho = {} < 0 but satisfied", rho); }
        }

        #[test]
        fn canonical_text_round_trips(f in co_safe()) {
            let names: Vec<String> = NAMES.iter().map(|s| s.to_string()).collect();
            let text = f.display(&names).to_string();
            let (parsed, atoms) = Formula::parse(&text).unwrap();
            prop_assert_eq!(parsed.display(&atoms).to_string(), text);
        }

        #[test]
        fn batch_equals_single_calls(f in co_safe(), data in prop::collection::vec(-2.0..2.0f64, 4 * 5 * 3)) {
            let spec = spec_for(&f);
            let batch = spec.robustness_batch(TrajectoryBatch::new(&data, 4, 5, 3).unwrap()).unwrap();
            let sats = spec.satisfied_batch(TrajectoryBatch::new(&data, 4, 5, 3).unwrap()).unwrap();
            for (b, chunk) in data.chunks(15).enumerate() {
                let traj = Trajectory::new(chunk, 3).unwrap();
                prop_assert_eq!(batch[b], spec.robustness(traj).unwrap());
                prop_assert_eq!(sats[b], spec.satisfied(traj).unwrap());
            }
        }

        #[test]
        fn parser_never_panics(text in "\\PC{0,40}") {
            let _ = Formula::parse(&text);
        }

        #[test]
        fn parser_never_panics_on_formula_like_text(text in "[a-c FXGU!&|()<>=\\[\\]-]{0,40}") {
            let _ = Formula::parse(&text);
        }
    }

    fn one_dim(formula: &str, name: &str, predicate: Predicate) -> Spec {
        Spec::new(formula, [(name, predicate)]).unwrap()
    }

    #[test]
    fn paper_example_eventually_below_four_closed_window() {
        // Paper Sec. III-B: rho(s_0:3, F(s < 4)) = max(4 - s_t); our window includes s_3.
        let spec = one_dim(
            "F low",
            "low",
            Predicate::halfspace(vec![-1.0], 4.0).unwrap(),
        );
        let states = [6.0, 5.0, 4.5, 3.5];
        let rho = spec
            .robustness(Trajectory::new(&states, 1).unwrap())
            .unwrap();
        assert_eq!(rho, 0.5);
        // The paper's half-open window would give max(-2, -1, -0.5) = -0.5 here.
        assert!(spec
            .satisfied(Trajectory::new(&states, 1).unwrap())
            .unwrap());
        let short = &states[..3];
        assert_eq!(
            spec.robustness(Trajectory::new(short, 1).unwrap()).unwrap(),
            -0.5
        );
    }

    fn running_example() -> Spec {
        // Regions a, b, c of radius 1 on a line (paper Sec. V); state = [x, y].
        let region =
            |x: f64| Predicate::ball(vec![0, 1], 1.0, Center::Fixed(vec![x, 0.0])).unwrap();
        Spec::new(
            "(F a | F b) & F c & ((!a & !b) U c)",
            [("a", region(0.0)), ("b", region(4.0)), ("c", region(8.0))],
        )
        .unwrap()
    }

    #[test]
    fn paper_running_example_visit_c_then_a() {
        let spec = running_example();
        // Start between a and b (outside both), go to c, then back to a.
        let path = [2.0, 0.0, 8.0, 0.0, 0.0, 0.0];
        let traj = Trajectory::new(&path, 2).unwrap();
        assert!(spec.satisfied(traj).unwrap());
        // Every conjunct holds with margin 1 (centres reached); the binding term is the until:
        // !a & !b at s_0 has robustness min(|2-0|-1, |2-4|-1) = 1.
        assert_eq!(spec.robustness(traj).unwrap(), 1.0);
    }

    #[test]
    fn paper_running_example_a_before_c_violates() {
        let spec = running_example();
        let path = [2.0, 0.0, 0.0, 0.0, 8.0, 0.0];
        let traj = Trajectory::new(&path, 2).unwrap();
        assert!(!spec.satisfied(traj).unwrap());
        // (!a & !b) fails at s_1 by 1 before c is reached at s_2: the until scores -1.
        assert_eq!(spec.robustness(traj).unwrap(), -1.0);
    }

    #[test]
    fn constants_and_next_at_the_end() {
        let p = Predicate::halfspace(vec![1.0], 0.0).unwrap();
        let spec = one_dim("X p", "p", p.clone());
        let one = [1.0];
        assert_eq!(
            spec.robustness(Trajectory::new(&one, 1).unwrap()).unwrap(),
            f64::NEG_INFINITY
        );
        let spec = one_dim("F true | p", "p", p);
        assert_eq!(
            spec.robustness(Trajectory::new(&one, 1).unwrap()).unwrap(),
            f64::INFINITY
        );
    }

    #[test]
    fn bad_trajectories_are_errors() {
        crate::tests_support::assert_error(Trajectory::new(&[], 1), "Shape", "trajectory");
        crate::tests_support::assert_error(
            Trajectory::new(&[1.0, 2.0, 3.0], 2),
            "Shape",
            "trajectory",
        );
        let err = Trajectory::new(&[1.0, 2.0, f64::NAN, 0.0], 2).unwrap_err();
        assert_eq!(
            err.to_string(),
            "traj[1, 0] is NaN (all values must be finite)"
        );
        let sum = Predicate::halfspace(vec![1.0, 1.0], 0.0).unwrap();
        let spec2 = Spec::new("F a", [("a", sum)]).unwrap();
        let data = [0.0, 0.0, 0.0, f64::INFINITY, f64::NAN, 0.0];
        let err = spec2
            .robustness_batch(TrajectoryBatch::new(&data, 3, 1, 2).unwrap())
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "trajs[1, 0, 1] is inf (all values must be finite)"
        );
        crate::tests_support::assert_error(
            TrajectoryBatch::new(&[0.0; 5], 2, 1, 2),
            "Shape",
            "trajs",
        );
        let spec = running_example();
        let err = spec
            .robustness(Trajectory::new(&[0.0], 1).unwrap())
            .unwrap_err();
        assert_eq!(err.to_string(), "state length: expected at least 2, got 1");
    }
}
