//! [`Spec`]: an scTLTL formula ([`crate::formula`]) bound to the predicates of its atoms, with
//! its robustness and Boolean satisfaction over trajectories ([`crate::robustness`]).

use std::fmt;

use crate::check::{check_finite, check_state_len, StateLen};
use crate::error::{InputError, SpecError};
use crate::formula::Formula;
use crate::predicate::Predicate;
use crate::robustness::{Program, Scratch, Trajectory, TrajectoryBatch};

/// A formula bound to the predicates that give its atoms meaning; evaluates robustness and
/// Boolean satisfaction of trajectories (see [`Spec::robustness`]).
#[derive(Debug, Clone)]
pub struct Spec {
    formula: Formula,
    atoms: Vec<String>,
    predicates: Vec<Predicate>,
    program: Program,
    exact_dim: Option<usize>,
    min_dim: usize,
    /// Groups of atoms (bitmasks) of which at most one holds at a time.
    exclusive: Vec<u32>,
}

impl Spec {
    /// Parses `formula` and binds each atom to its predicate. Predicates for names that do not
    /// occur in the formula are allowed and ignored.
    pub fn new<I, S>(formula: &str, predicates: I) -> Result<Self, SpecError>
    where
        I: IntoIterator<Item = (S, Predicate)>,
        S: AsRef<str>,
    {
        let (parsed, atoms) = Formula::parse(formula)?;
        let mut bound: Vec<Option<(String, Predicate)>> = vec![None; atoms.len()];
        for (name, predicate) in predicates {
            if let Some(i) = atoms.iter().position(|a| a == name.as_ref()) {
                bound[i] = Some((name.as_ref().to_string(), predicate));
            }
        }
        let missing: Vec<String> = atoms
            .iter()
            .zip(&bound)
            .filter(|(_, b)| b.is_none())
            .map(|(a, _)| a.clone())
            .collect();
        if !missing.is_empty() {
            return Err(SpecError::MissingPredicates(missing));
        }
        let bound: Vec<(String, Predicate)> = bound.into_iter().flatten().collect();

        let mut exact_dim: Option<(usize, &str)> = None;
        for (name, p) in &bound {
            if let Some(d) = p.exact_dim() {
                match exact_dim {
                    Some((e, other)) if e != d => {
                        return Err(SpecError::InconsistentDimension(format!(
                            "Halfspace '{other}' has length {e} but Halfspace '{name}' has length {d}"
                        )))
                    }
                    _ => exact_dim = Some((d, name)),
                }
            }
        }
        let min_dim = bound.iter().map(|(_, p)| p.min_dim()).max().unwrap_or(0);
        if let Some((e, hs)) = exact_dim {
            if let Some((name, p)) = bound.iter().find(|(_, p)| p.min_dim() > e) {
                return Err(SpecError::InconsistentDimension(format!(
                    "'{name}' reads state dimension {} but Halfspace '{hs}' has length {e}",
                    p.min_dim() - 1
                )));
            }
        }
        let exact_dim = exact_dim.map(|(d, _)| d);
        let program = Program::compile(&parsed);
        Ok(Spec {
            formula: parsed,
            atoms,
            predicates: bound.into_iter().map(|(_, p)| p).collect(),
            program,
            exact_dim,
            min_dim,
            exclusive: Vec::new(),
        })
    }

    /// Declares groups of atoms of which at most one holds at any state (goal regions whose
    /// positions live in the state, so the geometry cannot tell). The automaton's ranks, goals
    /// and progress-preserving safe set then read only valuations that respect them. Unknown
    /// names are an error, and so are two atoms of one group whose fixed regions overlap (they
    /// can hold together). Disjoint fixed regions need no declaration: the geometry says so.
    pub fn with_exclusive<G, S>(mut self, groups: G) -> Result<Self, SpecError>
    where
        G: IntoIterator,
        G::Item: IntoIterator<Item = S>,
        S: AsRef<str>,
    {
        let masks = self.atom_masks(groups)?;
        for &mask in &masks {
            if self.is_bound() {
                let members: Vec<usize> = (0..self.atoms.len())
                    .filter(|i| mask >> i & 1 == 1)
                    .collect();
                for (k, &i) in members.iter().enumerate() {
                    for &j in &members[k + 1..] {
                        let (a, b) = (&self.predicates[i], &self.predicates[j]);
                        if crate::region::can_hold_together(a, b) == Some(true) {
                            return Err(SpecError::InvalidPredicate(format!(
                                "exclusive groups {:?} and {:?} together, but their regions \
                                 overlap: both can hold at one state",
                                self.atoms[i], self.atoms[j]
                            )));
                        }
                    }
                }
            }
        }
        self.exclusive = masks;
        Ok(self)
    }

    /// Groups of atom names as bitmasks over the atoms (bit `i`: atom `i`); an unknown name is
    /// an error that lists the atoms.
    pub fn atom_masks<G, S>(&self, groups: G) -> Result<Vec<u32>, SpecError>
    where
        G: IntoIterator,
        G::Item: IntoIterator<Item = S>,
        S: AsRef<str>,
    {
        let mut masks = Vec::new();
        for group in groups {
            let mut mask = 0u32;
            for name in group {
                let name = name.as_ref();
                let Some(i) = self.atoms.iter().position(|a| a == name) else {
                    return Err(SpecError::InvalidPredicate(format!(
                        "exclusive names {name:?}, which is not an atom of the formula (atoms: \
                         {})",
                        self.atoms.join(", ")
                    )));
                };
                mask |= 1 << i;
            }
            masks.push(mask);
        }
        Ok(masks)
    }

    /// The declared exclusive groups as bitmasks over the atoms (bit `i`: atom `i`).
    pub fn exclusive(&self) -> &[u32] {
        &self.exclusive
    }

    /// The formula alone, its atoms without predicates: its automaton has the formula's
    /// structure (states, guards, safe-set CNFs, valuations via
    /// [`crate::Automaton::step_valuation`]) but evaluates no state: every state query is an
    /// error that says so (see [`Spec::is_bound`]).
    pub fn from_formula(formula: &str) -> Result<Self, SpecError> {
        let (parsed, atoms) = Formula::parse(formula)?;
        let program = Program::compile(&parsed);
        Ok(Spec {
            formula: parsed,
            atoms,
            predicates: Vec::new(),
            program,
            exact_dim: None,
            min_dim: 0,
            exclusive: Vec::new(),
        })
    }

    /// Whether every atom has a predicate (false for [`Spec::from_formula`] with atoms).
    pub fn is_bound(&self) -> bool {
        self.predicates.len() == self.atoms.len()
    }

    /// The parsed formula.
    pub fn formula(&self) -> &Formula {
        &self.formula
    }

    /// Atom names in order of first appearance in the formula.
    pub fn atoms(&self) -> &[String] {
        &self.atoms
    }

    /// The predicate of each atom, aligned with [`Spec::atoms`].
    pub fn predicates(&self) -> &[Predicate] {
        &self.predicates
    }

    /// What the predicates need of a state's length (see [`check_state_len`]); an error for a
    /// spec without predicates, which cannot evaluate states at all.
    pub(crate) fn state_len(&self) -> Result<StateLen, InputError> {
        if !self.is_bound() {
            return Err(InputError::Value {
                what: "spec".into(),
                expected: "predicates for its atoms to evaluate states (build it with Spec::new)"
                    .into(),
                got: "a formula alone (Spec::from_formula)".into(),
            });
        }
        Ok(match self.exact_dim {
            Some(d) => StateLen::new(d, true),
            None => StateLen::new(self.min_dim.max(1), false),
        })
    }

    /// The state length, when a predicate fixes it (a Halfspace's weights do); `None` when the
    /// predicates only bound it from below.
    pub fn state_dim(&self) -> Option<usize> {
        self.exact_dim
    }

    /// Robustness of every atom at one state, written into `out` (length = number of atoms).
    /// The caller has checked the state length.
    #[inline]
    pub fn atom_robustness_into(&self, s: &[f64], out: &mut [f64]) {
        for (o, p) in out.iter_mut().zip(&self.predicates) {
            *o = p.value(s);
        }
    }

    /// Robustness of every atom at one state, after validating it.
    pub fn atom_robustness(&self, s: &[f64]) -> Result<Vec<f64>, InputError> {
        check_state_len("state", s.len(), &[self.state_len()?])?;
        check_finite("s", s, s.len())?;
        let mut out = vec![0.0; self.atoms.len()];
        self.atom_robustness_into(s, &mut out);
        Ok(out)
    }
}

impl Spec {
    fn check_trajectory(&self, traj: &Trajectory<'_>) -> Result<(), InputError> {
        check_state_len("state", traj.dim(), &[self.state_len()?])
    }

    /// Robustness `rho(s_0..s_T, phi)` at `t = 0` (closed window).
    pub fn robustness(&self, traj: Trajectory<'_>) -> Result<f64, InputError> {
        self.robustness_with(traj, &mut Scratch::default())
    }

    /// [`Spec::robustness`] reusing `scratch` (no allocation after the first call).
    pub fn robustness_with(
        &self,
        traj: Trajectory<'_>,
        scratch: &mut Scratch,
    ) -> Result<f64, InputError> {
        self.check_trajectory(&traj)?;
        Ok(crate::robustness::robustness(
            &self.program,
            &self.predicates,
            traj,
            scratch,
        ))
    }

    /// Boolean satisfaction of the whole trajectory (an atom holds iff its robustness is > 0).
    pub fn satisfied(&self, traj: Trajectory<'_>) -> Result<bool, InputError> {
        self.check_trajectory(&traj)?;
        Ok(crate::robustness::satisfied(
            &self.program,
            &self.predicates,
            traj,
            &mut Scratch::default(),
        ))
    }

    /// Robustness of every trajectory of a batch, in parallel (rayon).
    pub fn robustness_batch(&self, batch: TrajectoryBatch<'_>) -> Result<Vec<f64>, InputError> {
        check_state_len("state", batch.dim, &[self.state_len()?])?;
        batch.map(0.0, |traj, scratch| {
            crate::robustness::robustness(&self.program, &self.predicates, traj, scratch)
        })
    }

    /// Boolean satisfaction of every trajectory of a batch, in parallel (rayon).
    pub fn satisfied_batch(&self, batch: TrajectoryBatch<'_>) -> Result<Vec<bool>, InputError> {
        check_state_len("state", batch.dim, &[self.state_len()?])?;
        batch.map(false, |traj, scratch| {
            crate::robustness::satisfied(&self.program, &self.predicates, traj, scratch)
        })
    }
}

impl fmt::Display for Spec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.formula.display(&self.atoms))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_formula_alone_evaluates_no_state() {
        let spec = Spec::from_formula("F a & X b").unwrap();
        assert_eq!(spec.atoms(), ["a", "b"]);
        assert!(!spec.is_bound());
        let err = spec.state_len().unwrap_err().to_string();
        assert!(err.contains("a formula alone"), "{err}");
        let traj = Trajectory::new(&[0.0, 1.0], 1).unwrap();
        crate::tests_support::assert_error(spec.robustness(traj), "Value", "spec");
        crate::tests_support::assert_error(spec.satisfied(traj), "Value", "spec");
        assert!(Spec::from_formula("true").unwrap().is_bound());
        crate::tests_support::assert_error(Spec::from_formula("G a"), "NotCoSafe", "column 1");
    }

    #[test]
    fn spec_checks_predicates() {
        let ball = Predicate::ball(vec![0, 1], 1.0, crate::Center::Fixed(vec![0.0, 0.0])).unwrap();
        let err = Spec::new("F a & F b & c", [("a", ball.clone())]).unwrap_err();
        assert_eq!(err.to_string(), "atom(s) without a predicate: b, c");
        let hs3 = Predicate::halfspace(vec![1.0; 3], 0.0).unwrap();
        let hs4 = Predicate::halfspace(vec![1.0; 4], 0.0).unwrap();
        assert!(matches!(
            Spec::new("a & b", [("a", hs3.clone()), ("b", hs4)]),
            Err(SpecError::InconsistentDimension(_))
        ));
        let far = Predicate::ball(vec![0, 5], 1.0, crate::Center::Fixed(vec![0.0, 0.0])).unwrap();
        assert!(matches!(
            Spec::new("a & b", [("a", hs3.clone()), ("b", far)]),
            Err(SpecError::InconsistentDimension(_))
        ));
        let spec = Spec::new("F a", [("a", ball), ("unused", hs3)]).unwrap();
        assert_eq!(spec.atoms(), ["a"]);
        let rule = [spec.state_len().unwrap()];
        crate::tests_support::assert_error(
            check_state_len("state", 1, &rule),
            "Shape",
            "state length",
        );
        assert!(check_state_len("state", 2, &rule).is_ok());
    }
}
