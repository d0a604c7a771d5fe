//! The layout check: the model's state dimensions, the predicates' and the drift's must agree.
//! A state laid out in another order than the model assumes gives numbers of the right size
//! and no sign of the mistake, so each mismatch the structure of the model shows is an error
//! that names the dimensions, raised when the shield is built (the drift's, at the call that
//! passes it):
//!
//! - the CLF's position (by default the model's own) must be dimensions the model moves;
//! - a ball's position must be dimensions the model moves (a goal or an obstacle over values
//!   the robot cannot change is never reached, nor ever left);
//! - a centre read from the state (`center_dims`: an obstacle's or a goal's measured position)
//!   must be dimensions no input moves;
//! - a drift (the measured motion of what no input moves) must be 0 on every dimension an
//!   input moves.
//!
//! What it cannot see: a layout that swaps dimensions the model treats alike (x for y, one
//! obstacle's centre for another's), and anything of a shield without a model (`f` and `g`
//! with every call).

use crate::dynamics::Structure;
use crate::predicate::{Center, Predicate};
use crate::spec::Spec;

use super::{ShieldError, ShieldParams};

/// Fills in an unset (empty) CLF position: the model's, or
/// [`ShieldParams::DEFAULT_POS`] for a model that names none.
pub(super) fn resolve_pos(params: &mut ShieldParams, model: Option<&dyn Structure>) {
    if params.pos.is_empty() {
        params.pos = model
            .and_then(Structure::position)
            .unwrap_or_else(|| ShieldParams::DEFAULT_POS.to_vec());
    }
}

/// Every ball among the leaves of `p`.
fn balls<'a>(p: &'a Predicate, out: &mut Vec<&'a crate::predicate::Ball>) {
    match p {
        Predicate::Ball(b) => out.push(b),
        Predicate::Halfspace(_) => {}
        Predicate::Union(parts) | Predicate::Intersection(parts) => {
            parts.iter().for_each(|q| balls(q, out));
        }
    }
}

/// Checks the CLF's position and every ball of the spec and of the barriers against `model`.
pub(super) fn check(
    spec: &Spec,
    params: &ShieldParams,
    model: &dyn Structure,
) -> Result<(), ShieldError> {
    let still = |dims: &[usize]| -> Vec<usize> {
        dims.iter().copied().filter(|&d| !model.moves(d)).collect()
    };
    if params.use_clf {
        let unmoved = still(&params.pos);
        if !unmoved.is_empty() {
            return Err(ShieldError::Config(format!(
                "pos = {:?}: the CLF drives dimensions {unmoved:?}, which {model} does not move \
                 (pass pos= the robot's position dimensions, or build the model over the \
                 state's layout)",
                params.pos
            )));
        }
    }
    let named = spec
        .atoms()
        .iter()
        .zip(spec.predicates())
        .map(|(a, p)| (format!("atom {a:?}"), p))
        .chain(
            params
                .barriers
                .iter()
                .map(|b| (format!("barrier {:?}", b.name), &b.predicate)),
        );
    for (what, p) in named {
        let mut found = Vec::new();
        balls(p, &mut found);
        for ball in found {
            let unmoved = still(ball.pos());
            if !unmoved.is_empty() {
                return Err(ShieldError::Config(format!(
                    "{what}: a ball over dimensions {:?}, of which {unmoved:?} {model} does not \
                     move: the robot can never enter or leave it (a ball's pos is the robot's \
                     position; check the state's layout against the model's dimensions)",
                    ball.pos()
                )));
            }
            if let Center::Dims(c) = ball.center() {
                let moved: Vec<usize> = c.iter().copied().filter(|&d| model.moves(d)).collect();
                if !moved.is_empty() {
                    return Err(ShieldError::Config(format!(
                        "{what}: its centre is read from dimensions {c:?}, of which {moved:?} \
                         {model} moves: a centre read from the state must be values no input \
                         moves (an obstacle's or a goal's measured position; check the state's \
                         layout against the model's dimensions)"
                    )));
                }
            }
        }
    }
    Ok(())
}

/// Checks that a drift (`rows` rows of `n` values) is 0 on every dimension `model` moves:
/// the drift is the measured motion of what no input moves, and the model already accounts
/// for the rest.
pub(super) fn check_drift(d: &[f64], n: usize, model: &dyn Structure) -> Result<(), ShieldError> {
    for (k, &v) in d.iter().enumerate() {
        let dim = k % n;
        if v != 0.0 && model.moves(dim) {
            return Err(ShieldError::Config(format!(
                "drift[{dim}] = {v}: dimension {dim} is one {model} moves; the drift is the \
                 measured motion of state values no input moves (obstacle centres), so it must \
                 be 0 there (check the state's layout against the model's dimensions)"
            )));
        }
    }
    Ok(())
}
