//! Which rows of Eq. 5D2 need the second-order form (HOCBF, Xiao & Belta): a barrier whose
//! predicate reads no state dimension an input moves directly has `Lg h = 0` identically under
//! the model (relative degree 2: a position constraint under an acceleration-level model), so a
//! first-order row would be empty and enforce nothing. Decided once, from the structure of the
//! model and the predicates, when the shield is built. A shield without a model (`f`, `g` with
//! every call) can only form first-order rows, so each call checks that the `g` it is given
//! moves something every enforced barrier reads: a row that cannot act is an error, never a
//! silent pass.
//!
//! A barrier that reads both kinds of dimension (a point of the body under an acceleration-level
//! model: its position is two integrations from the acceleration, its heading one from the
//! steering) has mixed relative degree. Its rate splits into `Lf h` (no input) and `Lg h . a`.
//! The shield holds each part with its own row: the second-order row keeps
//! `psi_1 = Lf h + alpha h >= 0`, and a first-order row keeps `Lg h . a >= -alpha h`. Together
//! `dh/dt >= -2 alpha h`, so `h` stays positive, and the first-order row is always feasible
//! (`a` with `Lg h . a = 0` meets it).

use super::{ShieldError, ShieldParams};
use crate::automaton::Automaton;
use crate::dynamics::Structure;
use crate::predicate::Predicate;

/// The form of one barrier's rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Form {
    /// One first-order row (relative degree 1).
    First,
    /// One second-order (HOCBF) row (relative degree 2).
    Second,
    /// Mixed relative degree: the second-order row on `Lf h`, then a first-order row on
    /// `Lg h . a` (see the module docs).
    Mixed,
}

impl Form {
    /// Whether the first row is the second-order one.
    pub(super) fn second(self) -> bool {
        self != Form::First
    }
}

/// The order of every barrier row and of the CLF row.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct Orders {
    /// Per atom of the spec: the form of its safe-set literal's rows (first order for atoms
    /// no safe set can keep).
    pub(super) atoms: Vec<Form>,
    /// Per user barrier, the same.
    pub(super) barriers: Vec<Form>,
    /// The CLF needs its second-order form (no CLF dimension is moved by an input directly).
    pub(super) clf: bool,
    /// Per atom of the spec: some state's safe set keeps it (the shield may enforce it).
    pub(super) enforced: Vec<bool>,
}

/// The relative degree of a barrier on `predicate` under `model`: 1 when it reads a dimension
/// an input moves, 2 when it reads one an input moves through one integration, mixed when it
/// reads both, else none the shield can enforce (`None`).
fn degree(predicate: &Predicate, model: &dyn Structure, n: usize) -> Option<Form> {
    let reads = |test: &dyn Fn(usize) -> bool| (0..n).any(|d| predicate.reads(d) && test(d));
    let once = reads(&|d| model.actuates(d));
    let twice = reads(&|d| !model.actuates(d) && model.actuates_twice_removed(d));
    match (once, twice) {
        (true, true) => Some(Form::Mixed),
        (true, false) => Some(Form::First),
        (false, true) => Some(Form::Second),
        (false, false) => None,
    }
}

impl Orders {
    /// The orders for `spec`'s atoms and `params`'s barriers under `model` (`None`: `f`, `g`
    /// come with every call and every row is first order). Errors when a second-order row is
    /// needed and `alpha2` is missing.
    pub(super) fn new(
        automaton: &Automaton,
        params: &ShieldParams,
        model: Option<&dyn Structure>,
        n: usize,
    ) -> Result<Self, ShieldError> {
        let spec = automaton.spec();
        // Only atoms that some state's safe set can keep are ever enforced.
        let enforced: Vec<bool> = (0..spec.atoms().len())
            .map(|atom| {
                (0..automaton.num_states()).any(|q| {
                    let cnf = if params.preserve_progress {
                        automaton.avoid_cnf(q)
                    } else {
                        automaton.trap_cnf(q)
                    };
                    cnf.is_ok_and(|cnf| cnf.iter().flatten().any(|l| l.atom == atom))
                })
            })
            .collect();
        let Some(model) = model else {
            return Ok(Orders {
                atoms: vec![Form::First; spec.atoms().len()],
                barriers: vec![Form::First; params.barriers.len()],
                clf: false,
                enforced,
            });
        };
        let order = |what: String, p: &Predicate| -> Result<Form, ShieldError> {
            match degree(p, model, n) {
                _ if !params.use_cbf => Ok(Form::First),
                Some(form) => Ok(form),
                None => Err(ShieldError::Config(format!(
                    "{what} reads no state dimension that {model} can move within two \
                     integrations (relative degree > 2, or not controlled): the shield cannot \
                     enforce it"
                ))),
            }
        };
        let atoms: Vec<Form> = spec
            .atoms()
            .iter()
            .zip(spec.predicates())
            .enumerate()
            .map(|(i, (a, p))| match enforced[i] {
                true => order(format!("atom {a:?}"), p),
                false => Ok(Form::First),
            })
            .collect::<Result<_, _>>()?;
        let barriers: Vec<Form> = params
            .barriers
            .iter()
            .map(|b| order(format!("barrier {:?}", b.name), &b.predicate))
            .collect::<Result<_, _>>()?;
        let clf = params.use_clf && !params.pos.iter().any(|&d| model.actuates(d));
        if params.alpha2.is_none() {
            let first = atoms
                .iter()
                .position(|o| o.second())
                .map(|i| format!("atom {:?}", spec.atoms()[i]))
                .or_else(|| {
                    barriers
                        .iter()
                        .position(|o| o.second())
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
            enforced,
        })
    }

    /// Whether some row needs the drift's Jacobian (a second-order barrier row or CLF).
    pub(super) fn second_order(&self) -> bool {
        self.clf || self.atoms.iter().chain(&self.barriers).any(|o| o.second())
    }

    /// For a shield without a model: checks that the `g` (n x m) given at `s` moves a state
    /// dimension that every enforceable barrier reads. A barrier whose dimensions `g` leaves
    /// alone has `Lg h = 0`: its first-order row could not act, and without a model the shield
    /// cannot form the second-order one.
    pub(super) fn check_authority(
        &self,
        automaton: &Automaton,
        params: &ShieldParams,
        g: &[f64],
        n: usize,
    ) -> Result<(), ShieldError> {
        if !params.use_cbf {
            return Ok(());
        }
        let m = g.len() / n.max(1);
        let moved = |d: usize| g[d * m..(d + 1) * m].iter().any(|&v| v != 0.0);
        let acts = |p: &Predicate| (0..n).any(|d| p.reads(d) && moved(d));
        let spec = automaton.spec();
        let atoms = spec
            .atoms()
            .iter()
            .zip(spec.predicates())
            .zip(&self.enforced);
        let unmoved = params
            .barriers
            .iter()
            .map(|b| (format!("barrier {:?}", b.name), &b.predicate))
            .chain(
                atoms
                    .filter(|(_, &on)| on)
                    .map(|((a, p), _)| (format!("atom {a:?}"), p)),
            )
            .find(|(_, p)| !acts(p));
        match unmoved {
            None => Ok(()),
            Some((what, _)) => Err(ShieldError::Config(format!(
                "{what}: the g passed with this call moves none of the state dimensions it reads \
                 (Lg h = 0), so its first-order row cannot act, and a shield without a model \
                 cannot form the second-order one (relative degree 2, e.g. a position under an \
                 acceleration input). Build the shield with dynamics=tlshield.ControlAffine(f, \
                 g, ...) or a built-in model"
            ))),
        }
    }
}
