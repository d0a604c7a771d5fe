//! The input checks every layer shares, each once: a state's length against its readers'
//! rules ([`check_state_len`]), non-finite values reported with their position
//! ([`check_finite`]), a state and a batch of states as a task monitor reads them
//! ([`check_state`], [`check_state_rows`]), and a restored step count. A leaf module (it
//! depends on the error types alone), so the spec, the predicates, the monitor and the shield
//! all check through it without importing one another.

use crate::error::InputError;

/// `dim` of [`check_finite`] for a single value, named without an index (`phi`, not `phi[0]`).
pub const SCALAR: usize = 0;

/// Index of the first NaN or infinity. Scans blocks with a branch-free fold (vectorised) and
/// only searches inside a block that failed.
pub fn first_non_finite(data: &[f64]) -> Option<usize> {
    const BLOCK: usize = 64;
    data.chunks(BLOCK).enumerate().find_map(|(k, block)| {
        if block.iter().fold(true, |ok, v| ok & v.is_finite()) {
            None
        } else {
            block
                .iter()
                .position(|v| !v.is_finite())
                .map(|i| k * BLOCK + i)
        }
    })
}

/// Reports the first non-finite value of a row-major array of rows of `dim` values as
/// `name[row, col]` (`name[i]` for a single row, `name` alone with `dim` = [`SCALAR`]).
pub fn check_finite(name: &str, data: &[f64], dim: usize) -> Result<(), InputError> {
    match first_non_finite(data) {
        None => Ok(()),
        Some(i) if dim == SCALAR => Err(InputError::NonFinite {
            what: name.into(),
            value: data[i],
        }),
        Some(i) if data.len() == dim => Err(InputError::NonFinite {
            what: format!("{name}[{i}]"),
            value: data[i],
        }),
        Some(i) => Err(InputError::NonFinite {
            what: format!("{name}[{}, {}]", i / dim, i % dim),
            value: data[i],
        }),
    }
}

/// What one reader of a state needs of its length, and how its error reads: exactly `len`
/// values or at least `len`. The spec, a predicate, a user's model and a shield each state
/// theirs once; [`check_state_len`] checks them all.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateLen {
    /// The length required (exactly, or at least).
    pub len: usize,
    /// Whether the length must be exactly `len`.
    pub exact: bool,
    /// What the error says after the expected length (e.g. `" (the model's state_dim)"`).
    pub note: &'static str,
    /// Whether the error names the caller's argument (`{what} length`) rather than the state
    /// (`state length`): the spec and its predicates speak of the state.
    pub named: bool,
}

impl StateLen {
    /// Exactly `len` values, or at least `len` (`exact` false); the error speaks of the state.
    pub fn new(len: usize, exact: bool) -> Self {
        StateLen {
            len,
            exact,
            note: "",
            named: false,
        }
    }

    /// The same rule, its error naming the caller's argument.
    pub fn named(self) -> Self {
        StateLen {
            named: true,
            ..self
        }
    }
}

/// The one check of a state length: `n` against every rule in order; the first one broken is
/// the error (`{what} length` or `state length`, see [`StateLen::named`]). Formats nothing
/// unless it fails.
pub fn check_state_len(what: &str, n: usize, rules: &[StateLen]) -> Result<(), InputError> {
    let Some(rule) = rules
        .iter()
        .find(|r| if r.exact { n != r.len } else { n < r.len })
    else {
        return Ok(());
    };
    Err(InputError::Shape {
        what: match rule.named {
            true => format!("{what} length"),
            false => "state length".into(),
        },
        expected: match rule.exact {
            true => format!("{}{}", rule.len, rule.note),
            false => format!("at least {}{}", rule.len, rule.note),
        },
        got: n.to_string(),
    })
}

/// A state as a task monitor reads it: its length (the error names it `{what} length`) and
/// finiteness.
pub fn check_state(what: &str, s: &[f64], rule: StateLen) -> Result<(), InputError> {
    check_state_len(what, s.len(), &[rule.named()])?;
    check_finite(what, s, s.len())
}

/// `(rows, dim)` states, row-major, as a batch of task monitors reads them: the shape, each
/// row's length and finiteness.
pub fn check_state_rows(
    states: &[f64],
    dim: usize,
    rows: usize,
    rule: StateLen,
) -> Result<(), InputError> {
    if dim == 0 || rows.checked_mul(dim) != Some(states.len()) {
        return Err(InputError::Shape {
            what: "states".into(),
            expected: format!("({rows}, n): one row per monitor"),
            got: format!("{} values in rows of {dim}", states.len()),
        });
    }
    check_state_len("states row", dim, &[rule.named()])?;
    check_finite("states", states, dim)
}

/// Checks a restored step count against the horizon.
pub fn check_steps(t: u32, horizon: u32) -> Result<(), InputError> {
    if t > horizon {
        return Err(InputError::Value {
            what: "t".into(),
            expected: format!("a step count within the horizon (0..={horizon})"),
            got: t.to_string(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_rule_broken_names_the_error() {
        let rules = [
            StateLen::new(3, false),
            StateLen {
                note: " (the model's state_dim)",
                ..StateLen::new(4, true).named()
            },
        ];
        assert!(check_state_len("s", 4, &rules).is_ok());
        let short = check_state_len("s", 2, &rules).unwrap_err().to_string();
        assert_eq!(short, "state length: expected at least 3, got 2");
        let long = check_state_len("s", 5, &rules).unwrap_err().to_string();
        assert_eq!(long, "s length: expected 4 (the model's state_dim), got 5");
    }

    #[test]
    fn a_non_finite_value_is_named_by_its_place() {
        let err = |data: &[f64], dim| check_finite("x", data, dim).unwrap_err().to_string();
        assert_eq!(
            err(&[f64::NAN], SCALAR),
            "x is NaN (all values must be finite)"
        );
        assert_eq!(
            err(&[0.0, f64::INFINITY], 2),
            "x[1] is inf (all values must be finite)"
        );
        assert_eq!(
            err(&[0.0, 0.0, f64::NAN], 2),
            "x[1, 0] is NaN (all values must be finite)"
        );
        assert!(check_finite("x", &[1.0, 2.0], 2).is_ok());
    }
}
