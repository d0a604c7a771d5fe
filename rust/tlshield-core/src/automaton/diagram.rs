//! Multi-terminal decision diagrams over the atoms: the symbolic form of a transition
//! function. Ordered (atom 0 at the top, then ascending), reduced (no node with
//! equal children) and hash-consed (no two equal nodes), so one function has one node and two
//! diagrams are equal iff their ids are. A leaf carries a `u32` value: a residual formula
//! while building, a state id once built.
//!
//! A diagram has as many nodes as its function needs, not `2^atoms`: the successor function
//! of `F(a0 & F(a1 & ... F a(n-1)))` has `n` nodes.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use crate::cnf::Cube;
use crate::error::AutomatonError;

/// A node: a branch (index into the branches) or, with [`LEAF`] set, a leaf value.
pub(crate) type NodeId = u32;

/// The bit that marks a leaf; leaf values stay below it.
const LEAF: u32 = 1 << 31;

/// Most nodes one build may create (about 12 bytes each, plus the unique table).
pub const MAX_NODES: usize = 1 << 22;

/// How often (in nodes created) a build asks its `stop` callback.
const STOP_EVERY: usize = 1024;

/// A small, fast hasher for the build's maps (keys are node ids and short bit vectors; no
/// untrusted input reaches them).
#[derive(Default)]
pub(super) struct FxHasher(u64);

impl Hasher for FxHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u32(&mut self, i: u32) {
        self.write_u64(u64::from(i));
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

/// A hash map with [`FxHasher`].
pub(super) type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<FxHasher>>;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Branch {
    /// The atom tested.
    var: u32,
    /// The child where the atom does not hold.
    lo: NodeId,
    /// The child where it holds.
    hi: NodeId,
}

/// The leaf with value `value` (< 2^31).
#[inline]
pub(crate) fn leaf(value: u32) -> NodeId {
    debug_assert!(value < LEAF);
    value | LEAF
}

/// The value of a leaf, `None` for a branch.
#[inline]
pub(crate) fn leaf_value(id: NodeId) -> Option<u32> {
    (id & LEAF != 0).then_some(id & !LEAF)
}

/// Diagrams under construction: a node store with its unique table, a node budget and a
/// caller's `stop` callback, asked every [`STOP_EVERY`] nodes.
pub(crate) struct Builder<'s> {
    diagram: Diagram,
    unique: FastMap<Branch, NodeId>,
    stop: &'s dyn Fn() -> bool,
    since_stop: usize,
}

impl<'s> Builder<'s> {
    /// An empty store.
    pub fn new(stop: &'s dyn Fn() -> bool) -> Self {
        Builder {
            diagram: Diagram::default(),
            unique: FastMap::default(),
            stop,
            since_stop: 0,
        }
    }

    /// Nodes created so far.
    pub fn len(&self) -> usize {
        self.diagram.branches.len()
    }

    /// The nodes built so far, to read.
    pub fn diagram(&self) -> &Diagram {
        &self.diagram
    }

    /// The node testing `var` with children `lo` (false) and `hi` (true), reduced and shared.
    pub fn node(&mut self, var: u32, lo: NodeId, hi: NodeId) -> Result<NodeId, AutomatonError> {
        if lo == hi {
            return Ok(lo);
        }
        let b = Branch { var, lo, hi };
        if let Some(&id) = self.unique.get(&b) {
            return Ok(id);
        }
        if self.len() >= MAX_NODES {
            return Err(AutomatonError::TooLarge {
                what: "decision-diagram nodes",
                size: self.len() + 1,
                max: MAX_NODES,
            });
        }
        self.since_stop += 1;
        if self.since_stop >= STOP_EVERY {
            self.since_stop = 0;
            if (self.stop)() {
                return Err(AutomatonError::Interrupted);
            }
        }
        let id = self.len() as NodeId;
        self.diagram.branches.push(b);
        self.unique.insert(b, id);
        Ok(id)
    }

    /// The atom tested at `id` (`u32::MAX` at a leaf, below every atom).
    #[inline]
    fn var(&self, id: NodeId) -> u32 {
        match leaf_value(id) {
            Some(_) => u32::MAX,
            None => self.diagram.branches[id as usize].var,
        }
    }

    /// The two cofactors of `id` on atom `var` (`id` twice when it does not test `var`).
    #[inline]
    fn cofactors(&self, id: NodeId, var: u32) -> (NodeId, NodeId) {
        match leaf_value(id) {
            None if self.diagram.branches[id as usize].var == var => {
                let b = self.diagram.branches[id as usize];
                (b.lo, b.hi)
            }
            _ => (id, id),
        }
    }

    /// The pointwise combination of `a` and `b` by `op` on leaf values. `absorbing` (a node
    /// that makes the result whatever the other operand) and `identity` (a node that makes it
    /// the other operand), when `op` has them, spare descending. `memo` caches `(a, b)` pairs
    /// for this `op` alone.
    pub fn apply(
        &mut self,
        a: NodeId,
        b: NodeId,
        op: &mut dyn FnMut(u32, u32) -> u32,
        absorbing: Option<NodeId>,
        identity: Option<NodeId>,
        memo: &mut FastMap<(NodeId, NodeId), NodeId>,
    ) -> Result<NodeId, AutomatonError> {
        if let Some(z) = absorbing.filter(|&z| a == z || b == z) {
            return Ok(z);
        }
        if identity == Some(a) {
            return Ok(b);
        }
        if identity == Some(b) {
            return Ok(a);
        }
        if let (Some(x), Some(y)) = (leaf_value(a), leaf_value(b)) {
            return Ok(leaf(op(x, y)));
        }
        if let Some(&done) = memo.get(&(a, b)) {
            return Ok(done);
        }
        let var = self.var(a).min(self.var(b));
        let (a0, a1) = self.cofactors(a, var);
        let (b0, b1) = self.cofactors(b, var);
        let lo = self.apply(a0, b0, op, absorbing, identity, memo)?;
        let hi = self.apply(a1, b1, op, absorbing, identity, memo)?;
        let out = self.node(var, lo, hi)?;
        memo.insert((a, b), out);
        Ok(out)
    }

    /// The store, frozen for stepping (the unique table dropped).
    pub fn freeze(self) -> Diagram {
        self.diagram
    }
}

/// Built diagrams, read-only: the automaton's transition function, one root per state.
#[derive(Debug, Clone, Default)]
pub(crate) struct Diagram {
    branches: Vec<Branch>,
}

impl Diagram {
    /// The leaf value `id` reaches on valuation `v`.
    #[inline]
    pub fn eval(&self, mut id: NodeId, v: usize) -> u32 {
        while id & LEAF == 0 {
            let b = &self.branches[id as usize];
            id = if v >> b.var & 1 == 1 { b.hi } else { b.lo };
        }
        id & !LEAF
    }

    /// Nodes stored.
    pub fn len(&self) -> usize {
        self.branches.len()
    }

    /// `id` with every leaf value `x` replaced by `relabel(x)`, built in `into` (which may be
    /// a fresh store: copying the nodes a set of roots uses compacts them). `memo` caches
    /// nodes for this `relabel` and `into` alone.
    pub fn transplant(
        &self,
        id: NodeId,
        into: &mut Builder<'_>,
        relabel: &dyn Fn(u32) -> u32,
        memo: &mut FastMap<NodeId, NodeId>,
    ) -> Result<NodeId, AutomatonError> {
        if let Some(x) = leaf_value(id) {
            return Ok(leaf(relabel(x)));
        }
        if let Some(&done) = memo.get(&id) {
            return Ok(done);
        }
        let b = self.branches[id as usize];
        let lo = self.transplant(b.lo, into, relabel, memo)?;
        let hi = self.transplant(b.hi, into, relabel, memo)?;
        let out = into.node(b.var, lo, hi)?;
        memo.insert(id, out);
        Ok(out)
    }

    /// Every leaf value of `id` with the least valuation (as an integer, bit `i` for atom
    /// `i`) that reaches it, ordered by that valuation: the order in which ascending letters
    /// first reach each leaf.
    pub fn first_letters(&self, id: NodeId) -> Vec<(u32, u32)> {
        let mut best: FastMap<u32, u32> = FastMap::default();
        self.paths(id, &mut |cube, x| {
            let e = best.entry(x).or_insert(cube.value);
            *e = (*e).min(cube.value);
        });
        let mut out: Vec<(u32, u32)> = best.into_iter().map(|(x, v)| (v, x)).collect();
        out.sort_unstable();
        out.into_iter().map(|(v, x)| (x, v)).collect()
    }

    /// Calls `visit(cube, leaf value)` for every path from `id` to a leaf, the low child
    /// first: the cubes are disjoint and cover every valuation.
    pub fn paths(&self, id: NodeId, visit: &mut dyn FnMut(Cube, u32)) {
        fn walk(branches: &[Branch], id: NodeId, cube: Cube, visit: &mut dyn FnMut(Cube, u32)) {
            if let Some(x) = leaf_value(id) {
                visit(cube, x);
                return;
            }
            let b = branches[id as usize];
            let bit = 1u32 << b.var;
            let lo = Cube {
                care: cube.care | bit,
                value: cube.value,
            };
            walk(branches, b.lo, lo, visit);
            let hi = Cube {
                care: cube.care | bit,
                value: cube.value | bit,
            };
            walk(branches, b.hi, hi, visit);
        }
        walk(&self.branches, id, Cube { care: 0, value: 0 }, visit);
    }

    /// Whether every valuation in `cube` leads from `id` to the leaf value `x`. Its cost is
    /// bounded by the paths from `id` (which the guards enumerate anyway); it stops at the
    /// first other leaf.
    pub fn within(&self, id: NodeId, cube: Cube, x: u32) -> bool {
        match leaf_value(id) {
            Some(y) => y == x,
            None => {
                let b = self.branches[id as usize];
                let bit = 1u32 << b.var;
                match (cube.care & bit != 0, cube.value & bit != 0) {
                    (true, false) => self.within(b.lo, cube, x),
                    (true, true) => self.within(b.hi, cube, x),
                    (false, _) => self.within(b.lo, cube, x) && self.within(b.hi, cube, x),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn never() -> bool {
        false
    }

    #[test]
    fn equal_functions_share_one_node() {
        let mut b = Builder::new(&never);
        let x = b.node(0, leaf(0), leaf(1)).unwrap();
        let y = b.node(0, leaf(0), leaf(1)).unwrap();
        assert_eq!(x, y);
        assert_eq!(b.node(1, x, x).unwrap(), x, "equal children reduce");
        assert_eq!(b.len(), 1);
    }

    #[test]
    fn apply_matches_pointwise_evaluation() {
        // (a0 xor a2) as 0/1 leaves, combined with a1 by max.
        let mut b = Builder::new(&never);
        let not_a2 = b.node(2, leaf(1), leaf(0)).unwrap();
        let a2 = b.node(2, leaf(0), leaf(1)).unwrap();
        let xor = b.node(0, a2, not_a2).unwrap();
        let a1 = b.node(1, leaf(0), leaf(1)).unwrap();
        let mut memo = FastMap::default();
        let or = b
            .apply(
                xor,
                a1,
                &mut |x, y| x.max(y),
                Some(leaf(1)),
                Some(leaf(0)),
                &mut memo,
            )
            .unwrap();
        let mut cubes = Vec::new();
        b.diagram().paths(or, &mut |c, x| cubes.push((c, x)));
        let d = b.freeze();
        for v in 0..8usize {
            let want = u32::from((v & 1 ^ v >> 2 & 1) == 1 || v >> 1 & 1 == 1);
            assert_eq!(d.eval(or, v), want, "v = {v}");
            let hits: Vec<_> = cubes.iter().filter(|(c, _)| c.contains(v as u32)).collect();
            assert_eq!(hits.len(), 1, "paths are disjoint and cover");
            assert_eq!(hits[0].1, want);
        }
    }

    #[test]
    fn a_stop_is_asked_every_stop_every_nodes() {
        let stop = || true;
        let mut b = Builder::new(&stop);
        let mut last = leaf(0);
        let mut made = 0;
        let err = (0..STOP_EVERY as u32 + 1)
            .try_for_each(|i| {
                last = b.node(i % 31, last, leaf(i + 1))?;
                made += 1;
                Ok::<_, AutomatonError>(())
            })
            .unwrap_err();
        assert_eq!(err, AutomatonError::Interrupted);
        // The callback is first asked when the STOP_EVERY-th node is about to be stored.
        assert_eq!(made, STOP_EVERY - 1);
        assert_eq!(b.len(), STOP_EVERY - 1);
    }
}
