//! The FSA of an scTLTL formula, built natively: formula progression over the valuations of
//! the atoms with canonical simplification, acceptance by end-of-trace evaluation, then
//! minimisation. The result is unique for the formula's language: one absorbing accepting
//! state, and at most one trap state (no path to acceptance). Guards are minimised DNFs.
//!
//! The FSA reads every state of a trajectory: `q_0 = delta(initial, s_0)`,
//! `q_{t+1} = delta(q_t, s_{t+1})`; an atom holds iff its robustness is > 0.
//!
//! Also here: the FSA-augmented reward (Eq. 5A1) and the CBF safe set (Eq. 5C1).

use std::collections::{HashMap, VecDeque};
use std::hash::{BuildHasherDefault, Hasher};

use rayon::prelude::*;
use smallvec::{smallvec, SmallVec};

use crate::cnf::{self, Cube, Literal};
use crate::error::{AutomatonError, InputError};
use crate::formula::Formula;
use crate::predicate::{Center, Predicate};
use crate::robustness::Trajectory;
use crate::spec::Spec;
use crate::validate::check_finite;

/// Most atoms an automaton supports (its alphabet has `2^atoms` letters).
pub const MAX_ATOMS: usize = 16;

/// Most transitions (states x 2^atoms) an automaton may have: its table stays under 16 MiB.
pub const MAX_TRANSITIONS: usize = 1 << 22;

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
    /// `table[q * letters + v]`: the successor of `q` on valuation `v`.
    table: Vec<u32>,
    edges: Vec<Edge>,
    /// Per state: the cubes of D_q, the OR of the guards to states other than q and the trap.
    progress: Vec<Vec<Cube>>,
    /// Per state: the guard of its edge to the trap (empty: no such edge).
    trap_guard: Vec<Vec<Cube>>,
    /// Per state: the CNF of the negated trap guard (empty: no trap edge).
    trap_cnf: Vec<Vec<Vec<Literal>>>,
}

/// Most distinct temporal obligations (subformulas under `F`, `U`, `X`) a formula may have.
pub const MAX_OBLIGATIONS: usize = 128;

/// A positive Boolean combination of obligations in canonical DNF: each cube is a set of
/// obligation ids (bit `k`: obligation `k` must hold at the start of the rest of the trace).
/// Cubes are sorted and no cube contains another (absorption), so equal functions of the
/// obligations get equal values and progression reaches finitely many of them.
/// `[]` is false; `[0]` (the empty cube) is true.
///
/// Stored inline up to four cubes (the common case), so progression rarely allocates.
type Dnf = SmallVec<[u128; 4]>;

const TRUE: u128 = 0;

/// Canonical form in place: sorted, no duplicates, no cube containing another.
fn absorb(mut cubes: Dnf) -> Dnf {
    if cubes.len() < 2 {
        return cubes;
    }
    // Fewest obligations first, so a cube can only be absorbed by one kept before it.
    cubes.sort_unstable_by_key(|c| (c.count_ones(), *c));
    cubes.dedup();
    let mut kept = 0;
    for i in 0..cubes.len() {
        let c = cubes[i];
        if !cubes[..kept].iter().any(|&d| d & !c == 0) {
            cubes[kept] = c;
            kept += 1;
        }
    }
    cubes.truncate(kept);
    cubes.sort_unstable();
    cubes
}

fn dnf_or(mut a: Dnf, b: &[u128]) -> Dnf {
    a.extend_from_slice(b);
    absorb(a)
}

fn dnf_and(a: &[u128], b: &[u128]) -> Dnf {
    // Fast paths: `true` is the identity, `false` absorbs, and two single cubes make one.
    match (a, b) {
        ([TRUE], other) | (other, [TRUE]) => return SmallVec::from_slice(other),
        ([], _) | (_, []) => return SmallVec::new(),
        (&[x], &[y]) => return smallvec![x | y],
        _ => {}
    }
    absorb(
        a.iter()
            .flat_map(|x| b.iter().map(move |y| x | y))
            .collect(),
    )
}

fn constant(b: bool) -> Dnf {
    if b {
        smallvec![TRUE]
    } else {
        SmallVec::new()
    }
}

/// Truth of a propositional formula under valuation `v`.
fn holds(f: &Formula, v: u32) -> bool {
    match f {
        Formula::True => true,
        Formula::False => false,
        Formula::Atom(i) => v >> i & 1 == 1,
        Formula::Not(a) => !holds(a, v),
        Formula::And(parts) => parts.iter().all(|p| holds(p, v)),
        Formula::Or(parts) => parts.iter().any(|p| holds(p, v)),
        Formula::Implies(a, b) => !holds(a, v) || holds(b, v),
        // Co-safety puts only propositional formulas under `!` and left of `->`, the only
        // places this is called.
        Formula::Until(..) | Formula::Eventually(_) | Formula::Next(_) => false,
    }
}

/// The atoms occurring in `f` (bit `i`: atom `i`); progression of `f` reads no others.
fn atom_mask(f: &Formula) -> u32 {
    match f {
        Formula::True | Formula::False => 0,
        Formula::Atom(i) => 1 << i,
        Formula::Not(a) | Formula::Eventually(a) | Formula::Next(a) => atom_mask(a),
        Formula::And(parts) | Formula::Or(parts) => parts.iter().fold(0, |m, p| m | atom_mask(p)),
        Formula::Implies(a, b) | Formula::Until(a, b) => atom_mask(a) | atom_mask(b),
    }
}

/// A small, fast hasher for the build's maps (keys are addresses and short bit vectors; no
/// untrusted input reaches them).
#[derive(Default)]
struct FxHasher(u64);

impl Hasher for FxHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }

    fn write_u128(&mut self, i: u128) {
        self.write_u64(i as u64);
        self.write_u64((i >> 64) as u64);
    }

    fn write_usize(&mut self, i: usize) {
        self.write_u64(i as u64);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<FxHasher>>;

/// The obligations of a formula: the subformulas that can be left to hold "from the next
/// state on" (the formula itself, every `F` and `U` node, every `X` operand). Structurally
/// equal subformulas share an id; ids are assigned once, before exploring.
struct Obligations<'f> {
    formulas: Vec<&'f Formula>,
    /// The atoms each obligation reads: its progression depends on `v & masks[k]` only.
    masks: Vec<u32>,
    /// Node address -> obligation id.
    by_node: FastMap<*const Formula, usize>,
    /// `progress(formulas[k], v & masks[k])` by `(k, v & masks[k])`, computed on first use
    /// (a map: only the projections actually reached are stored).
    memo: FastMap<(usize, u32), Dnf>,
}

impl<'f> Obligations<'f> {
    fn new(root: &'f Formula) -> Result<Self, AutomatonError> {
        let mut this = Obligations {
            formulas: Vec::new(),
            masks: Vec::new(),
            by_node: FastMap::default(),
            memo: FastMap::default(),
        };
        let mut structural: FastMap<&'f Formula, usize> = FastMap::default();
        this.register(root, &mut structural)?;
        this.visit(root, &mut structural)?;
        Ok(this)
    }

    fn register(
        &mut self,
        f: &'f Formula,
        structural: &mut FastMap<&'f Formula, usize>,
    ) -> Result<(), AutomatonError> {
        let next = self.formulas.len();
        let id = *structural.entry(f).or_insert(next);
        if id == next {
            if next == MAX_OBLIGATIONS {
                return Err(AutomatonError::TooManyObligations(MAX_OBLIGATIONS));
            }
            self.formulas.push(f);
            self.masks.push(atom_mask(f));
        }
        self.by_node.insert(f as *const Formula, id);
        Ok(())
    }

    fn visit(
        &mut self,
        f: &'f Formula,
        structural: &mut FastMap<&'f Formula, usize>,
    ) -> Result<(), AutomatonError> {
        match f {
            Formula::True | Formula::False | Formula::Atom(_) => {}
            Formula::Not(a) => self.visit(a, structural)?,
            Formula::And(parts) | Formula::Or(parts) => {
                for p in parts {
                    self.visit(p, structural)?;
                }
            }
            Formula::Implies(a, b) => {
                self.visit(a, structural)?;
                self.visit(b, structural)?;
            }
            Formula::Eventually(a) => {
                self.register(f, structural)?;
                self.visit(a, structural)?;
            }
            Formula::Until(a, b) => {
                self.register(f, structural)?;
                self.visit(a, structural)?;
                self.visit(b, structural)?;
            }
            Formula::Next(a) => {
                self.register(a, structural)?;
                self.visit(a, structural)?;
            }
        }
        Ok(())
    }

    fn id(&self, f: &Formula) -> u128 {
        1u128 << self.by_node[&(f as *const Formula)]
    }

    /// What remains of "`f` holds from here" after reading a state with valuation `v`.
    fn progress(&self, f: &Formula, v: u32) -> Dnf {
        match f {
            Formula::True | Formula::False | Formula::Atom(_) | Formula::Not(_) => {
                constant(holds(f, v))
            }
            Formula::And(parts) => parts.iter().fold(smallvec![TRUE], |acc, p| {
                dnf_and(&acc, &self.progress(p, v))
            }),
            Formula::Or(parts) => parts
                .iter()
                .fold(SmallVec::new(), |acc, p| dnf_or(acc, &self.progress(p, v))),
            Formula::Implies(a, b) if holds(a, v) => self.progress(b, v),
            Formula::Implies(..) => smallvec![TRUE],
            Formula::Eventually(a) => dnf_or(self.progress(a, v), &[self.id(f)]),
            Formula::Until(a, b) => {
                let keep = dnf_and(&self.progress(a, v), &[self.id(f)]);
                dnf_or(self.progress(b, v), &keep)
            }
            // `X a`: `a` must hold from the next state on (which must exist).
            Formula::Next(a) => smallvec![self.id(a)],
        }
    }

    /// "`f` holds from here" as a DNF over obligations, when `f` is an `&`/`|` combination of
    /// `F`/`U` nodes (the usual shape of a task); `None` otherwise. Starting from this
    /// instead of `[f]` spares progressing the whole formula once per letter: only its parts
    /// are progressed, each over the few atoms it reads.
    fn unfold(&self, f: &Formula) -> Option<Dnf> {
        match f {
            Formula::Eventually(_) | Formula::Until(..) => Some(smallvec![self.id(f)]),
            Formula::And(parts) => parts.iter().try_fold(smallvec![TRUE], |acc: Dnf, p| {
                Some(dnf_and(&acc, &self.unfold(p)?))
            }),
            Formula::Or(parts) => parts
                .iter()
                .try_fold(Dnf::new(), |acc, p| Some(dnf_or(acc, &self.unfold(p)?))),
            _ => None,
        }
    }

    /// The atoms a residual reads: its successor depends on `v & mask` only.
    fn residual_mask(&self, residual: &[u128]) -> u32 {
        let used = residual.iter().fold(0u128, |m, c| m | c);
        (0..self.formulas.len())
            .filter(|k| used >> k & 1 == 1)
            .fold(0, |m, k| m | self.masks[k])
    }

    /// Progression of a whole residual.
    fn step(&mut self, residual: &[u128], v: u32) -> Dnf {
        let mut out = Dnf::new();
        for &cube in residual {
            let mut acc: Dnf = smallvec![TRUE];
            let mut bits = cube;
            while bits != 0 && !acc.is_empty() {
                let k = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let key = (k, v & self.masks[k]);
                acc = match self.memo.get(&key) {
                    Some(progressed) => dnf_and(&acc, progressed),
                    None => {
                        let progressed = self.progress(self.formulas[k], key.1);
                        let product = dnf_and(&acc, &progressed);
                        self.memo.insert(key, progressed);
                        product
                    }
                };
            }
            out.extend(acc);
        }
        absorb(out)
    }
}

impl Automaton {
    /// Builds the minimal automaton of `spec`'s formula.
    pub fn build(spec: &Spec) -> Result<Self, AutomatonError> {
        let n = spec.atoms().len();
        if n > MAX_ATOMS {
            return Err(AutomatonError::TooManyAtoms {
                atoms: n,
                max: MAX_ATOMS,
            });
        }
        let letters = 1usize << n;

        // 1. Explore the residuals reachable by progression. A residual holds on the empty
        //    rest of a trace iff it is `true` (every obligation needs a state).
        let mut obligations = Obligations::new(spec.formula())?;
        let start: Dnf = obligations
            .unfold(spec.formula())
            .unwrap_or_else(|| smallvec![obligations.id(spec.formula())]);
        let mut ids: FastMap<Dnf, usize> = FastMap::default();
        ids.insert(start.clone(), 0);
        let mut residuals = vec![start];
        let mut raw: Vec<u32> = Vec::new();
        let mut raw_masks: Vec<u32> = Vec::new();
        let mut next = 0;
        // Successor per projected valuation `v & mask` of the current residual.
        let mut by_projection = vec![u32::MAX; letters];
        while next < residuals.len() {
            let current = residuals[next].clone();
            let mask = obligations.residual_mask(&current);
            raw_masks.push(mask);
            by_projection.fill(u32::MAX);
            for v in 0..letters as u32 {
                let projected = (v & mask) as usize;
                if by_projection[projected] != u32::MAX {
                    raw.push(by_projection[projected]);
                    continue;
                }
                let succ = obligations.step(&current, v & mask);
                let id = match ids.get(&succ) {
                    Some(&id) => id,
                    None => {
                        if (residuals.len() + 1) * letters > MAX_TRANSITIONS {
                            return Err(AutomatonError::TooLarge {
                                states: residuals.len() + 1,
                                letters,
                                max: MAX_TRANSITIONS,
                            });
                        }
                        ids.insert(succ.clone(), residuals.len());
                        residuals.push(succ);
                        residuals.len() - 1
                    }
                };
                by_projection[projected] = id as u32;
                raw.push(id as u32);
            }
            next += 1;
        }
        let accepting_raw: Vec<bool> = residuals.iter().map(|r| r.contains(&TRUE)).collect();

        // 2. Minimise (Moore refinement), then number states breadth-first from the start.
        let block = minimise(&raw, &accepting_raw, letters);
        let blocks = block.iter().max().map_or(0, |m| m + 1);
        let mut representative = vec![usize::MAX; blocks];
        for (q, &b) in block.iter().enumerate().rev() {
            representative[b] = q;
        }
        let mut order = vec![usize::MAX; blocks];
        let mut queue = VecDeque::from([block[0]]);
        order[block[0]] = 0;
        let mut count = 1;
        let mut table = vec![0u32; blocks * letters];
        let mut visit = Vec::with_capacity(blocks);
        while let Some(b) = queue.pop_front() {
            visit.push(b);
            let q = representative[b];
            for v in 0..letters {
                let nb = block[raw[q * letters + v] as usize];
                if order[nb] == usize::MAX {
                    order[nb] = count;
                    count += 1;
                    queue.push_back(nb);
                }
            }
        }
        for &b in &visit {
            let q = representative[b];
            for v in 0..letters {
                table[order[b] * letters + v] = order[block[raw[q * letters + v] as usize]] as u32;
            }
        }
        let num_states = count;
        table.truncate(num_states * letters);
        let mut accepting = vec![false; num_states];
        for &b in &visit {
            accepting[order[b]] = accepting_raw[representative[b]];
        }

        // 3. The trap: the state from which no accepting state is reachable (at most one
        //    after minimisation).
        let mut reaches = accepting.clone();
        loop {
            let mut changed = false;
            for q in 0..num_states {
                if !reaches[q]
                    && table[q * letters..(q + 1) * letters]
                        .iter()
                        .any(|&d| reaches[d as usize])
                {
                    reaches[q] = true;
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        let trap = reaches.iter().position(|r| !r);

        // 4. Guards.
        //    A state's row depends only on the atoms its residual reads (`mask`), so each
        //    guard is minimised over those atoms alone.
        let mut mask_of = vec![0u32; num_states];
        for &b in &visit {
            mask_of[order[b]] = raw_masks[representative[b]];
        }
        let mut edges = Vec::new();
        let mut by_dst: Vec<Vec<u32>> = vec![Vec::new(); num_states];
        for src in 0..num_states {
            let mask = mask_of[src];
            by_dst.iter_mut().for_each(Vec::clear);
            for v in (0..letters as u32).filter(|v| v & !mask == 0) {
                by_dst[table[src * letters + v as usize] as usize].push(v);
            }
            for (dst, minterms) in by_dst.iter().enumerate() {
                if !minterms.is_empty() {
                    edges.push(Edge {
                        src,
                        dst,
                        guard: cnf::minimise_within(minterms, mask),
                    });
                }
            }
        }
        let mut progress_cubes = vec![Vec::new(); num_states];
        let mut trap_guard = vec![Vec::new(); num_states];
        for e in &edges {
            if Some(e.dst) == trap && e.src != e.dst {
                trap_guard[e.src] = e.guard.clone();
            } else if e.dst != e.src && Some(e.dst) != trap {
                progress_cubes[e.src].extend_from_slice(&e.guard);
            }
        }
        let trap_cnf = trap_guard.iter().map(|g| cnf::complement_cnf(g)).collect();
        Ok(Automaton {
            spec: spec.clone(),
            letters,
            initial: 0,
            accepting,
            trap,
            table,
            edges,
            progress: progress_cubes,
            trap_guard,
            trap_cnf,
        })
    }

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
        self.check_state("q", q as i64)?;
        Ok(&self.trap_cnf[q])
    }

    /// The guard of `q`'s edge to the trap (empty: none).
    pub fn trap_guard(&self, q: usize) -> Result<&[Cube], AutomatonError> {
        self.check_state("q", q as i64)?;
        Ok(&self.trap_guard[q])
    }

    /// The cubes of D_q (Eq. 5A1): the guards of `q`'s edges to other non-trap states.
    pub fn progress_guard(&self, q: usize) -> Result<&[Cube], AutomatonError> {
        self.check_state("q", q as i64)?;
        Ok(&self.progress[q])
    }

    /// Checks a state id given by a caller.
    pub fn check_state(&self, what: &str, q: i64) -> Result<usize, AutomatonError> {
        match usize::try_from(q) {
            Ok(q) if q < self.num_states() => Ok(q),
            _ => Err(AutomatonError::UnknownState {
                what: what.into(),
                q,
                num_states: self.num_states(),
            }),
        }
    }

    fn check_vector(&self, s: &[f64]) -> Result<(), InputError> {
        self.spec.check_state_len(s.len())?;
        check_finite("s", s, s.len())
    }

    /// Atom robustness at `s` into a stack buffer (no allocation).
    #[inline]
    fn atom_rho(&self, s: &[f64]) -> [f64; MAX_ATOMS] {
        let mut rho = [0.0; MAX_ATOMS];
        self.spec
            .atom_robustness_into(s, &mut rho[..self.spec.atoms().len()]);
        rho
    }

    #[inline]
    fn valuation(rho: &[f64]) -> usize {
        rho.iter()
            .enumerate()
            .fold(0, |v, (i, &r)| v | (usize::from(r > 0.0) << i))
    }

    /// The successor of `q` after reading state `s` (validated).
    pub fn step(&self, q: usize, s: &[f64]) -> Result<usize, AutomatonError> {
        self.check_state("q", q as i64)?;
        self.check_vector(s)?;
        Ok(self.step_unchecked(q, s))
    }

    /// The successor of `q` on the atom valuation `v` (bit `i` set: atom `i` holds). The caller
    /// guarantees `q < num_states()` and `v < 2^atoms`.
    pub fn step_valuation(&self, q: usize, v: usize) -> usize {
        self.table[q * self.letters + v] as usize
    }

    /// [`Automaton::step`] for inputs the caller has validated.
    #[inline]
    pub fn step_unchecked(&self, q: usize, s: &[f64]) -> usize {
        let rho = self.atom_rho(s);
        let v = Self::valuation(&rho[..self.spec.atoms().len()]);
        self.table[q * self.letters + v] as usize
    }

    /// Steps a batch in parallel: row `i` of `states` (row-major, `dim` values) from `qs[i]`.
    pub fn step_batch(
        &self,
        qs: &[i64],
        states: &[f64],
        dim: usize,
    ) -> Result<Vec<usize>, AutomatonError> {
        if dim == 0 || states.len() != qs.len() * dim {
            return Err(InputError::Shape {
                what: "states".into(),
                expected: format!("({}, n) to match qs", qs.len()),
                got: format!("{} values in rows of {dim}", states.len()),
            }
            .into());
        }
        self.spec.check_state_len(dim)?;
        check_finite("states", states, dim)?;
        let qs: Vec<usize> = qs
            .iter()
            .enumerate()
            .map(|(i, &q)| self.check_state(&format!("qs[{i}]"), q))
            .collect::<Result<_, _>>()?;
        Ok(qs
            .par_iter()
            .zip(states.par_chunks(dim))
            .map(|(&q, s)| self.step_unchecked(q, s))
            .collect())
    }

    /// The state after reading every state of `traj`, starting from the initial state.
    pub fn run(&self, traj: Trajectory<'_>) -> Result<usize, AutomatonError> {
        self.spec.check_state_len(traj.dim())?;
        Ok((0..traj.len()).fold(self.initial, |q, t| self.step_unchecked(q, traj.state(t))))
    }

    /// Whether the automaton accepts `traj` (reads every state, ends in an accepting state).
    pub fn accepts(&self, traj: Trajectory<'_>) -> Result<bool, AutomatonError> {
        Ok(self.accepting[self.run(traj)?])
    }

    /// The FSA-augmented reward of Eq. 5A1 for leaving `q` into state `s_next`:
    /// `min(rho(s', D_q), c_r * rho(s', !psi_{q,trap}))`, `rho(s', D_q)` without a trap edge,
    /// 0 in an accepting state, `trap_penalty` in the trap (an error when it is `None`).
    pub fn reward(
        &self,
        q: usize,
        s_next: &[f64],
        c_r: f64,
        trap_penalty: Option<f64>,
    ) -> Result<f64, AutomatonError> {
        self.check_state("q", q as i64)?;
        self.check_vector(s_next)?;
        self.check_weight(c_r)?;
        if Some(q) == self.trap {
            return self.trap_reward(q, trap_penalty);
        }
        Ok(self.reward_unchecked(q, s_next, c_r))
    }

    /// One step of the FSA-augmented loop from one evaluation of the atoms at `s_next`:
    /// the next state `q' = step(q, s_next)`, the reward of Eq. 5A1 for leaving `q`
    /// ([`Automaton::reward`]), and the safe set at `(s_next, q')` written into `safe`
    /// ([`Automaton::safe_set`]).
    pub fn advance(
        &self,
        q: usize,
        s_next: &[f64],
        c_r: f64,
        trap_penalty: Option<f64>,
        safe: &mut Vec<(Literal, f64)>,
    ) -> Result<(usize, f64), AutomatonError> {
        self.check_state("q", q as i64)?;
        self.check_vector(s_next)?;
        self.check_weight(c_r)?;
        let rho = self.atom_rho(s_next);
        let rho = &rho[..self.spec.atoms().len()];
        let reward = if Some(q) == self.trap {
            self.trap_reward(q, trap_penalty)?
        } else {
            self.reward_from(q, rho, c_r)
        };
        let next = self.table[q * self.letters + Self::valuation(rho)] as usize;
        safe.clear();
        safe.extend(cnf::safe_literals(&self.trap_cnf[next], rho));
        Ok((next, reward))
    }

    fn check_weight(&self, c_r: f64) -> Result<(), AutomatonError> {
        if c_r.is_finite() && c_r > 0.0 {
            return Ok(());
        }
        Err(InputError::Value {
            what: "c_r".into(),
            expected: "a finite weight > 0".into(),
            got: c_r.to_string(),
        }
        .into())
    }

    fn trap_reward(&self, q: usize, trap_penalty: Option<f64>) -> Result<f64, AutomatonError> {
        match trap_penalty {
            Some(p) if p.is_finite() => Ok(p),
            Some(p) => Err(InputError::NonFinite {
                what: "trap_penalty".into(),
                value: p,
            }
            .into()),
            None => Err(AutomatonError::TrapReward(q)),
        }
    }

    /// [`Automaton::reward`] for validated inputs and a non-trap `q`.
    #[inline]
    pub fn reward_unchecked(&self, q: usize, s_next: &[f64], c_r: f64) -> f64 {
        let rho = self.atom_rho(s_next);
        self.reward_from(q, &rho[..self.spec.atoms().len()], c_r)
    }

    /// The Eq. 5A1 value of being in `q` at a state whose atoms have robustness `rho`
    /// (validated inputs; 0 in an accepting state). The progress reward uses it as the
    /// within-state part of its potential.
    pub fn task_signal_from(&self, q: usize, rho: &[f64], c_r: f64) -> f64 {
        self.reward_from(q, rho, c_r)
    }

    /// [`Automaton::task_signal_from`] over the cubes of `D_q` that can hold where they lead:
    /// a cube whose positive Ball literal (a goal) has its centre violating one of the cube's
    /// other literals (e.g. a goal disc wholly outside the channel the cube also requires) is
    /// left out, so the shaping does not pull towards a goal the task cannot take. When every
    /// cube is left out, all count (the plain Eq. 5A1 value). Validated inputs.
    pub fn reachable_signal_from(&self, q: usize, s: &[f64], rho: &[f64], c_r: f64) -> f64 {
        if self.accepting[q] {
            return 0.0;
        }
        let mut at_goal: SmallVec<[f64; 32]> = SmallVec::from_slice(s);
        let mut best = f64::NEG_INFINITY;
        let mut any = false;
        for cube in &self.progress[q] {
            let ball = cube
                .literals()
                .find_map(|l| match &self.spec.predicates()[l.atom] {
                    Predicate::Ball(b) if l.positive => Some((l.atom, b)),
                    _ => None,
                });
            if let Some((atom, ball)) = ball {
                at_goal.copy_from_slice(s);
                for (k, &i) in ball.pos().iter().enumerate() {
                    at_goal[i] = match ball.center() {
                        Center::Fixed(c) => c[k],
                        Center::Dims(d) => s[d[k]],
                    };
                }
                let blocked = cube.literals().filter(|l| l.atom != atom).any(|l| {
                    let value = self.spec.predicates()[l.atom].value(&at_goal);
                    (if l.positive { value } else { -value }) < 0.0
                });
                if blocked {
                    continue;
                }
            }
            any = true;
            best = best.max(cube.robustness(rho));
        }
        if !any {
            return self.reward_from(q, rho, c_r);
        }
        if self.trap_cnf[q].is_empty() {
            best
        } else {
            best.min(c_r * cnf::cnf_robustness(&self.trap_cnf[q], rho))
        }
    }

    /// The atoms' robustness at `s` after checking its length and finiteness.
    pub fn checked_atom_robustness(&self, s: &[f64]) -> Result<[f64; MAX_ATOMS], InputError> {
        self.check_vector(s)?;
        Ok(self.atom_rho(s))
    }

    /// The successor of `q` given the atoms' robustness at the state read (validated).
    #[inline]
    pub fn step_rho(&self, q: usize, rho: &[f64]) -> usize {
        self.table[q * self.letters + Self::valuation(rho)] as usize
    }

    fn reward_from(&self, q: usize, rho: &[f64], c_r: f64) -> f64 {
        if self.accepting[q] {
            return 0.0;
        }
        let progress = cnf::dnf_robustness(&self.progress[q], rho);
        if self.trap_cnf[q].is_empty() {
            progress
        } else {
            progress.min(c_r * cnf::cnf_robustness(&self.trap_cnf[q], rho))
        }
    }

    /// The CBF safe set of Eq. 5C1 at `(s, q)`: per clause of the negated trap guard, the
    /// literal with the largest robustness at `s` and that robustness (empty without a trap
    /// edge).
    pub fn safe_set(&self, q: usize, s: &[f64]) -> Result<Vec<(Literal, f64)>, AutomatonError> {
        self.check_state("q", q as i64)?;
        self.check_vector(s)?;
        let mut out = Vec::with_capacity(self.trap_cnf[q].len());
        self.safe_set_into(q, s, &mut out);
        Ok(out)
    }

    /// [`Automaton::safe_set`] into a reused buffer, for validated inputs.
    pub fn safe_set_into(&self, q: usize, s: &[f64], out: &mut Vec<(Literal, f64)>) {
        out.clear();
        if !self.trap_cnf[q].is_empty() {
            self.safe_set_from(q, &self.atom_rho(s), out);
        }
    }

    /// [`Automaton::safe_set_into`] from the atoms' robustness (see
    /// [`Automaton::atom_robustness`]), so a caller that needs it elsewhere computes it once.
    pub fn safe_set_from(&self, q: usize, rho: &[f64], out: &mut Vec<(Literal, f64)>) {
        out.clear();
        out.extend(cnf::safe_literals(&self.trap_cnf[q], rho));
    }

    /// The robustness of every atom at `s` (validated input), in a stack buffer: the first
    /// `spec().atoms().len()` values are meaningful.
    pub fn atom_robustness(&self, s: &[f64]) -> [f64; MAX_ATOMS] {
        self.atom_rho(s)
    }

    /// The CLF goal of Eq. 5B1 at `(s, q)`: among `q`'s edges to other non-trap states the one
    /// whose guard has the largest robustness at `s` (the first on ties), in its DNF the cube
    /// with the largest robustness, and the mean of the centres of that cube's positive Ball
    /// literals. `None` when there is no such edge or the cube has no positive Ball literal.
    pub fn goal(&self, q: usize, s: &[f64]) -> Result<Option<Vec<f64>>, AutomatonError> {
        self.check_state("q", q as i64)?;
        self.check_vector(s)?;
        Ok(self.goal_unchecked(q, s))
    }

    /// [`Automaton::goal`] for validated inputs.
    pub fn goal_unchecked(&self, q: usize, s: &[f64]) -> Option<Vec<f64>> {
        let mut goal = Vec::new();
        self.goal_into(q, s, &mut goal).then_some(goal)
    }

    /// [`Automaton::goal`] into a reused buffer, for validated inputs; `false` when there is
    /// no goal (then `goal` is left empty).
    pub fn goal_into(&self, q: usize, s: &[f64], goal: &mut Vec<f64>) -> bool {
        self.goal_from(q, s, &self.atom_rho(s), goal)
    }

    /// [`Automaton::goal_into`] with the atoms' robustness at `s` already computed.
    pub fn goal_from(&self, q: usize, s: &[f64], rho: &[f64], goal: &mut Vec<f64>) -> bool {
        goal.clear();
        let Some((cube, _)) = self
            .edges
            .iter()
            .filter(|e| e.src == q && e.dst != q && Some(e.dst) != self.trap)
            .filter_map(|e| best_cube(&e.guard, rho))
            .fold(None, cnf::first_max)
        else {
            return false;
        };
        let mut count = 0.0;
        for lit in cube.literals().filter(|l| l.positive) {
            if let Predicate::Ball(ball) = &self.spec.predicates()[lit.atom] {
                let len = ball.pos().len();
                if count == 0.0 {
                    goal.resize(len, 0.0);
                } else if goal.len() != len {
                    continue;
                }
                match ball.center() {
                    Center::Fixed(c) => goal.iter_mut().zip(c).for_each(|(a, b)| *a += b),
                    Center::Dims(d) => goal.iter_mut().zip(d).for_each(|(a, &i)| *a += s[i]),
                }
                count += 1.0;
            }
        }
        if count == 0.0 {
            return false;
        }
        goal.iter_mut().for_each(|v| *v /= count);
        true
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
                cnf::dnf_text(&e.guard, atoms)
            ));
        }
        out.push_str("}\n");
        out
    }
}

/// The cube of a DNF with the largest robustness (the first on ties) and that robustness.
fn best_cube<'a>(guard: &'a [Cube], rho: &[f64]) -> Option<(&'a Cube, f64)> {
    guard
        .iter()
        .map(|c| (c, c.robustness(rho)))
        .fold(None, cnf::first_max)
}

/// Moore partition refinement: returns the block of every state, blocks numbered by first
/// occurrence.
fn minimise(table: &[u32], accepting: &[bool], letters: usize) -> Vec<usize> {
    let n = accepting.len();
    let mut block: Vec<usize> = accepting.iter().map(|&a| usize::from(a)).collect();
    let mut count = 0;
    // Signatures (own block, then the successors' blocks) live in one flat buffer.
    let width = letters + 1;
    let mut signatures = vec![0u32; n * width];
    let mut refined = vec![0; n];
    loop {
        for q in 0..n {
            let sig = &mut signatures[q * width..(q + 1) * width];
            sig[0] = block[q] as u32;
            for (slot, &d) in sig[1..]
                .iter_mut()
                .zip(&table[q * letters..(q + 1) * letters])
            {
                *slot = block[d as usize] as u32;
            }
        }
        let mut ids: FastMap<&[u32], usize> =
            FastMap::with_capacity_and_hasher(n, BuildHasherDefault::default());
        for (q, sig) in signatures.chunks_exact(width).enumerate() {
            let next_id = ids.len();
            refined[q] = *ids.entry(sig).or_insert(next_id);
        }
        let new_count = ids.len();
        std::mem::swap(&mut block, &mut refined);
        if new_count == count {
            return block;
        }
        count = new_count;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{co_safe, spec_for, trajectory};
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
            .map(|e| (e.src, e.dst, cnf::dnf_text(&e.guard, aut.spec().atoms())))
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
    fn running_example_safe_set_is_the_papers() {
        // Between a and b, far from c: the kept literals are !a and !b (paper: C(s, q0)).
        let aut = running_example();
        let kept = aut.safe_set(0, &[2.0, 0.0]).unwrap();
        let lit = |atom, positive| Literal { atom, positive };
        assert_eq!(kept, vec![(lit(0, false), 1.0), (lit(1, false), 1.0)]);
        // Inside a the first clause keeps !a (the best literal, though violated: -0.5 > -6.5).
        let kept = aut.safe_set(0, &[0.5, 0.0]).unwrap();
        assert_eq!(kept, vec![(lit(0, false), -0.5), (lit(1, false), 2.5)]);
        assert!(aut.safe_set(2, &[2.0, 0.0]).unwrap().is_empty());
    }

    #[test]
    fn running_example_rewards_by_hand() {
        let aut = running_example();
        // s' = (2, 0): rho(a) = rho(b) = -1, rho(c) = -5. D_q0 = (!a&!b&c) | (a&c) | (b&c) = -5;
        // negated trap guard (!a|c)&(!b|c) = 1, times c_r = 2 -> 2; reward = min(-5, 2).
        assert_eq!(aut.reward(0, &[2.0, 0.0], 2.0, None).unwrap(), -5.0);
        // s' = (0.5, 0), inside a: rho(a) = 0.5, rho(b) = -2.5, rho(c) = -6.5.
        // D_q0 = -6.5; CNF = min(max(-0.5, -6.5), max(2.5, -6.5)) = -0.5 -> c_r * -0.5 = -1.
        assert_eq!(aut.reward(0, &[0.5, 0.0], 2.0, None).unwrap(), -6.5);
        assert_eq!(aut.reward(0, &[0.5, 0.0], 20.0, None).unwrap(), -10.0);
        // q2 has no trap edge: the reward is rho(a | b) = max(-1, -1).
        assert_eq!(aut.reward(2, &[2.0, 0.0], 2.0, None).unwrap(), -1.0);
        assert_eq!(aut.reward(3, &[2.0, 0.0], 2.0, None).unwrap(), 0.0);
        assert!(matches!(
            aut.reward(1, &[2.0, 0.0], 2.0, None),
            Err(AutomatonError::TrapReward(1))
        ));
        assert_eq!(aut.reward(1, &[2.0, 0.0], 2.0, Some(-7.0)).unwrap(), -7.0);
        assert!(aut.reward(0, &[2.0, 0.0], 0.0, None).is_err());
        assert!(aut.reward(9, &[2.0, 0.0], 1.0, None).is_err());
        assert!(aut.reward(0, &[f64::NAN, 0.0], 1.0, None).is_err());
    }

    #[test]
    fn goals_follow_eq_5b1() {
        let aut = running_example();
        // At q0 the edge to q2 (reach c) is the only one that does not risk the trap first;
        // D_q0's best cube decides: from x = 2 the cube !a & !b & c scores min(1, 1, -5) = -5,
        // a & c and b & c score -5 too; the first best (to q2, cube !a & !b & c) wins -> c.
        assert_eq!(aut.goal(0, &[2.0, 0.0]).unwrap(), Some(vec![8.0, 0.0]));
        // At q2 (after c): a or b, whichever is closer.
        assert_eq!(aut.goal(2, &[3.0, 0.0]).unwrap(), Some(vec![4.0, 0.0]));
        assert_eq!(aut.goal(2, &[1.0, 0.0]).unwrap(), Some(vec![0.0, 0.0]));
        // Accepting and trap states have no goal.
        assert_eq!(aut.goal(3, &[1.0, 0.0]).unwrap(), None);
        assert_eq!(aut.goal(1, &[1.0, 0.0]).unwrap(), None);
        // A cube with two positive balls aims at the mean of their centres.
        let task = task();
        let mut s = [0.0; 13];
        s[..2].copy_from_slice(&[1.1, 1.0]);
        s[3..9].copy_from_slice(&[1.0, 1.0, 5.0, 4.0, 1.2, 1.0]);
        // Inside both g1 and g3 (they overlap): the cube g1 & g3 (to acceptance) is the best.
        let goal = task.goal(0, &s).unwrap().unwrap();
        assert!((goal[0] - 1.1).abs() < 1e-12 && (goal[1] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn advance_fuses_step_reward_and_safe_set() {
        let aut = running_example();
        let mut safe = Vec::new();
        for (q, s) in [
            (0, [2.0, 0.0]),
            (0, [8.0, 0.0]),
            (2, [4.5, 0.0]),
            (0, [0.5, 0.0]),
        ] {
            let (next, reward) = aut.advance(q, &s, 2.0, None, &mut safe).unwrap();
            assert_eq!(next, aut.step(q, &s).unwrap());
            assert_eq!(reward, aut.reward(q, &s, 2.0, None).unwrap());
            assert_eq!(safe, aut.safe_set(next, &s).unwrap());
        }
        assert!(aut.advance(1, &[0.0, 0.0], 2.0, None, &mut safe).is_err());
        assert_eq!(
            aut.advance(1, &[0.0, 0.0], 2.0, Some(-3.0), &mut safe)
                .unwrap(),
            (1, -3.0)
        );
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
        let kept = aut.safe_set(0, &s).unwrap();
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
        let names: Vec<String> = (0..17).map(|i| format!("p{i}")).collect();
        let text = names
            .iter()
            .map(|n| format!("F {n}"))
            .collect::<Vec<_>>()
            .join(" & ");
        let p = Predicate::halfspace(vec![1.0], 0.0).unwrap();
        let spec = Spec::new(&text, names.iter().map(|n| (n.as_str(), p.clone()))).unwrap();
        let err = Automaton::build(&spec).unwrap_err();
        assert_eq!(
            err.to_string(),
            "the formula has 17 atoms; automata support at most 16"
        );
    }

    #[test]
    fn oversized_automata_are_an_error() {
        // 16 independent goals: 2^16 residuals over 2^16 letters.
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
}
