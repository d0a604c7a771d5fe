//! Construction (Eq. 4 of the paper's FSA, built natively and symbolically): formula
//! progression with canonical simplification, as decision diagrams over the atoms (each
//! residual's successor as a function of the letter, never an enumeration of the 2^atoms
//! letters), acceptance by end-of-trace evaluation, Moore minimisation on the diagrams, and
//! guards read off their paths.

use std::collections::VecDeque;

use smallvec::{smallvec, SmallVec};

use super::diagram::{leaf, Builder, Diagram, FastMap, NodeId};
use super::{regions, Automaton, Edge, MAX_ATOMS};
use crate::cnf::{self, Cube};
use crate::error::AutomatonError;
use crate::formula::Formula;
use crate::spec::Spec;

/// Most states (distinct residual formulas, before minimisation) a build may reach.
pub const MAX_STATES: usize = 1 << 11;

/// Most guard cubes (paths of the states' diagrams) a build may read: a guard is a DNF, and
/// some automata with few states need exponentially many cubes for it.
pub const MAX_GUARD_CUBES: usize = 1 << 20;

/// Guards over at most this many atoms are minimised exactly (Quine-McCluskey over their
/// minterms); larger ones are the diagram's path cubes, each expanded to a prime implicant.
const EXACT_GUARD_ATOMS: u32 = 8;

/// A transition table `states x 2^atoms` is kept for stepping when it has at most this many
/// entries (256 KiB): one lookup per step. Larger automata step through their diagrams.
const DENSE_MAX: usize = 1 << 16;

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
#[cfg(test)]
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

/// The obligations of a formula: the subformulas that can be left to hold "from the next
/// state on" (the formula itself, every `F` and `U` node, every `X` operand). Structurally
/// equal subformulas share an id; ids are assigned once, before exploring.
struct Obligations<'f> {
    formulas: Vec<&'f Formula>,
    /// The atoms each obligation reads: its progression depends on `v & masks[k]` only.
    masks: Vec<u32>,
    /// Node address -> obligation id.
    by_node: FastMap<*const Formula, usize>,
    /// Per obligation `i`: the obligations known to imply it (bit `j`; `i` itself included),
    /// from sound syntactic rules, closed transitively (see [`Obligations::implications`]).
    implied_by: Vec<u128>,
}

impl<'f> Obligations<'f> {
    fn new(root: &'f Formula) -> Result<Self, AutomatonError> {
        let mut this = Obligations {
            formulas: Vec::new(),
            masks: Vec::new(),
            by_node: FastMap::default(),
            implied_by: Vec::new(),
        };
        let mut structural: FastMap<&'f Formula, usize> = FastMap::default();
        this.register(root, &mut structural)?;
        this.visit(root, &mut structural)?;
        this.implied_by = this.implications(&structural);
        Ok(this)
    }

    /// Which obligations imply which, by rules that hold for every trace:
    /// - `b` implies `F b` and `a U b`, and so does each disjunct of `b`;
    /// - `F(x & F y & ...)` implies `F y`, and `F F y` implies `F y`.
    ///
    /// Residuals are simplified with it ([`Obligations::simplify`]): `U1 | U0` of an until
    /// chain is `U0`, so progression reaches `n` residuals where plain absorption reaches
    /// `2^n`. Only the speed of the build depends on these rules, never its language.
    fn implications(&self, structural: &FastMap<&'f Formula, usize>) -> Vec<u128> {
        let mut implied_by: Vec<u128> = (0..self.formulas.len()).map(|i| 1u128 << i).collect();
        let id = |f: &Formula| structural.get(f).copied();
        for (i, f) in self.formulas.iter().enumerate() {
            let target = match f {
                Formula::Eventually(b) | Formula::Until(_, b) => b.as_ref(),
                _ => continue,
            };
            let disjuncts: &[Formula] = match target {
                Formula::Or(parts) => parts,
                other => std::slice::from_ref(other),
            };
            for j in std::iter::once(target).chain(disjuncts).filter_map(id) {
                implied_by[i] |= 1 << j;
            }
            if let Formula::Eventually(x) = f {
                let conjuncts: &[Formula] = match x.as_ref() {
                    Formula::And(parts) => parts,
                    other => std::slice::from_ref(other),
                };
                for part in conjuncts {
                    if let (Formula::Eventually(_), Some(j)) = (part, id(part)) {
                        implied_by[j] |= 1 << i;
                    }
                }
            }
        }
        loop {
            let mut changed = false;
            for i in 0..implied_by.len() {
                let mut closed = implied_by[i];
                let mut bits = implied_by[i];
                while bits != 0 {
                    let j = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    closed |= implied_by[j];
                }
                if closed != implied_by[i] {
                    implied_by[i] = closed;
                    changed = true;
                }
            }
            if !changed {
                return implied_by;
            }
        }
    }

    /// Whether the conjunction `c` implies the conjunction `d` (every obligation of `d` is
    /// implied by one of `c`).
    fn cube_implies(&self, c: u128, d: u128) -> bool {
        let mut bits = d;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            if c & self.implied_by[i] == 0 {
                return false;
            }
        }
        true
    }

    /// `dnf` with what the implications make redundant removed: an obligation implied by
    /// another in its cube, a cube that implies another. Of two equivalent ones the first
    /// (lower id, earlier cube) stays. An equivalent DNF; plain [`absorb`] when no rule applies.
    fn simplify(&self, dnf: Dnf) -> Dnf {
        if self.implied_by.iter().all(|m| m.count_ones() == 1) {
            return dnf;
        }
        let stronger = |j: usize, i: usize| {
            self.implied_by[i] >> j & 1 == 1 && (self.implied_by[j] >> i & 1 == 0 || j < i)
        };
        let cubes: Dnf = dnf
            .iter()
            .map(|&c| {
                let mut kept = c;
                let mut bits = c;
                while bits != 0 {
                    let i = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let mut others = kept & !(1u128 << i);
                    while others != 0 {
                        let j = others.trailing_zeros() as usize;
                        others &= others - 1;
                        if stronger(j, i) {
                            kept &= !(1u128 << i);
                            break;
                        }
                    }
                }
                kept
            })
            .collect();
        let cubes = absorb(cubes);
        let mut out = Dnf::new();
        for (k, &c) in cubes.iter().enumerate() {
            let redundant = cubes.iter().enumerate().any(|(m, &d)| {
                m != k && self.cube_implies(c, d) && (!self.cube_implies(d, c) || m < k)
            });
            if !redundant {
                out.push(c);
            }
        }
        out
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

    /// What remains of "`f` holds from here" after reading a state with valuation `v` (the
    /// letter-by-letter progression the diagrams compute symbolically; the tests' oracle).
    #[cfg(test)]
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
}

/// The interned residuals that label the progression diagrams' leaves.
struct Leaves {
    dnfs: Vec<Dnf>,
    ids: FastMap<Dnf, u32>,
}

/// Leaf value of `false` (the empty DNF) and of `true` (the empty cube).
const FALSE_LEAF: u32 = 0;
const TRUE_LEAF: u32 = 1;

impl Leaves {
    fn new() -> Self {
        let mut this = Leaves {
            dnfs: Vec::new(),
            ids: FastMap::default(),
        };
        this.intern(constant(false));
        this.intern(constant(true));
        this
    }

    fn intern(&mut self, dnf: Dnf) -> u32 {
        if let Some(&id) = self.ids.get(&dnf) {
            return id;
        }
        let id = self.dnfs.len() as u32;
        self.ids.insert(dnf.clone(), id);
        self.dnfs.push(dnf);
        id
    }
}

/// Formula progression as diagrams: `progress(f)` is the function from the letter read to
/// the residual left, a diagram over the atoms `f` reads with interned residuals at its
/// leaves. Each obligation is progressed once; a residual's successor combines them.
struct Symbolic<'o, 'f, 's> {
    obligations: &'o Obligations<'f>,
    diagrams: Builder<'s>,
    leaves: Leaves,
    /// Per obligation: its progression, once computed.
    progressed: Vec<Option<NodeId>>,
    and_memo: FastMap<(NodeId, NodeId), NodeId>,
    or_memo: FastMap<(NodeId, NodeId), NodeId>,
    not_memo: FastMap<(NodeId, NodeId), NodeId>,
}

impl<'o, 'f, 's> Symbolic<'o, 'f, 's> {
    fn new(obligations: &'o Obligations<'f>, stop: &'s dyn Fn() -> bool) -> Self {
        Symbolic {
            obligations,
            diagrams: Builder::new(stop),
            leaves: Leaves::new(),
            progressed: vec![None; obligations.formulas.len()],
            and_memo: FastMap::default(),
            or_memo: FastMap::default(),
            not_memo: FastMap::default(),
        }
    }

    fn constant(&mut self, dnf: Dnf) -> NodeId {
        leaf(self.leaves.intern(dnf))
    }

    fn and(&mut self, a: NodeId, b: NodeId) -> Result<NodeId, AutomatonError> {
        let (leaves, obligations) = (&mut self.leaves, self.obligations);
        self.diagrams.apply(
            a,
            b,
            &mut |x, y| {
                let product = dnf_and(&leaves.dnfs[x as usize], &leaves.dnfs[y as usize]);
                leaves.intern(obligations.simplify(product))
            },
            Some(leaf(FALSE_LEAF)),
            Some(leaf(TRUE_LEAF)),
            &mut self.and_memo,
        )
    }

    fn or(&mut self, a: NodeId, b: NodeId) -> Result<NodeId, AutomatonError> {
        let (leaves, obligations) = (&mut self.leaves, self.obligations);
        self.diagrams.apply(
            a,
            b,
            &mut |x, y| {
                let sum = dnf_or(leaves.dnfs[x as usize].clone(), &leaves.dnfs[y as usize]);
                leaves.intern(obligations.simplify(sum))
            },
            Some(leaf(TRUE_LEAF)),
            Some(leaf(FALSE_LEAF)),
            &mut self.or_memo,
        )
    }

    /// The negation of a propositional diagram (leaves `false` and `true` only): its leaves
    /// swapped, by [`Builder::apply`] against the constant `true`.
    fn not(&mut self, a: NodeId) -> Result<NodeId, AutomatonError> {
        let mut swap = |x: u32, _| {
            if x == TRUE_LEAF {
                FALSE_LEAF
            } else {
                TRUE_LEAF
            }
        };
        let t = leaf(TRUE_LEAF);
        self.diagrams
            .apply(a, t, &mut swap, None, None, &mut self.not_memo)
    }

    /// What remains of "`f` holds from here" after reading a letter, for every letter.
    fn progress(&mut self, f: &Formula) -> Result<NodeId, AutomatonError> {
        let obligation = self
            .obligations
            .by_node
            .get(&(f as *const Formula))
            .copied();
        if let Some(done) = obligation.and_then(|k| self.progressed[k]) {
            return Ok(done);
        }
        let out = match f {
            Formula::True => leaf(TRUE_LEAF),
            Formula::False => leaf(FALSE_LEAF),
            Formula::Atom(i) => self
                .diagrams
                .node(*i as u32, leaf(FALSE_LEAF), leaf(TRUE_LEAF))?,
            Formula::Not(a) => {
                let a = self.progress(a)?;
                self.not(a)?
            }
            Formula::And(parts) => parts.iter().try_fold(leaf(TRUE_LEAF), |acc, p| {
                let p = self.progress(p)?;
                self.and(acc, p)
            })?,
            Formula::Or(parts) => parts.iter().try_fold(leaf(FALSE_LEAF), |acc, p| {
                let p = self.progress(p)?;
                self.or(acc, p)
            })?,
            Formula::Implies(a, b) => {
                let a = self.progress(a)?;
                let not_a = self.not(a)?;
                let b = self.progress(b)?;
                self.or(not_a, b)?
            }
            Formula::Eventually(a) => {
                let now = self.progress(a)?;
                let later = self.constant(smallvec![self.obligations.id(f)]);
                self.or(now, later)?
            }
            Formula::Until(a, b) => {
                let now = self.progress(b)?;
                let hold = self.progress(a)?;
                let later = self.constant(smallvec![self.obligations.id(f)]);
                let keep = self.and(hold, later)?;
                self.or(now, keep)?
            }
            // `X a`: `a` must hold from the next state on (which must exist).
            Formula::Next(a) => self.constant(smallvec![self.obligations.id(a)]),
        };
        // Only `F`/`U` nodes are cached here (an `X` operand's id names its operand, whose
        // progression is a different function).
        if let (Some(k), Formula::Eventually(_) | Formula::Until(..)) = (obligation, f) {
            self.progressed[k] = Some(out);
        }
        Ok(out)
    }

    /// The successor of a whole residual, for every letter.
    fn successor(&mut self, residual: &[u128]) -> Result<NodeId, AutomatonError> {
        let mut out = leaf(FALSE_LEAF);
        for &cube in residual {
            let mut acc = leaf(TRUE_LEAF);
            let mut bits = cube;
            while bits != 0 && acc != leaf(FALSE_LEAF) {
                let k = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let p = self.progress(self.obligations.formulas[k])?;
                acc = self.and(acc, p)?;
            }
            out = self.or(out, acc)?;
        }
        Ok(out)
    }
}

/// How often (in states or cubes handled) a build asks its `stop` callback, besides every
/// 1024 diagram nodes.
const STOP_EVERY: usize = 1024;

impl Automaton {
    /// Builds the minimal automaton of `spec`'s formula.
    pub fn build(spec: &Spec) -> Result<Self, AutomatonError> {
        Self::build_until(spec, &|| false)
    }

    /// [`Automaton::build`] that asks `stop` every 1024 diagram nodes, states or cubes (and
    /// between the merge steps of each guard's minimisation) and returns
    /// [`AutomatonError::Interrupted`] as soon as it says so: a caller can keep a long build
    /// responsive (the Python bindings check for Ctrl-C there).
    pub fn build_until(spec: &Spec, stop: &dyn Fn() -> bool) -> Result<Self, AutomatonError> {
        let mut ticks = 0usize;
        let mut tick = |cost: usize| -> Result<(), AutomatonError> {
            ticks += cost;
            if ticks >= STOP_EVERY {
                ticks = 0;
                if stop() {
                    return Err(AutomatonError::Interrupted);
                }
            }
            Ok(())
        };
        let n = spec.atoms().len();
        if n > MAX_ATOMS {
            return Err(AutomatonError::TooManyAtoms {
                atoms: n,
                max: MAX_ATOMS,
            });
        }
        let explored = explore(spec, stop, &mut tick)?;
        let Minimal {
            diagram,
            roots,
            accepting,
            mask_of,
            successors,
        } = minimal(explored, stop, &mut tick)?;
        let trap = trap_of(&accepting, &successors);
        let edges = guards(&diagram, &roots, &mask_of, stop, &mut tick)?;
        let (progress_cubes, trap_guard) = split_guards(&edges, trap, roots.len());
        let trap_cnf: Vec<_> = trap_guard
            .iter()
            .map(|g| regions::dedup_cnf(cnf::complement_cnf(g)))
            .collect();
        let recovery_cnf = regions::recovery_cnf(&trap_cnf);
        let letters = 1usize << n;
        let table = step_table(&diagram, &roots, letters);

        // The map's part (regions.rs): ranks over admissible letters, goals, the avoid CNF.
        let pairs = regions::pairs(spec);
        let ranks = regions::ranks(roots.len(), &accepting, &edges, |v| {
            regions::admissible_letter(spec, &pairs, v)
        });
        let goal_alternatives = edges
            .iter()
            .map(|e| {
                e.guard
                    .iter()
                    .map(|c| regions::goal_alternatives(spec, c))
                    .collect()
            })
            .collect();
        let avoid_cnf = regions::avoid_cnf(roots.len(), &edges, &ranks, &trap_cnf);
        Ok(Automaton {
            spec: spec.clone(),
            letters,
            initial: 0,
            accepting,
            trap,
            table,
            diagram,
            roots,
            edges,
            progress: progress_cubes,
            trap_guard,
            trap_cnf,
            recovery_cnf,
            pairs,
            ranks,
            goal_alternatives,
            avoid_cnf,
        })
    }
}

/// A build's progress callback: counts work and asks the caller's `stop` now and then.
type Tick<'a> = dyn FnMut(usize) -> Result<(), AutomatonError> + 'a;

/// The residuals reachable by progression before minimisation: each state's successors as
/// one diagram (leaves: residual ids), the atoms each residual reads and whether it accepts.
struct Explored<'s> {
    raw: Builder<'s>,
    roots: Vec<NodeId>,
    masks: Vec<u32>,
    accepting: Vec<bool>,
}

/// Phase 1: explores the residuals reachable by progression. A residual holds on the empty
/// rest of a trace iff it is `true` (every obligation needs a state). Successors are numbered
/// in the order ascending letters first reach them.
fn explore<'s>(
    spec: &Spec,
    stop: &'s dyn Fn() -> bool,
    tick: &mut Tick<'_>,
) -> Result<Explored<'s>, AutomatonError> {
    let obligations = Obligations::new(spec.formula())?;
    let start: Dnf = obligations.simplify(
        obligations
            .unfold(spec.formula())
            .unwrap_or_else(|| smallvec![obligations.id(spec.formula())]),
    );
    let mut symbolic = Symbolic::new(&obligations, stop);
    let mut raw = Builder::new(stop);
    let mut ids: FastMap<Dnf, u32> = FastMap::default();
    ids.insert(start.clone(), 0);
    let mut residuals = vec![start];
    let mut masks: Vec<u32> = Vec::new();
    let mut roots: Vec<NodeId> = Vec::new();
    let mut next = 0;
    while next < residuals.len() {
        tick(1)?;
        let current = residuals[next].clone();
        masks.push(obligations.residual_mask(&current));
        let root = symbolic.successor(&current)?;
        let mut state_of: FastMap<u32, u32> = FastMap::default();
        for (x, _) in symbolic.diagrams.diagram().first_letters(root) {
            let succ = &symbolic.leaves.dnfs[x as usize];
            let id = match ids.get(succ) {
                Some(&id) => id,
                None => {
                    if residuals.len() == MAX_STATES {
                        return Err(AutomatonError::TooLarge {
                            what: "states",
                            size: residuals.len() + 1,
                            max: MAX_STATES,
                        });
                    }
                    ids.insert(succ.clone(), residuals.len() as u32);
                    residuals.push(succ.clone());
                    residuals.len() as u32 - 1
                }
            };
            state_of.insert(x, id);
        }
        let root = symbolic.diagrams.diagram().transplant(
            root,
            &mut raw,
            &|x| state_of[&x],
            &mut FastMap::default(),
        )?;
        roots.push(root);
        next += 1;
    }
    drop(symbolic);
    let accepting = residuals.iter().map(|r| r.contains(&TRUE)).collect();
    Ok(Explored {
        raw,
        roots,
        masks,
        accepting,
    })
}

/// The minimal automaton's transition diagram, per state its root, acceptance, atom mask and
/// sorted successors.
struct Minimal {
    diagram: Diagram,
    roots: Vec<NodeId>,
    accepting: Vec<bool>,
    mask_of: Vec<u32>,
    successors: Vec<Vec<usize>>,
}

/// Phase 2: minimises (Moore refinement on the diagrams), then numbers states breadth-first
/// from the start, successors in the order ascending letters first reach them.
fn minimal(
    explored: Explored<'_>,
    stop: &dyn Fn() -> bool,
    tick: &mut Tick<'_>,
) -> Result<Minimal, AutomatonError> {
    let Explored {
        raw,
        roots: raw_roots,
        masks: raw_masks,
        accepting: accepting_raw,
    } = explored;
    let block = minimise(&raw, &raw_roots, &accepting_raw, tick)?;
    let raw = raw.freeze();
    let blocks = block.iter().max().map_or(0, |m| m + 1);
    let mut representative = vec![usize::MAX; blocks];
    for (q, &b) in block.iter().enumerate().rev() {
        representative[b] = q;
    }
    let mut order = vec![usize::MAX; blocks];
    let mut queue = VecDeque::from([block[0]]);
    order[block[0]] = 0;
    let mut count = 1;
    let mut visit = Vec::with_capacity(blocks);
    while let Some(b) = queue.pop_front() {
        tick(1)?;
        visit.push(b);
        for (r, _) in raw.first_letters(raw_roots[representative[b]]) {
            let nb = block[r as usize];
            if order[nb] == usize::MAX {
                order[nb] = count;
                count += 1;
                queue.push_back(nb);
            }
        }
    }
    let num_states = count;
    let mut built = Builder::new(stop);
    let mut memo = FastMap::default();
    let relabel = |r: u32| order[block[r as usize]] as u32;
    let mut roots = Vec::with_capacity(num_states);
    let mut accepting = vec![false; num_states];
    let mut mask_of = vec![0u32; num_states];
    for &b in &visit {
        let q = representative[b];
        roots.push(raw.transplant(raw_roots[q], &mut built, &relabel, &mut memo)?);
        accepting[order[b]] = accepting_raw[q];
        mask_of[order[b]] = raw_masks[q];
    }
    drop(raw);
    let diagram = built.freeze();
    let successors: Vec<Vec<usize>> = roots
        .iter()
        .map(|&root| {
            let mut out: Vec<usize> = diagram
                .first_letters(root)
                .into_iter()
                .map(|(d, _)| d as usize)
                .collect();
            out.sort_unstable();
            out
        })
        .collect();
    Ok(Minimal {
        diagram,
        roots,
        accepting,
        mask_of,
        successors,
    })
}

/// Phase 3: the trap, the state from which no accepting state is reachable (at most one
/// after minimisation).
fn trap_of(accepting: &[bool], successors: &[Vec<usize>]) -> Option<usize> {
    let mut reaches = accepting.to_vec();
    loop {
        let mut changed = false;
        for q in 0..reaches.len() {
            if !reaches[q] && successors[q].iter().any(|&d| reaches[d]) {
                reaches[q] = true;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    reaches.iter().position(|r| !r)
}

/// Phase 4: the guards, read off each state's diagram: its paths to a target are disjoint
/// cubes over the atoms the state's residual reads (`mask_of`).
fn guards(
    diagram: &Diagram,
    roots: &[NodeId],
    mask_of: &[u32],
    stop: &dyn Fn() -> bool,
    tick: &mut Tick<'_>,
) -> Result<Vec<Edge>, AutomatonError> {
    let num_states = roots.len();
    let mut edges = Vec::new();
    let mut by_dst: Vec<Vec<Cube>> = vec![Vec::new(); num_states];
    let mut cubes_read = 0usize;
    for src in 0..num_states {
        by_dst.iter_mut().for_each(Vec::clear);
        diagram.paths(roots[src], &mut |cube, d| {
            if cubes_read <= MAX_GUARD_CUBES {
                by_dst[d as usize].push(cube);
                cubes_read += 1;
            }
        });
        if cubes_read > MAX_GUARD_CUBES {
            return Err(AutomatonError::TooLarge {
                what: "guard cubes",
                size: cubes_read,
                max: MAX_GUARD_CUBES,
            });
        }
        for (dst, cubes) in by_dst.iter().enumerate() {
            if cubes.is_empty() {
                continue;
            }
            tick(cubes.len())?;
            let guard = if mask_of[src].count_ones() <= EXACT_GUARD_ATOMS {
                cnf::minimise_within_until(&minterms(cubes, mask_of[src]), mask_of[src], stop)
                    .ok_or(AutomatonError::Interrupted)?
            } else {
                primes(diagram, roots[src], cubes, dst as u32)
            };
            edges.push(Edge { src, dst, guard });
        }
    }
    Ok(edges)
}

/// Per state, the cubes of its edges to other non-trap states (progress) and its guard into
/// the trap.
fn split_guards(
    edges: &[Edge],
    trap: Option<usize>,
    num_states: usize,
) -> (Vec<Vec<Cube>>, Vec<Vec<Cube>>) {
    let mut progress_cubes = vec![Vec::new(); num_states];
    let mut trap_guard = vec![Vec::new(); num_states];
    for e in edges {
        if Some(e.dst) == trap && e.src != e.dst {
            trap_guard[e.src] = e.guard.clone();
        } else if e.dst != e.src && Some(e.dst) != trap {
            progress_cubes[e.src].extend_from_slice(&e.guard);
        }
    }
    (progress_cubes, trap_guard)
}

/// Phase 5: a table for one-lookup steps, when small (empty otherwise).
fn step_table(diagram: &Diagram, roots: &[NodeId], letters: usize) -> Vec<u32> {
    if roots.len().saturating_mul(letters) <= DENSE_MAX {
        (0..roots.len())
            .flat_map(|q| (0..letters).map(move |v| (q, v)))
            .map(|(q, v)| diagram.eval(roots[q], v))
            .collect()
    } else {
        Vec::new()
    }
}

/// Every valuation of the atoms in `mask` that lies in one of `cubes`, ascending.
fn minterms(cubes: &[Cube], mask: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for c in cubes {
        let free = mask & !c.care;
        let mut sub = free;
        loop {
            out.push(c.value | sub);
            if sub == 0 {
                break;
            }
            sub = (sub - 1) & free;
        }
    }
    out.sort_unstable();
    out
}

/// A DNF of the edge from `root` to `dst` for a guard too wide to minimise exactly: each of
/// its path `cubes` loses every literal it can while still leading only to `dst` (a prime
/// implicant), then cubes another contains are dropped. Sorted as the exact minimiser sorts.
fn primes(diagram: &Diagram, root: NodeId, cubes: &[Cube], dst: u32) -> Vec<Cube> {
    let mut out: Vec<Cube> = cubes
        .iter()
        .map(|&c| {
            let mut c = c;
            let mut care = c.care;
            while care != 0 {
                let bit = care & care.wrapping_neg();
                care &= care - 1;
                // The cube's own half leads to `dst`: dropping the literal keeps the cube
                // inside the guard iff the other half does too.
                let other = Cube {
                    care: c.care,
                    value: c.value ^ bit,
                };
                if diagram.within(root, other, dst) {
                    c = Cube {
                        care: c.care & !bit,
                        value: c.value & !bit,
                    };
                }
            }
            c
        })
        .collect();
    out.sort_unstable_by_key(|c| (c.care.count_ones(), c.care, c.value));
    out.dedup();
    let contains = |d: &Cube, c: &Cube| d.care & !c.care == 0 && c.value & d.care == d.value;
    let mut kept: Vec<Cube> = Vec::with_capacity(out.len());
    for c in out {
        if !kept.iter().any(|d| contains(d, &c)) {
            kept.push(c);
        }
    }
    kept
}

/// Moore partition refinement on the states' diagrams: two states stay together while they
/// agree on acceptance and their diagrams, leaves replaced by blocks, are the same node.
/// Returns the block of every state, blocks numbered by first occurrence.
fn minimise(
    raw: &Builder<'_>,
    roots: &[NodeId],
    accepting: &[bool],
    tick: &mut dyn FnMut(usize) -> Result<(), AutomatonError>,
) -> Result<Vec<usize>, AutomatonError> {
    let n = accepting.len();
    let mut block: Vec<usize> = accepting.iter().map(|&a| usize::from(a)).collect();
    let mut count = 0;
    let mut refined = vec![0; n];
    let never = || false;
    loop {
        let mut signatures = Builder::new(&never);
        let mut memo = FastMap::default();
        let mut ids: FastMap<(usize, NodeId), usize> =
            FastMap::with_capacity_and_hasher(n, Default::default());
        for q in 0..n {
            tick(1)?;
            let relabel = |r: u32| block[r as usize] as u32;
            let sig = raw
                .diagram()
                .transplant(roots[q], &mut signatures, &relabel, &mut memo)?;
            let next_id = ids.len();
            refined[q] = *ids.entry((block[q], sig)).or_insert(next_id);
        }
        let new_count = ids.len();
        std::mem::swap(&mut block, &mut refined);
        if new_count == count {
            return Ok(block);
        }
        count = new_count;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::co_safe_over;
    use proptest::prelude::*;

    /// The construction before diagrams, kept as the oracle: progression letter by letter
    /// over every valuation, from the same start. Checks that `aut` accepts exactly the words
    /// the residuals accept, by a breadth-first walk of the pairs (residual, automaton state).
    fn same_language_as_letter_progression(spec: &Spec, aut: &Automaton) -> Result<(), String> {
        let obligations = Obligations::new(spec.formula()).map_err(|e| e.to_string())?;
        let start: Dnf = obligations
            .unfold(spec.formula())
            .unwrap_or_else(|| smallvec![obligations.id(spec.formula())]);
        let letters = 1u32 << spec.atoms().len();
        let step = |residual: &Dnf, v: u32| -> Dnf {
            let mut out = Dnf::new();
            for &cube in residual {
                let mut acc: Dnf = smallvec![TRUE];
                let mut bits = cube;
                while bits != 0 {
                    let k = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    acc = dnf_and(&acc, &obligations.progress(obligations.formulas[k], v));
                }
                out.extend(acc);
            }
            absorb(out)
        };
        let mut seen: FastMap<(Dnf, usize), ()> = FastMap::default();
        let mut queue = VecDeque::from([(start, aut.initial())]);
        while let Some((r, q)) = queue.pop_front() {
            if seen.insert((r.clone(), q), ()).is_some() {
                continue;
            }
            if r.contains(&TRUE) != aut.is_accepting(q) {
                return Err(format!(
                    "residual {r:?} and state {q} disagree on acceptance"
                ));
            }
            for v in 0..letters {
                queue.push_back((step(&r, v), aut.step_valuation(q, v as usize)));
            }
            if seen.len() > 20_000 {
                return Err("too many pairs".into());
            }
        }
        Ok(())
    }

    fn sequence(n: usize) -> String {
        let mut text = String::from("F(a0");
        for i in 1..n {
            text.push_str(&format!(" & F(a{i}"));
        }
        text + &")".repeat(n)
    }

    #[test]
    fn a_sequence_of_24_atoms_builds_its_25_states() {
        let spec = Spec::from_formula(&sequence(24)).unwrap();
        let aut = Automaton::build(&spec).unwrap();
        assert_eq!(aut.num_states(), 25);
        assert!(aut.table.is_empty(), "stepped through the diagrams");
        // The word a0, a1, ..., a23 (one atom a letter) is accepted, and not one letter early.
        let mut q = aut.initial();
        for i in 0..24 {
            assert!(!aut.is_accepting(q));
            q = aut.step_valuation(q, 1 << i);
        }
        assert!(aut.is_accepting(q));
        // Every guard is one cube, as short as it can be: `a0 & ... & a(k-1) & !ak`.
        assert!(aut.edges().iter().all(|e| e.guard.len() == 1));
        assert_eq!(aut.edges().len(), 2 * 24 + 1 + 24 * 23 / 2);
    }

    #[test]
    fn the_paper_task_and_flatworld_formulas_match_letter_progression() {
        let task = crate::fixtures::task_automaton();
        same_language_as_letter_progression(task.spec(), &task).unwrap();
        for text in [
            "(!red U green) & F (blue & F yellow)",
            "!(green | blue) U (yellow & F magenta)",
            "F (a & X (b U c)) | (d -> X F e)",
        ] {
            let spec = Spec::from_formula(text).unwrap();
            let aut = Automaton::build(&spec).unwrap();
            same_language_as_letter_progression(&spec, &aut).unwrap();
        }
    }

    proptest! {
        #![proptest_config(crate::tests_support::seeded(256))]

        /// Random co-safe formulas over up to 10 atoms: the diagrams give exactly the language
        /// of letter-by-letter progression.
        #[test]
        fn diagrams_accept_what_letter_progression_accepts(f in co_safe_over(10)) {
            let names: Vec<String> = (0..10).map(|i| format!("a{i}")).collect();
            let Ok(spec) = Spec::from_formula(&f.display(&names).to_string()) else {
                return Ok(());
            };
            let Ok(aut) = Automaton::build(&spec) else {
                return Ok(());
            };
            prop_assert_eq!(same_language_as_letter_progression(&spec, &aut), Ok(()));
        }
    }
}
