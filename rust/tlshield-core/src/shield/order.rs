//! Which rows of Eq. 5D2 need the second-order form (HOCBF, Xiao & Belta): a barrier whose
//! predicate reads no state dimension an input moves directly has `Lg h = 0` identically under
//! the model (relative degree 2: a position constraint under an acceleration-level model), so a
//! first-order row would be empty and enforce nothing. Decided once, from the structure of the
//! model and the predicates, when the shield is built.

use super::{ShieldConfig, ShieldError};
use crate::dynamics::Dynamics;
use crate::predicate::Predicate;
use crate::spec::Spec;

/// The order of every barrier row and of the CLF row.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct Orders {
    /// Per atom of the spec: its safe-set literal needs the second-order row.
    pub(super) atoms: Vec<bool>,
    /// Per user barrier, the same.
    pub(super) barriers: Vec<bool>,
    /// The CLF needs its second-order form (no CLF dimension is moved by an input directly).
    pub(super) clf: bool,
}

fn second_order(predicate: &Predicate, model: &Dynamics, n: usize) -> bool {
    !(0..n).any(|d| predicate.reads(d) && model.actuates(d))
}

impl Orders {
    /// The orders for `spec`'s atoms and `config`'s barriers under `model` (`None`: `f`, `g`
    /// come with every call and every row is first order). Errors when a second-order row is
    /// needed and `alpha2` is missing.
    pub(super) fn new(
        spec: &Spec,
        config: &ShieldConfig,
        model: Option<&Dynamics>,
        n: usize,
    ) -> Result<Self, ShieldError> {
        let Some(model) = model else {
            return Ok(Orders {
                atoms: vec![false; spec.atoms().len()],
                barriers: vec![false; config.barriers.len()],
                clf: false,
            });
        };
        let atoms: Vec<bool> = spec
            .predicates()
            .iter()
            .map(|p| config.use_cbf && second_order(p, model, n))
            .collect();
        let barriers: Vec<bool> = config
            .barriers
            .iter()
            .map(|b| config.use_cbf && second_order(&b.predicate, model, n))
            .collect();
        let clf = config.use_clf && !config.pos.iter().any(|&d| model.actuates(d));
        if config.alpha2.is_none() {
            let first = atoms
                .iter()
                .position(|&o| o)
                .map(|i| format!("atom {:?}", spec.atoms()[i]))
                .or_else(|| {
                    barriers
                        .iter()
                        .position(|&o| o)
                        .map(|i| format!("barrier {:?}", config.barriers[i].name))
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
