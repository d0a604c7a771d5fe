//! Which rows of Eq. 5D2 need the second-order form (HOCBF, Xiao & Belta): a barrier whose
//! predicate reads no state dimension an input moves directly has `Lg h = 0` identically under
//! the model (relative degree 2: a position constraint under an acceleration-level model), so a
//! first-order row would be empty and enforce nothing. Decided once, from the structure of the
//! model and the predicates, when the shield is built.

use super::{ShieldError, ShieldParams};
use crate::automaton::Automaton;
use crate::dynamics::Dynamics;
use crate::predicate::Predicate;

/// The order of every barrier row and of the CLF row.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct Orders {
    /// Per atom of the spec: its safe-set literal needs the second-order row (false for atoms
    /// no safe set can keep).
    pub(super) atoms: Vec<bool>,
    /// Per user barrier, the same.
    pub(super) barriers: Vec<bool>,
    /// The CLF needs its second-order form (no CLF dimension is moved by an input directly).
    pub(super) clf: bool,
}

/// The relative degree of a barrier on `predicate` under `model`: 1 when it reads a dimension
/// an input moves, 2 when it reads one an input moves through one integration, else none the
/// shield can enforce (`None`).
fn degree(predicate: &Predicate, model: &Dynamics, n: usize) -> Option<u8> {
    let reads = |test: &dyn Fn(usize) -> bool| (0..n).any(|d| predicate.reads(d) && test(d));
    if reads(&|d| model.actuates(d)) {
        Some(1)
    } else if reads(&|d| model.actuates_twice_removed(d)) {
        Some(2)
    } else {
        None
    }
}

impl Orders {
    /// The orders for `spec`'s atoms and `params`'s barriers under `model` (`None`: `f`, `g`
    /// come with every call and every row is first order). Errors when a second-order row is
    /// needed and `alpha2` is missing.
    pub(super) fn new(
        automaton: &Automaton,
        params: &ShieldParams,
        model: Option<&Dynamics>,
        n: usize,
    ) -> Result<Self, ShieldError> {
        let spec = automaton.spec();
        let Some(model) = model else {
            return Ok(Orders {
                atoms: vec![false; spec.atoms().len()],
                barriers: vec![false; params.barriers.len()],
                clf: false,
            });
        };
        let order = |what: String, p: &Predicate| -> Result<bool, ShieldError> {
            match degree(p, model, n) {
                Some(d) => Ok(params.use_cbf && d == 2),
                None if !params.use_cbf => Ok(false),
                None => Err(ShieldError::Config(format!(
                    "{what} reads no state dimension that {model} can move within two \
                     integrations (relative degree > 2, or not controlled): the shield cannot \
                     enforce it"
                ))),
            }
        };
        // Only atoms that some state's safe set can keep are ever enforced.
        let enforced = |atom: usize| {
            (0..automaton.num_states()).any(|q| {
                let cnf = if params.preserve_progress {
                    automaton.avoid_cnf(q)
                } else {
                    automaton.trap_cnf(q)
                };
                cnf.is_ok_and(|cnf| cnf.iter().flatten().any(|l| l.atom == atom))
            })
        };
        let atoms: Vec<bool> = spec
            .atoms()
            .iter()
            .zip(spec.predicates())
            .enumerate()
            .map(|(i, (a, p))| match enforced(i) {
                true => order(format!("atom {a:?}"), p),
                false => Ok(false),
            })
            .collect::<Result<_, _>>()?;
        let barriers: Vec<bool> = params
            .barriers
            .iter()
            .map(|b| order(format!("barrier {:?}", b.name), &b.predicate))
            .collect::<Result<_, _>>()?;
        let clf = params.use_clf && !params.pos.iter().any(|&d| model.actuates(d));
        if params.alpha2.is_none() {
            let first = atoms
                .iter()
                .position(|&o| o)
                .map(|i| format!("atom {:?}", spec.atoms()[i]))
                .or_else(|| {
                    barriers
                        .iter()
                        .position(|&o| o)
                        .map(|i| format!("barrier {:?}", params.barriers[i].name))
                });
            if let Some(what) = first {
                return Err(ShieldError::Config(format!(
                    "{what} has relative degree 2 under {model} (no input moves what it reads): \
                     pass alpha2, the gain of the second-order (HOCBF) condition"
                )));
            }
        }
        Ok(Orders {
            atoms,
            barriers,
            clf,
        })
    }
}
