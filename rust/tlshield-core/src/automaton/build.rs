//! Construction (Eq. 4 of the paper's FSA, built natively): formula progression over the
//! valuations of the atoms with canonical simplification, acceptance by end-of-trace
//! evaluation, then Moore minimisation.

use std::collections::{HashMap, VecDeque};
use std::hash::{BuildHasherDefault, Hasher};

use smallvec::{smallvec, SmallVec};

use super::{regions, Automaton, Edge, MAX_ATOMS, MAX_TRANSITIONS};
use crate::cnf;
use crate::error::AutomatonError;
use crate::formula::Formula;
use crate::spec::Spec;

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

/// How often (in letters or states handled) a build asks its `stop` callback.
const STOP_EVERY: usize = 1024;

impl Automaton {
    /// Builds the minimal automaton of `spec`'s formula.
    pub fn build(spec: &Spec) -> Result<Self, AutomatonError> {
        Self::build_until(spec, &|| false)
    }

    /// [`Automaton::build`] that asks `stop` every [`STOP_EVERY`] letters or states (and
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
                tick(1)?;
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
        let block = minimise(&raw, &accepting_raw, letters, &mut tick)?;
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
            tick(letters)?;
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
            tick(letters)?;
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
                        guard: cnf::minimise_within_until(minterms, mask, stop)
                            .ok_or(AutomatonError::Interrupted)?,
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
        let trap_cnf: Vec<_> = trap_guard
            .iter()
            .map(|g| regions::dedup_cnf(cnf::complement_cnf(g)))
            .collect();

        // 5. The map's part (regions.rs): admissible letters, ranks, goals, the avoid CNF.
        let (admissible, pairs) = regions::admissible_letters(spec, letters);
        let ranks = regions::ranks(
            num_states,
            letters,
            &accepting,
            |q, v| table[q * letters + v] as usize,
            |v| admissible[v],
        );
        let goal_alternatives = edges
            .iter()
            .map(|e| {
                e.guard
                    .iter()
                    .map(|c| regions::goal_alternatives(spec, c))
                    .collect()
            })
            .collect();
        let avoid_cnf = regions::avoid_cnf(num_states, &edges, &ranks, &trap_cnf);
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
            admissible,
            pairs,
            ranks,
            goal_alternatives,
            avoid_cnf,
        })
    }
}

/// Moore partition refinement: returns the block of every state, blocks numbered by first
/// occurrence.
fn minimise(
    table: &[u32],
    accepting: &[bool],
    letters: usize,
    tick: &mut dyn FnMut(usize) -> Result<(), AutomatonError>,
) -> Result<Vec<usize>, AutomatonError> {
    let n = accepting.len();
    let mut block: Vec<usize> = accepting.iter().map(|&a| usize::from(a)).collect();
    let mut count = 0;
    // Signatures (own block, then the successors' blocks) live in one flat buffer.
    let width = letters + 1;
    let mut signatures = vec![0u32; n * width];
    let mut refined = vec![0; n];
    loop {
        for q in 0..n {
            tick(letters)?;
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
            return Ok(block);
        }
        count = new_count;
    }
}
