//! The FSA of an scTLTL formula, built natively and symbolically: formula progression as
//! decision diagrams over the atoms (`diagram`) with canonical simplification, acceptance by
//! end-of-trace evaluation, then minimisation. The result is unique for the formula's
//! language: one absorbing accepting state, and at most one trap state (no path to
//! acceptance). Guards are DNFs read off the diagrams (minimised exactly up to 8 atoms).
//!
//! The FSA reads every state of a trajectory: `q_0 = delta(initial, s_0)`,
//! `q_{t+1} = delta(q_t, s_{t+1})`; an atom holds iff its robustness is > 0.
//!
//! Construction is in `build` (diagrams in `diagram`); the reward that guides the learner
//! (Eq. 5A1) is in `reward`, the shield's safe set (Eq. 5C1) in `safe_set`, and the CLF goal
//! (Eq. 5B1) with the rest of the shield's guidance in the crate's guidance room. Here: the
//! automaton, its stepper and [`Reading`], the atoms of one validated state read once.

use rayon::prelude::*;

use crate::check::{check_finite, check_state_len};
use crate::cnf::{dnf_text, Cube, Literal};
use crate::error::{AutomatonError, InputError};
use crate::robustness::Trajectory;
use crate::spec::Spec;

mod build;
mod diagram;
mod regions;
mod reward;
mod safe_set;

pub use build::{MAX_GUARD_CUBES, MAX_STATES};
pub use diagram::MAX_NODES;
pub use regions::ranks;
pub(crate) use regions::GoalAlternative;
pub use reward::{DEFAULT_C_R, DEFAULT_TRAP_PENALTY};

/// Most atoms an automaton supports. The construction never enumerates the `2^atoms` letters
/// (transitions are decision diagrams over the atoms), so the bound is the letter's width.
pub const MAX_ATOMS: usize = 30;

/// One edge of the automaton with its guard.
#[derive(Debug, Clone, PartialEq)]
pub struct Edge {
    /// Source state.
    pub src: usize,
    /// Target state.
    pub dst: usize,
    /// Minimised DNF over the atoms.
    pub guard: Vec<Cube>,
}

/// A deterministic automaton over atom valuations, with the per-state data the shield needs.
#[derive(Debug, Clone)]
pub struct Automaton {
    spec: Spec,
    letters: usize,
    initial: usize,
    accepting: Vec<bool>,
    trap: Option<usize>,
    /// `table[q * letters + v]`: the successor of `q` on valuation `v`, when small enough to
    /// keep (empty otherwise: steps walk `diagram`).
    table: Vec<u32>,
    /// The transition function: per state, the root of its diagram (leaves: successors).
    diagram: diagram::Diagram,
    roots: Vec<diagram::NodeId>,
    edges: Vec<Edge>,
    /// Per state: the cubes of D_q, the OR of the guards to states other than q and the trap.
    progress: Vec<Vec<Cube>>,
    /// Per state: the guard of its edge to the trap (empty: no such edge).
    trap_guard: Vec<Vec<Cube>>,
    /// Per state: the CNF of the negated trap guard (empty: no trap edge).
    trap_cnf: Vec<Vec<Vec<Literal>>>,
    /// The trap's safe set: what every way into it kept (`regions::recovery_cnf`).
    recovery_cnf: Vec<Vec<Literal>>,
    /// Per atom pair (row-major, atoms x atoms): whether the two can hold together.
    pairs: Vec<Option<bool>>,
    /// Per state: transitions to acceptance over admissible letters.
    ranks: Vec<Option<u32>>,
    /// Per edge, per guard cube: where the cube can hold, with its goal.
    goal_alternatives: Vec<Vec<Vec<regions::GoalAlternative>>>,
    /// Per state: the CNF that keeps away from every setback (the progress-preserving safe set).
    avoid_cnf: Vec<Vec<Vec<Literal>>>,
}

/// The atoms of one validated state, read once (see [`Automaton::read`]). Every query takes
/// a state id `q` of the automaton (from [`Automaton::check_state`] or the automaton itself);
/// an id past [`Automaton::num_states`] panics.
#[derive(Debug, Clone, Copy)]
pub struct Reading<'a> {
    aut: &'a Automaton,
    s: &'a [f64],
    rho: [f64; MAX_ATOMS],
}

impl<'a> Reading<'a> {
    /// A reading from atoms computed earlier for the validated state `s` (the task monitor
    /// keeps its last reading this way).
    pub(crate) fn from_parts(aut: &'a Automaton, s: &'a [f64], rho: [f64; MAX_ATOMS]) -> Self {
        Reading { aut, s, rho }
    }

    /// The robustness of every atom, in the spec's atom order.
    #[inline]
    pub fn rho(&self) -> &[f64] {
        &self.rho[..self.aut.spec.atoms().len()]
    }

    /// The automaton that read the state.
    pub fn automaton(&self) -> &'a Automaton {
        self.aut
    }

    /// The state read.
    pub fn state(&self) -> &'a [f64] {
        self.s
    }

    /// The valuation: bit `i` set iff atom `i` holds (robustness > 0).
    #[inline]
    pub fn valuation(&self) -> usize {
        self.rho()
            .iter()
            .enumerate()
            .fold(0, |v, (i, &r)| v | (usize::from(r > 0.0) << i))
    }

    /// The successor of `q` on this state.
    #[inline]
    pub fn step(&self, q: usize) -> usize {
        self.aut.step_valuation(q, self.valuation())
    }
}

impl Automaton {
    /// The spec the automaton was built from.
    pub fn spec(&self) -> &Spec {
        &self.spec
    }

    /// Number of states.
    pub fn num_states(&self) -> usize {
        self.accepting.len()
    }

    /// The state before anything is read (the formula itself).
    pub fn initial(&self) -> usize {
        self.initial
    }

    /// Whether `q` is accepting.
    pub fn is_accepting(&self, q: usize) -> bool {
        self.accepting[q]
    }

    /// Accepting states, ascending.
    pub fn accepting(&self) -> Vec<usize> {
        (0..self.num_states())
            .filter(|&q| self.accepting[q])
            .collect()
    }

    /// The trap state, if the formula can be violated.
    pub fn trap(&self) -> Option<usize> {
        self.trap
    }

    /// All edges (self-loops included), sorted by source then target.
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// The CNF of the negated trap guard of `q` (empty: `q` has no trap edge).
    pub fn trap_cnf(&self, q: usize) -> Result<&[Vec<Literal>], AutomatonError> {
        self.check_state("q", q)?;
        Ok(&self.trap_cnf[q])
    }

    /// The CNF of the progress-preserving safe set of `q`: the negation of every guard to a
    /// state farther from acceptance (or the trap); the trap CNF when nothing else sets back.
    pub fn avoid_cnf(&self, q: usize) -> Result<&[Vec<Literal>], AutomatonError> {
        self.check_state("q", q)?;
        Ok(&self.avoid_cnf[q])
    }

    /// The trap's recovery safe set (empty without a trap): the clauses every state with an
    /// edge into the trap keeps, which the shield keeps enforcing once the task has failed.
    pub fn recovery_cnf(&self) -> &[Vec<Literal>] {
        &self.recovery_cnf
    }

    /// Transitions to acceptance from each state over the letters the regions' geometry
    /// admits (`None`: unreachable, e.g. the trap).
    pub fn ranks(&self) -> &[Option<u32>] {
        &self.ranks
    }

    /// Per guard cube of edge `e`: the ways it can hold, each with its goal (Eq. 5B1's
    /// candidates, read by `guidance::goal`).
    pub(crate) fn goal_alternatives(&self, e: usize) -> &[Vec<GoalAlternative>] {
        &self.goal_alternatives[e]
    }

    /// [`Automaton::goal_alternatives`] of every edge, in edge order.
    pub(crate) fn all_goal_alternatives(&self) -> &[Vec<Vec<GoalAlternative>>] {
        &self.goal_alternatives
    }

    /// Whether the geometry admits valuation `v` (no two disjoint regions, no empty
    /// intersection, among the atoms that hold). The caller guarantees `v < 2^atoms`.
    /// Computed per call (the letters are never tabulated): admissibility is anti-monotone
    /// (more atoms holding can only add a clash), so a cube admits some letter iff its
    /// positive literals alone are admissible.
    pub fn admissible(&self, v: usize) -> bool {
        regions::admissible_letter(&self.spec, &self.pairs, v as u32)
    }

    /// Whether atoms `i` and `j` can hold at one state: `Some(false)` for disjoint regions,
    /// `Some(true)` for overlapping ones, `None` when the geometry does not say (moving
    /// regions). Panics on an index past the atoms.
    pub fn can_hold_together(&self, i: usize, j: usize) -> Option<bool> {
        let n = self.spec.atoms().len();
        assert!(i < n && j < n, "atom index past {n}");
        if i == j {
            return Some(true);
        }
        self.pairs[i * n + j]
    }

    /// The guard of `q`'s edge to the trap (empty: none).
    pub fn trap_guard(&self, q: usize) -> Result<&[Cube], AutomatonError> {
        self.check_state("q", q)?;
        Ok(&self.trap_guard[q])
    }

    /// The cubes of D_q (Eq. 5A1): the guards of `q`'s edges to other non-trap states.
    pub fn progress_guard(&self, q: usize) -> Result<&[Cube], AutomatonError> {
        self.check_state("q", q)?;
        Ok(&self.progress[q])
    }

    /// Checks a state id given by a caller.
    pub fn check_state(&self, what: &str, q: usize) -> Result<usize, AutomatonError> {
        match q {
            q if q < self.num_states() => Ok(q),
            _ => Err(AutomatonError::UnknownState {
                what: what.into(),
                q,
                num_states: self.num_states(),
            }),
        }
    }

    /// [`Automaton::check_state`] of every `qs[i]` (the error names the first bad one as
    /// `{what}[i]`); the name is only formatted for an error, so a batch's check allocates
    /// nothing per row.
    pub fn check_states(&self, what: &str, qs: &[usize]) -> Result<(), AutomatonError> {
        match qs.iter().position(|&q| q >= self.num_states()) {
            None => Ok(()),
            Some(i) => self.check_state(&format!("{what}[{i}]"), qs[i]).map(|_| ()),
        }
    }

    fn check_vector(&self, s: &[f64]) -> Result<(), InputError> {
        check_state_len("state", s.len(), &[self.spec.state_len()?])?;
        check_finite("s", s, s.len())
    }

    /// Reads state `s` after checking its length and finiteness: the atoms' robustness,
    /// computed once, for [`Reading::step`], [`Reading::reward`], [`Reading::goal`] and
    /// [`Reading::safe_set`]. Allocation-free.
    pub fn read<'a>(&'a self, s: &'a [f64]) -> Result<Reading<'a>, InputError> {
        self.check_vector(s)?;
        Ok(self.read_validated(s))
    }

    /// [`Automaton::read`] of a state the crate has already validated (the shield's hot path).
    #[inline]
    pub(crate) fn read_validated<'a>(&'a self, s: &'a [f64]) -> Reading<'a> {
        let mut rho = [0.0; MAX_ATOMS];
        self.spec
            .atom_robustness_into(s, &mut rho[..self.spec.atoms().len()]);
        Reading { aut: self, s, rho }
    }

    /// The successor of `q` after reading state `s` (validated). State first, as everywhere in
    /// the API: `(s, q)`.
    pub fn step(&self, s: &[f64], q: usize) -> Result<usize, AutomatonError> {
        self.check_state("q", q)?;
        Ok(self.read(s)?.step(q))
    }

    /// The successor of `q` on the atom valuation `v` (bit `i` set: atom `i` holds). The caller
    /// guarantees `q < num_states()` and `v < 2^atoms`.
    #[inline]
    pub fn step_valuation(&self, q: usize, v: usize) -> usize {
        if self.table.is_empty() {
            self.diagram.eval(self.roots[q], v) as usize
        } else {
            self.table[q * self.letters + v] as usize
        }
    }

    /// Nodes of the decision diagrams that hold the transition function: what the automaton
    /// stores, with its states and guards, instead of a `states x 2^atoms` table (a table is
    /// added only while it has at most 65,536 entries).
    pub fn diagram_nodes(&self) -> usize {
        self.diagram.len()
    }

    /// Steps a batch in parallel: row `i` of `states` (row-major, `dim` values) from `qs[i]`.
    pub fn step_batch(
        &self,
        qs: &[usize],
        states: &[f64],
        dim: usize,
    ) -> Result<Vec<usize>, AutomatonError> {
        if dim == 0 || qs.len().checked_mul(dim) != Some(states.len()) {
            return Err(InputError::Shape {
                what: "states".into(),
                expected: format!("({}, n) to match qs", qs.len()),
                got: format!("{} values in rows of {dim}", states.len()),
            }
            .into());
        }
        check_state_len("state", dim, &[self.spec.state_len()?])?;
        check_finite("states", states, dim)?;
        self.check_states("qs", qs)?;
        let mut out = crate::alloc::try_vec("qs", qs.len(), 0)?;
        crate::parallel::install(|| {
            out.par_iter_mut()
                .zip(qs.par_iter().zip(states.par_chunks(dim)))
                .for_each(|(o, (&q, s))| *o = self.read_validated(s).step(q));
        });
        Ok(out)
    }

    /// The state after reading every state of `traj`, starting from the initial state.
    pub fn run(&self, traj: Trajectory<'_>) -> Result<usize, AutomatonError> {
        check_state_len("state", traj.dim(), &[self.spec.state_len()?])?;
        Ok((0..traj.len()).fold(self.initial, |q, t| {
            self.read_validated(traj.state(t)).step(q)
        }))
    }

    /// Whether the automaton accepts `traj` (reads every state, ends in an accepting state).
    pub fn accepts(&self, traj: Trajectory<'_>) -> Result<bool, AutomatonError> {
        Ok(self.accepting[self.run(traj)?])
    }

    /// Graphviz DOT text: accepting states double circles, the trap filled red.
    pub fn to_dot(&self) -> String {
        let atoms = self.spec.atoms();
        let mut out = String::from("digraph fsa {\n  rankdir=LR;\n  node [shape=circle, fontname=\"Helvetica\"];\n  edge [fontname=\"Helvetica\", fontsize=10];\n  start [shape=point];\n");
        out.push_str(&format!("  start -> q{};\n", self.initial));
        for q in 0..self.num_states() {
            let mut attrs = vec![];
            if self.accepting[q] {
                attrs.push("shape=doublecircle".to_string());
            }
            if Some(q) == self.trap {
                attrs.push(format!("label=\"q{q}\\ntrap\""));
                attrs.push("style=filled, fillcolor=\"#f4b6b6\"".to_string());
            }
            if attrs.is_empty() {
                out.push_str(&format!("  q{q};\n"));
            } else {
                out.push_str(&format!("  q{q} [{}];\n", attrs.join(", ")));
            }
        }
        for e in &self.edges {
            out.push_str(&format!(
                "  q{} -> q{} [label=\"{}\"];\n",
                e.src,
                e.dst,
                dnf_text(&e.guard, atoms)
            ));
        }
        out.push_str("}\n");
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{co_safe, spec_for, trajectory};
    use crate::formula::Formula;
    use crate::predicate::{Center, Predicate};
    use crate::spec::Spec;
    use proptest::prelude::*;

    fn running_example() -> Automaton {
        let region =
            |x: f64| Predicate::ball(vec![0, 1], 1.0, Center::Fixed(vec![x, 0.0])).unwrap();
        let spec = Spec::new(
            "(F a | F b) & F c & ((!a & !b) U c)",
            [("a", region(0.0)), ("b", region(4.0)), ("c", region(8.0))],
        )
        .unwrap();
        Automaton::build(&spec).unwrap()
    }

    fn task() -> Automaton {
        crate::fixtures::task_automaton()
    }

    fn edge_list(aut: &Automaton) -> Vec<(usize, usize, String)> {
        aut.edges()
            .iter()
            .map(|e| (e.src, e.dst, dnf_text(&e.guard, aut.spec().atoms())))
            .collect()
    }

    fn cnf_text(aut: &Automaton, q: usize) -> Vec<String> {
        let atoms = aut.spec().atoms();
        aut.trap_cnf(q)
            .unwrap()
            .iter()
            .map(|clause| {
                clause
                    .iter()
                    .map(|l| format!("{}{}", if l.positive { "" } else { "!" }, atoms[l.atom]))
                    .collect::<Vec<_>>()
                    .join(" | ")
            })
            .collect()
    }

    fn owned(edges: &[(usize, usize, &str)]) -> Vec<(usize, usize, String)> {
        edges
            .iter()
            .map(|(a, b, g)| (*a, *b, g.to_string()))
            .collect()
    }

    #[test]
    fn running_example_matches_the_paper() {
        // Paper Fig. 5.1: q0 --c--> q1 --(a | b)--> qf, and the trap when a or b comes before c.
        let aut = running_example();
        assert_eq!(
            (aut.num_states(), aut.initial(), aut.trap()),
            (4, 0, Some(1))
        );
        assert_eq!(aut.accepting(), vec![3]);
        assert_eq!(
            edge_list(&aut),
            owned(&[
                (0, 0, "!a & !b & !c"),
                (0, 1, "a & !c | b & !c"),
                (0, 2, "!a & !b & c"),
                (0, 3, "a & c | b & c"),
                (1, 1, "true"),
                (2, 2, "!a & !b"),
                (2, 3, "a | b"),
                (3, 3, "true"),
            ])
        );
        assert_eq!(cnf_text(&aut, 0), ["!a | c", "!b | c"]);
        assert!(aut.trap_cnf(2).unwrap().is_empty());
    }

    #[test]
    fn the_trap_keeps_what_every_way_into_it_kept() {
        // Only q0 enters the trap: the trap's recovery set is q0's, and the trap's safe set
        // (Eq. 5C1 and progress-preserving alike) chooses from it instead of being empty.
        let aut = running_example();
        let trap = aut.trap().unwrap();
        assert_eq!(aut.recovery_cnf(), aut.trap_cnf(0).unwrap());
        let s = [0.5, 0.0];
        for progress in [false, true] {
            let in_trap = aut.safe_set(&s, trap, progress).unwrap();
            assert_eq!(in_trap, aut.safe_set(&s, 0, progress).unwrap());
        }
        // A formula without a trap keeps nothing.
        let spec = Spec::new(
            "F a",
            [("a", Predicate::halfspace(vec![1.0], 0.0).unwrap())],
        )
        .unwrap();
        assert!(Automaton::build(&spec).unwrap().recovery_cnf().is_empty());
    }

    #[test]
    fn running_example_safe_set_is_the_papers() {
        // Between a and b, far from c: the kept literals are !a and !b (paper: C(s, q0)).
        let aut = running_example();
        let kept = aut.safe_set(&[2.0, 0.0], 0, false).unwrap();
        let lit = |atom, positive| Literal { atom, positive };
        assert_eq!(kept, vec![(lit(0, false), 1.0), (lit(1, false), 1.0)]);
        // Inside a the first clause keeps !a (the best literal, though violated: -0.5 > -6.5).
        let kept = aut.safe_set(&[0.5, 0.0], 0, false).unwrap();
        assert_eq!(kept, vec![(lit(0, false), -0.5), (lit(1, false), 2.5)]);
        assert!(aut.safe_set(&[2.0, 0.0], 2, false).unwrap().is_empty());
    }

    #[test]
    fn running_example_rewards_by_hand() {
        let aut = running_example();
        // s' = (2, 0): rho(a) = rho(b) = -1, rho(c) = -5. D_q0 = (!a&!b&c) | (a&c) | (b&c) = -5;
        // negated trap guard (!a|c)&(!b|c) = 1, times c_r = 2 -> 2; reward = min(-5, 2).
        assert_eq!(aut.reward(&[2.0, 0.0], 0, 2.0, None).unwrap(), -5.0);
        // s' = (0.5, 0), inside a: rho(a) = 0.5, rho(b) = -2.5, rho(c) = -6.5.
        // D_q0 = -6.5; CNF = min(max(-0.5, -6.5), max(2.5, -6.5)) = -0.5 -> c_r * -0.5 = -1.
        assert_eq!(aut.reward(&[0.5, 0.0], 0, 2.0, None).unwrap(), -6.5);
        assert_eq!(aut.reward(&[0.5, 0.0], 0, 20.0, None).unwrap(), -10.0);
        // q2 has no trap edge: the reward is rho(a | b) = max(-1, -1).
        assert_eq!(aut.reward(&[2.0, 0.0], 2, 2.0, None).unwrap(), -1.0);
        assert_eq!(aut.reward(&[2.0, 0.0], 3, 2.0, None).unwrap(), 0.0);
        assert!(matches!(
            aut.reward(&[2.0, 0.0], 1, 2.0, None),
            Err(AutomatonError::TrapReward(1))
        ));
        assert_eq!(aut.reward(&[2.0, 0.0], 1, 2.0, Some(-7.0)).unwrap(), -7.0);
        crate::tests_support::assert_error(
            aut.reward(&[2.0, 0.0], 0, 0.0, None),
            "Input(Value",
            "c_r",
        );
        crate::tests_support::assert_error(
            aut.reward(&[2.0, 0.0], 9, 1.0, None),
            "UnknownState",
            "q",
        );
        crate::tests_support::assert_error(
            aut.reward(&[f64::NAN, 0.0], 0, 1.0, None),
            "Input(NonFinite",
            "s[0]",
        );
    }

    #[test]
    fn goals_follow_eq_5b1() {
        let aut = running_example();
        // At q0 the edge to q2 (reach c) is the only one that does not risk the trap first;
        // D_q0's best cube decides: from x = 2 the cube !a & !b & c scores min(1, 1, -5) = -5,
        // a & c and b & c score -5 too; the first best (to q2, cube !a & !b & c) wins -> c.
        assert_eq!(aut.goal(&[2.0, 0.0], 0).unwrap(), Some(vec![8.0, 0.0]));
        // At q2 (after c): a or b, whichever is closer.
        assert_eq!(aut.goal(&[3.0, 0.0], 2).unwrap(), Some(vec![4.0, 0.0]));
        assert_eq!(aut.goal(&[1.0, 0.0], 2).unwrap(), Some(vec![0.0, 0.0]));
        // Accepting and trap states have no goal.
        assert_eq!(aut.goal(&[1.0, 0.0], 3).unwrap(), None);
        assert_eq!(aut.goal(&[1.0, 0.0], 1).unwrap(), None);
        // A cube with two positive balls aims at the mean of their centres.
        let task = task();
        let mut s = [0.0; 13];
        s[..2].copy_from_slice(&[1.1, 1.0]);
        s[3..9].copy_from_slice(&[1.0, 1.0, 5.0, 4.0, 1.2, 1.0]);
        // Inside both g1 and g3 (they overlap): the cube g1 & g3 (to acceptance) is the best.
        let goal = task.goal(&s, 0).unwrap().unwrap();
        assert!((goal[0] - 1.1).abs() < 1e-12 && (goal[1] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_formula_alone_gives_the_same_automaton_and_reads_no_state() {
        let task = task();
        let alone = Automaton::build(&Spec::from_formula(crate::fixtures::TASK).unwrap()).unwrap();
        assert_eq!(alone.edges(), task.edges());
        assert_eq!(
            (alone.initial(), alone.trap()),
            (task.initial(), task.trap())
        );
        assert_eq!(alone.trap_cnf(0).unwrap(), task.trap_cnf(0).unwrap());
        let s = [0.0; 13];
        crate::tests_support::assert_error(alone.read(&s), "Value", "spec");
        crate::tests_support::assert_error(alone.step(&s, 0), "Input(Value", "spec");
        crate::tests_support::assert_error(alone.safe_set(&s, 0, false), "Input(Value", "spec");
        crate::tests_support::assert_error(alone.goal(&s, 0), "Input(Value", "spec");
    }

    #[test]
    fn a_moving_goal_outside_the_channel_is_passed_over() {
        let aut = crate::fixtures::task_automaton();
        // Agent at the origin; g1 at (4, 0) lies wholly outside the channel |x - y| < 1.5, g2
        // at (4, 4) inside it, g3 at (9, 9). g1 is nearer, but its cube (g1 & c1 & c2) cannot
        // hold: the goal is g2's centre.
        let mut s = vec![0.0; crate::fixtures::STATE_DIM];
        s[3..9].copy_from_slice(&[4.0, 0.0, 4.0, 4.0, 9.0, 9.0]);
        let q = aut.step(&s, aut.initial()).unwrap();
        assert_eq!(aut.goal(&s, q).unwrap(), Some(vec![4.0, 4.0]));
        // With g1 inside the channel too, the nearer one wins.
        s[3..5].copy_from_slice(&[2.0, 1.0]);
        assert_eq!(aut.goal(&s, q).unwrap(), Some(vec![2.0, 1.0]));
    }

    #[test]
    fn task_automaton() {
        let aut = task();
        assert_eq!(
            (aut.num_states(), aut.initial(), aut.trap()),
            (4, 0, Some(1))
        );
        assert_eq!(aut.accepting(), vec![2]);
        assert_eq!(
            edge_list(&aut),
            owned(&[
                (0, 0, "!g1 & !g2 & !g3 & c1 & c2"),
                (0, 1, "!g3 & !c1 | !g3 & !c2 | !g1 & !g2 & g3"),
                (0, 2, "g1 & g3 | g2 & g3"),
                (0, 3, "g1 & !g3 & c1 & c2 | g2 & !g3 & c1 & c2"),
                (1, 1, "true"),
                (2, 2, "true"),
                (3, 1, "!g3 & !c1 | !g3 & !c2"),
                (3, 2, "g3"),
                (3, 3, "!g3 & c1 & c2"),
            ])
        );
        assert_eq!(cnf_text(&aut, 0), ["g3 | c1", "g3 | c2", "g1 | g2 | !g3"]);
        assert_eq!(cnf_text(&aut, 3), ["g3 | c1", "g3 | c2"]);
    }

    #[test]
    fn task_safe_set_near_the_channel_border_keeps_the_channel() {
        let aut = task();
        // x = 0, y = 1.4: c1 = x - y + 1.5 = 0.1 (near the border), c2 = 2.9; goals far away.
        let mut s = [0.0; 13];
        s[1] = 1.4;
        s[3..9].copy_from_slice(&[3.0, 3.0, 5.0, 4.0, 8.0, 8.0]);
        let kept = aut.safe_set(&s, 0, false).unwrap();
        let names: Vec<_> = kept
            .iter()
            .map(|(l, _)| (aut.spec().atoms()[l.atom].as_str(), l.positive))
            .collect();
        assert_eq!(names, [("c1", true), ("c2", true), ("g3", false)]);
        assert!((kept[0].1 - 0.1).abs() < 1e-12 && (kept[1].1 - 2.9).abs() < 1e-12);
        assert!((kept[2].1 - ((8.0f64.powi(2) + 6.6f64.powi(2)).sqrt() - 0.5)).abs() < 1e-12);
    }

    #[test]
    fn unsatisfiable_and_trivial_formulas() {
        let p = Predicate::halfspace(vec![1.0], 0.0).unwrap();
        let unsat =
            Automaton::build(&Spec::new("F false & p", [("p", p.clone())]).unwrap()).unwrap();
        assert_eq!(unsat.trap(), Some(unsat.initial()));
        assert!(unsat.accepting().is_empty());
        let valid = Automaton::build(&Spec::new("true | p", [("p", p.clone())]).unwrap()).unwrap();
        assert_eq!(valid.trap(), None);
        let next = Automaton::build(&Spec::new("X (p | true)", [("p", p)]).unwrap()).unwrap();
        let one = [1.0];
        assert!(!next.accepts(Trajectory::new(&one, 1).unwrap()).unwrap());
        let two = [1.0, -1.0];
        assert!(next.accepts(Trajectory::new(&two, 1).unwrap()).unwrap());
    }

    #[test]
    fn too_many_atoms_is_an_error() {
        let names: Vec<String> = (0..31).map(|i| format!("p{i}")).collect();
        let text = names
            .iter()
            .map(|n| format!("F {n}"))
            .collect::<Vec<_>>()
            .join(" | ");
        let p = Predicate::halfspace(vec![1.0], 0.0).unwrap();
        let spec = Spec::new(&text, names.iter().map(|n| (n.as_str(), p.clone()))).unwrap();
        let err = Automaton::build(&spec).unwrap_err();
        assert_eq!(
            err.to_string(),
            "the formula has 31 atoms; automata support at most 30"
        );
    }

    #[test]
    fn oversized_automata_are_an_error() {
        // 16 independent goals: 2^16 states by nature, refused at MAX_STATES.
        let names: Vec<String> = (0..16).map(|i| format!("p{i}")).collect();
        let text = names
            .iter()
            .map(|n| format!("F {n}"))
            .collect::<Vec<_>>()
            .join(" & ");
        let p = Predicate::halfspace(vec![1.0], 0.0).unwrap();
        let spec = Spec::new(&text, names.iter().map(|n| (n.as_str(), p.clone()))).unwrap();
        let err = Automaton::build(&spec).unwrap_err().to_string();
        assert!(err.contains("too large"), "{err}");
        // Ten of them fit: 2^10 states.
        let text = names[..10]
            .iter()
            .map(|n| format!("F {n}"))
            .collect::<Vec<_>>()
            .join(" & ");
        let spec = Spec::new(&text, names.iter().map(|n| (n.as_str(), p.clone()))).unwrap();
        assert_eq!(Automaton::build(&spec).unwrap().num_states(), 1 << 10);
    }

    #[test]
    fn dot_marks_accepting_and_trap() {
        let dot = task().to_dot();
        assert!(dot.contains("q2 [shape=doublecircle]"));
        assert!(dot.contains("q1 [label=\"q1\\ntrap\""));
        assert!(dot.contains("start -> q0;"));
    }

    /// Boolean semantics over a word of valuations: independent of progression.
    fn sat(f: &Formula, word: &[usize], t: usize) -> bool {
        match f {
            Formula::True => true,
            Formula::False => false,
            Formula::Atom(i) => t < word.len() && word[t] >> i & 1 == 1,
            Formula::Not(a) => !sat(a, word, t),
            Formula::And(v) => v.iter().all(|g| sat(g, word, t)),
            Formula::Or(v) => v.iter().any(|g| sat(g, word, t)),
            Formula::Implies(a, b) => !sat(a, word, t) || sat(b, word, t),
            Formula::Eventually(a) => (t..word.len()).any(|u| sat(a, word, u)),
            Formula::Next(a) => t + 1 < word.len() && sat(a, word, t + 1),
            Formula::Until(a, b) => {
                (t..word.len()).any(|u| sat(b, word, u) && (t..u).all(|v| sat(a, word, v)))
            }
        }
    }

    fn words(letters: usize, len: usize) -> Vec<Vec<usize>> {
        (0..len).fold(vec![vec![]], |acc, _| {
            acc.into_iter()
                .flat_map(|w| (0..letters).map(move |v| [w.clone(), vec![v]].concat()))
                .collect()
        })
    }

    proptest! {
        #![proptest_config(crate::tests_support::seeded(1500))]

        #[test]
        fn acceptance_equals_the_formula_on_trajectories(f in co_safe(), data in trajectory()) {
            let spec = spec_for(&f);
            let aut = Automaton::build(&spec).unwrap();
            let traj = Trajectory::new(&data, 3).unwrap();
            prop_assert_eq!(aut.accepts(traj).unwrap(), spec.satisfied(traj).unwrap());
        }

        #[test]
        fn acceptance_and_trap_on_words(f in co_safe(), raw in prop::collection::vec(0usize..16, 1..6)) {
            let spec = spec_for(&f);
            let aut = Automaton::build(&spec).unwrap();
            let letters = 1usize << spec.atoms().len();
            let word: Vec<usize> = raw.iter().map(|v| v % letters).collect();
            // Every prefix: acceptance equals the formula on that prefix, and the trap is
            // entered exactly when no extension satisfies it. Shortest witnesses are shorter
            // than the number of states, so extensions up to that length decide it.
            let mut q = aut.initial();
            for k in 0..word.len() {
                q = aut.step_valuation(q, word[k]);
                let prefix = &word[..=k];
                prop_assert_eq!(aut.is_accepting(q), sat(spec.formula(), prefix, 0));
                let bound = aut.num_states().saturating_sub(1);
                if (letters as f64).powi(bound as i32) <= 4096.0 {
                    let extendable = (0..=bound).any(|len| {
                        words(letters, len).iter().any(|ext| sat(spec.formula(), &[prefix, ext].concat(), 0))
                    });
                    prop_assert_eq!(Some(q) == aut.trap(), !extendable);
                } else if Some(q) == aut.trap() {
                    for ext in words(letters, 2) {
                        prop_assert!(!sat(spec.formula(), &[prefix, &ext[..]].concat(), 0));
                    }
                }
            }
        }

        #[test]
        fn automaton_is_minimal_and_deterministic(f in co_safe()) {
            let spec = spec_for(&f);
            let a = Automaton::build(&spec).unwrap();
            let b = Automaton::build(&spec).unwrap();
            prop_assert_eq!(a.edges(), b.edges());
            prop_assert_eq!(a.accepting().len() <= 1, true);
            // Every state is reachable from the initial one (breadth-first numbering).
            let letters = 1usize << spec.atoms().len();
            let mut seen = vec![false; a.num_states()];
            seen[a.initial()] = true;
            let mut stack = vec![a.initial()];
            while let Some(q) = stack.pop() {
                for v in 0..letters {
                    let d = a.step_valuation(q, v);
                    if !seen[d] { seen[d] = true; stack.push(d); }
                }
            }
            prop_assert!(seen.iter().all(|s| *s));
        }
    }

    #[test]
    fn a_build_asked_to_stop_stops() {
        // Ten independent goals: 1024 states, so the build asks more than once.
        let formula = (1..10).fold("F a0".to_string(), |f, i| f + &format!(" & F a{i}"));
        let spec = Spec::from_formula(&formula).unwrap();
        let asked = std::cell::Cell::new(0);
        let err = Automaton::build_until(&spec, &|| {
            asked.set(asked.get() + 1);
            asked.get() > 3
        })
        .unwrap_err();
        assert_eq!(err, AutomatonError::Interrupted);
        assert_eq!(asked.get(), 4);
        assert_eq!(
            Automaton::build_until(&spec, &|| false)
                .unwrap()
                .num_states(),
            1 << 10
        );
    }
}
