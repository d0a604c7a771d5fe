//! The shield's input checks: every call's input (state lengths, finiteness, actions, the
//! per-call dynamics, batches and monitors), each a `ShieldError` naming what was wrong. The
//! checks every layer shares (a state's length, finiteness) are `crate::check`'s; what is
//! the shield's own (its actions, its model, the drift's layout) is here, beside the entry
//! points that run it.

use std::sync::Arc;

use crate::check::{check_finite, check_state_len, StateLen};
use crate::custom::CustomModel;
use crate::error::{AutomatonError, InputError, ShieldError};
use crate::monitor::MonitorBatch;

use super::inputs::{BatchDynamics, Call, ControlAffine, StateBatch};
use super::params::{Barrier, Bounds};
use super::Shield;

/// Checks that every row of `a` (rows of `lo.len()` values) lies in `b`, up to rounding
/// (1e-9 of the bound's size, so a policy action scaled onto the box's edge passes).
fn check_within(what: &str, a: &[f64], b: &Bounds) -> Result<(), ShieldError> {
    let m = b.lo.len();
    for (k, &v) in a.iter().enumerate() {
        let j = k % m;
        let (lo, hi) = (b.lo[j], b.hi[j]);
        let slack = 1e-9 * (1.0 + lo.abs().max(hi.abs()));
        if v < lo - slack || v > hi + slack {
            let at = if a.len() > m {
                format!("{what}[{}, {j}]", k / m)
            } else {
                format!("{what}[{j}]")
            };
            return Err(InputError::Value {
                what: at,
                expected: format!("a value in rl_bounds ({lo}, {hi})"),
                got: v.to_string(),
            }
            .into());
        }
    }
    Ok(())
}

/// Every rule a state's length must meet in a shield, in the order they are checked: the
/// spec's, the user's model's (exactly its own length), what the shield reads (the model,
/// the barriers, `pos`) and each barrier's. An `Err` for a spec that cannot evaluate states.
pub(super) fn state_rules(
    spec: &crate::spec::Spec,
    custom: Option<&CustomModel>,
    min_dim: usize,
    barriers: &[Barrier],
) -> Result<Vec<StateLen>, InputError> {
    let mut rules = vec![spec.state_len()?];
    if let Some(c) = custom {
        rules.push(StateLen {
            note: " (the model's state_dim)",
            ..StateLen::new(c.state_len(), true).named()
        });
    }
    rules.push(StateLen {
        note: " (dynamics, barriers and pos)",
        ..StateLen::new(min_dim, false).named()
    });
    rules.extend(barriers.iter().map(|b| b.predicate.state_len()));
    Ok(rules)
}

impl Shield {
    /// The rules of [`state_rules`], made at construction.
    pub(super) fn state_rules(&self) -> Result<&[StateLen], InputError> {
        self.state_len.as_deref().map_err(Clone::clone)
    }

    /// Validates the arguments of one step. A task monitor's state was checked against the
    /// same spec when the monitor read it (length and values) and its FSA state is one of the
    /// automaton's: of the state, only the shield's own rules are new to it.
    pub(super) fn check_call(&self, call: &Call<'_>) -> Result<(), ShieldError> {
        let Call {
            s,
            q,
            a_rl,
            fg,
            drift,
            task,
        } = *call;
        let n = s.len();
        check_state_len("s", n, self.state_rules()?)?;
        if task.is_none() {
            check_finite("s", s, n)?;
            self.automaton.check_state("q", q)?;
        }
        self.check_action("a_rl", a_rl)?;
        self.check_dynamics(n, fg)?;
        if let Some(d) = drift {
            self.check_drift(d, n, 1)?;
        }
        Ok(())
    }

    /// Checks a drift of `rows` rows of length `n`: its size, its values, and that it moves
    /// no dimension the model's inputs move (no model: nothing to check that against).
    fn check_drift(&self, d: &[f64], n: usize, rows: usize) -> Result<(), ShieldError> {
        if d.len() != rows * n {
            return Err(InputError::Shape {
                what: "drift".into(),
                expected: format!("{rows} x {n} (one value per state dimension)"),
                got: format!("{} values", d.len()),
            }
            .into());
        }
        check_finite("drift", d, n)?;
        self.structure()
            .map_or(Ok(()), |model| super::layout::check_drift(d, n, model))
    }

    /// Checks one call's RL action: length, finiteness and the RL box.
    fn check_action(&self, what: &str, a: &[f64]) -> Result<(), ShieldError> {
        if a.len() != self.m {
            return Err(InputError::Shape {
                what: format!("{what} length"),
                expected: format!("{} (one value per input)", self.m),
                got: a.len().to_string(),
            }
            .into());
        }
        check_finite(what, a, a.len())?;
        if let Some(rl) = &self.params.rl_bounds {
            check_within(what, a, rl)?;
        }
        Ok(())
    }

    /// Checks a batch's `(rows, m)` RL actions: shape, finiteness and the RL box.
    fn check_batch_actions(&self, a_rl: &[f64], rows: usize) -> Result<(), ShieldError> {
        let m = self.m;
        if a_rl.len() != rows * m {
            return Err(InputError::Shape {
                what: "a_rl".into(),
                expected: format!("({rows}, {m})"),
                got: format!("{} values", a_rl.len()),
            }
            .into());
        }
        check_finite("a_rl", a_rl, m)?;
        if let Some(rl) = &self.params.rl_bounds {
            check_within("a_rl", a_rl, rl)?;
        }
        Ok(())
    }

    /// Checks one call's dynamics at a state of length `n` (already checked against the
    /// shield's rules, a user's model's length among them), or, with none, that the shield
    /// has a model.
    fn check_dynamics(&self, n: usize, fg: Option<ControlAffine<'_>>) -> Result<(), ShieldError> {
        let Some(ControlAffine { f, g, jacobian }) = fg else {
            if self.dynamics.is_some() {
                return Ok(());
            }
            return Err(ShieldError::Config(match &self.custom {
                Some(c) => format!("the model {c} is evaluated by the caller: pass f and g"),
                None => "this shield has no dynamics model: pass f and g with every call".into(),
            }));
        };
        if f.len() != n {
            return Err(InputError::Shape {
                what: "f length".into(),
                expected: format!("{n} (the state length)"),
                got: f.len().to_string(),
            }
            .into());
        }
        if g.len() != n * self.m {
            return Err(InputError::Shape {
                what: "g size".into(),
                expected: format!("{n} x {} (state length x inputs)", self.m),
                got: g.len().to_string(),
            }
            .into());
        }
        check_finite("f", f, n)?;
        check_finite("g", g, self.m)?;
        match jacobian {
            Some(jac) => {
                if jac.len() != n * n {
                    return Err(InputError::Shape {
                        what: "jacobian size".into(),
                        expected: format!("{n} x {n} (df_i/ds_j)"),
                        got: jac.len().to_string(),
                    }
                    .into());
                }
                check_finite("jacobian", jac, n)?;
            }
            None if self.custom.is_some() && self.orders.second_order() => {
                return Err(ShieldError::Config(
                    "this shield has second-order rows under its ControlAffine model: pass the \
                     drift's Jacobian with f and g"
                        .into(),
                ));
            }
            None => {}
        }
        if self.dynamics.is_none() && self.custom.is_none() {
            self.orders
                .check_authority(&self.automaton, &self.params, g, n)?;
        }
        Ok(())
    }

    /// Checks a batch's per-row dynamics (or, with none, that the shield has a model).
    fn check_batch_dynamics(
        &self,
        rows: usize,
        n: usize,
        dynamics: Option<BatchDynamics<'_>>,
    ) -> Result<(), ShieldError> {
        let Some(d) = dynamics else {
            return self.check_dynamics(n, None);
        };
        let m = self.m;
        let sizes = [
            ("f", d.f.len(), n),
            ("g", d.g.len(), n * m),
            ("jacobian", d.jacobian.map_or(0, <[f64]>::len), n * n),
        ];
        for (what, got, per_row) in sizes {
            if (what != "jacobian" || d.jacobian.is_some()) && got != rows * per_row {
                return Err(InputError::Shape {
                    what: what.into(),
                    expected: format!("{rows} rows of {per_row} values"),
                    got: format!("{got} values"),
                }
                .into());
            }
        }
        (0..rows).try_for_each(|i| self.check_dynamics(n, Some(d.row(i, n, m))))
    }

    /// Checks the rows of a batch over states before any dynamics are read: the states'
    /// layout and values, each row's FSA state, the RL actions `(B, m)` and the drift
    /// `(B, n)`. A caller that evaluates a model at each row (a binding's `ControlAffine`)
    /// calls it first; every batch call over states runs it too.
    pub fn check_rows(
        &self,
        batch: StateBatch<'_>,
        a_rl: &[f64],
        drift: Option<&[f64]>,
    ) -> Result<(), ShieldError> {
        let StateBatch { states, n, qs } = batch;
        let rows = qs.len();
        if n > 0 && states.len() % n == 0 && states.len() / n != rows {
            return Err(InputError::Shape {
                what: "qs".into(),
                expected: format!("{} FSA states (one per row of states)", states.len() / n),
                got: rows.to_string(),
            }
            .into());
        }
        if n == 0 || rows.checked_mul(n) != Some(states.len()) {
            return Err(InputError::Shape {
                what: "states".into(),
                expected: format!("{rows} rows (one per q) of length n > 0"),
                got: format!("{} values with n = {n}", states.len()),
            }
            .into());
        }
        self.check_batch_actions(a_rl, rows)?;
        check_state_len("states row", n, self.state_rules()?)?;
        check_finite("states", states, n)?;
        if let Some(d) = drift {
            self.check_drift(d, n, rows)?;
        }
        Ok(self.automaton.check_states("qs", qs)?)
    }

    /// [`Shield::check_rows`] and the rows' dynamics, when given.
    pub(super) fn check_state_batch(
        &self,
        batch: StateBatch<'_>,
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
    ) -> Result<(), ShieldError> {
        self.check_rows(batch, a_rl, drift)?;
        self.check_batch_dynamics(batch.len(), batch.n, dynamics)
    }

    /// Checks the input of a batch over monitors (see [`Shield::filter_monitors_with`]);
    /// returns the state length, `None` for an empty batch.
    pub(super) fn check_monitor_batch(
        &self,
        batch: &MonitorBatch,
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
    ) -> Result<Option<usize>, ShieldError> {
        let monitors = batch.monitors();
        if !Arc::ptr_eq(batch.automaton(), &self.automaton) {
            return Err(ShieldError::Config(
                "monitors: they watch another automaton; build them from this shield's \
                 automaton (shield.automaton)"
                    .into(),
            ));
        }
        if let Some(row) = monitors.iter().position(|m| !m.started()) {
            return Err(AutomatonError::NotReset { row: Some(row) }.into());
        }
        let rows = monitors.len();
        self.check_batch_actions(a_rl, rows)?;
        let Some(first) = monitors.first() else {
            // An empty batch: nothing to check a state length against, nothing to solve.
            return Ok(None);
        };
        // Every monitor of the batch read a state of its automaton: one length for all.
        let n = first.state().len();
        check_state_len("monitor state", n, self.state_rules()?)?;
        self.check_batch_dynamics(rows, n, dynamics)?;
        if let Some(d) = drift {
            self.check_drift(d, n, rows)?;
        }
        Ok(Some(n))
    }
}
