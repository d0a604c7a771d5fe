//! The shield's input checks: every call's input (state lengths, finiteness, actions, the
//! per-call dynamics, batches and monitors), each a `ShieldError` naming what was wrong.

use std::sync::Arc;

use crate::error::{AutomatonError, InputError, ShieldError};
use crate::monitor::MonitorBatch;
use crate::validate::check_finite;

use super::inputs::{BatchDynamics, Call, ControlAffine, StateBatch};
use super::params::Bounds;
use super::Shield;

/// Checks that every row of `a` (rows of `lo.len()` values) lies in `b`, up to rounding
/// (1e-9 of the bound's size, so a policy action scaled onto the box's edge passes).
pub(super) fn check_within(what: &str, a: &[f64], b: &Bounds) -> Result<(), ShieldError> {
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

/// Checks a drift of `rows` rows of length `n` (its layout against the model's:
/// [`Shield::check_drift_layout`]).
pub(super) fn check_drift(d: &[f64], n: usize, rows: usize) -> Result<(), ShieldError> {
    if d.len() != rows * n {
        return Err(InputError::Shape {
            what: "drift".into(),
            expected: format!("{rows} x {n} (one value per state dimension)"),
            got: format!("{} values", d.len()),
        }
        .into());
    }
    check_finite("drift", d, n)?;
    Ok(())
}

impl Shield {
    /// Checks that a drift moves no dimension the model's inputs move (no model: nothing to
    /// check against).
    pub(super) fn check_drift_layout(&self, d: &[f64], n: usize) -> Result<(), ShieldError> {
        self.structure()
            .map_or(Ok(()), |model| super::layout::check_drift(d, n, model))
    }

    /// Checks the state length, finiteness and the barrier dimensions.
    pub(super) fn check_state(&self, what: &str, s: &[f64]) -> Result<(), ShieldError> {
        self.check_state_len(what, s.len())
    }

    /// Checks a state length `n` against the spec, the dynamics and the barriers (an empty
    /// batch still says how long its rows are).
    pub(super) fn check_state_len(&self, what: &str, n: usize) -> Result<(), ShieldError> {
        self.automaton.spec().check_state_len(n)?;
        // A user's model is evaluated at exactly its own state length.
        if let Some(c) = self.custom.as_ref().filter(|c| n != c.state_len()) {
            return Err(InputError::Shape {
                what: format!("{what} length"),
                expected: format!("{} (the model's state_dim)", c.state_len()),
                got: n.to_string(),
            }
            .into());
        }
        if n < self.min_dim {
            return Err(InputError::Shape {
                what: format!("{what} length"),
                expected: format!("at least {} (dynamics, barriers and pos)", self.min_dim),
                got: n.to_string(),
            }
            .into());
        }
        for b in &self.params.barriers {
            b.predicate.check_dim(n)?;
        }
        Ok(())
    }

    /// Checks a batch's `(rows, m)` RL actions: shape, finiteness and the RL box.
    pub(super) fn check_batch_actions(&self, a_rl: &[f64], rows: usize) -> Result<(), ShieldError> {
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

    pub(super) fn check_action(&self, what: &str, a: &[f64]) -> Result<(), ShieldError> {
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

    pub(super) fn check_dynamics(
        &self,
        n: usize,
        fg: Option<ControlAffine<'_>>,
    ) -> Result<(), ShieldError> {
        let Some(ControlAffine { f, g, jacobian }) = fg else {
            if self.dynamics.is_some() {
                return Ok(());
            }
            return Err(ShieldError::Config(match &self.custom {
                Some(c) => format!("the model {c} is evaluated by the caller: pass f and g"),
                None => "this shield has no dynamics model: pass f and g with every call".into(),
            }));
        };
        if let Some(c) = &self.custom {
            if n != c.state_len() {
                return Err(InputError::Shape {
                    what: "s length".into(),
                    expected: format!("{} (the model's state_dim)", c.state_len()),
                    got: n.to_string(),
                }
                .into());
            }
        }
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

    /// Validates the arguments of one step.
    pub(super) fn check_call(&self, call: &Call<'_>) -> Result<(), ShieldError> {
        let Call {
            s,
            q,
            a_rl,
            fg,
            drift,
            ..
        } = *call;
        self.check_state("s", s)?;
        check_finite("s", s, s.len())?;
        self.automaton.check_state("q", q)?;
        self.check_action("a_rl", a_rl)?;
        self.check_dynamics(s.len(), fg)?;
        if let Some(d) = drift {
            check_drift(d, s.len(), 1)?;
            self.check_drift_layout(d, s.len())?;
        }
        Ok(())
    }

    /// Checks a batch's per-row dynamics (or, with none, that the shield has a model).
    pub(super) fn check_batch_dynamics(
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
        self.check_state_len("states row", n)?;
        check_finite("states", states, n)?;
        if let Some(d) = drift {
            check_drift(d, n, rows)?;
            self.check_drift_layout(d, n)?;
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
        self.check_state("monitor state", first.state())?;
        self.check_batch_dynamics(rows, n, dynamics)?;
        if let Some(d) = drift {
            check_drift(d, n, rows)?;
            self.check_drift_layout(d, n)?;
        }
        Ok(Some(n))
    }
}
