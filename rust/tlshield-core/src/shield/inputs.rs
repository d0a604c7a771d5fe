//! The inputs of a shield call: per-call dynamics ([`ControlAffine`], [`BatchDynamics`]), the
//! rows of a batch, one call's arguments and what it is asked for.

use crate::error::InputError;
use crate::monitor::Monitor;

/// Per-call dynamics `f(s)` (length n) and `g(s)` (n x m, row-major), overriding the model,
/// and the drift's Jacobian `J_f(s)` (n x n, row-major) that second-order rows need. Without
/// `jacobian` a built-in model's own Jacobian is used; a [`CustomModel`](crate::custom::CustomModel) shield with
/// second-order rows requires it.
#[derive(Debug, Clone, Copy)]
pub struct ControlAffine<'a> {
    /// Drift.
    pub f: &'a [f64],
    /// Input matrix, row-major.
    pub g: &'a [f64],
    /// `df_i/ds_j` at `[i * n + j]`, when given.
    pub jacobian: Option<&'a [f64]>,
}

impl<'a> ControlAffine<'a> {
    /// `f` and `g` without a Jacobian.
    pub fn new(f: &'a [f64], g: &'a [f64]) -> Self {
        ControlAffine {
            f,
            g,
            jacobian: None,
        }
    }

    /// Per-call dynamics from what a caller passed: both `f` and `g` (the control-affine
    /// dynamics at the call's state), or neither (the shield's model).
    pub fn given(f: Option<&'a [f64]>, g: Option<&'a [f64]>) -> Result<Option<Self>, InputError> {
        match (f, g) {
            (Some(f), Some(g)) => Ok(Some(ControlAffine::new(f, g))),
            (None, None) => Ok(None),
            (f, _) => Err(InputError::Value {
                what: "f, g".into(),
                expected: "both f and g (the control-affine dynamics at s), or neither".into(),
                got: format!("only {}", if f.is_some() { "f" } else { "g" }),
            }),
        }
    }
}

/// Per-row dynamics of a batch (a [`CustomModel`](crate::custom::CustomModel) shield's, or a shield without a model):
/// `f` `(B, n)`, `g` `(B, n, m)` and `jacobian` `(B, n, n)`, row-major.
#[derive(Debug, Clone, Copy)]
pub struct BatchDynamics<'a> {
    /// Drifts.
    pub f: &'a [f64],
    /// Input matrices.
    pub g: &'a [f64],
    /// Drift Jacobians, when given.
    pub jacobian: Option<&'a [f64]>,
}

impl<'a> BatchDynamics<'a> {
    /// Row `i`'s dynamics (sizes checked by the shield before any row is read).
    pub(super) fn row(&self, i: usize, n: usize, m: usize) -> ControlAffine<'a> {
        ControlAffine {
            f: &self.f[i * n..(i + 1) * n],
            g: &self.g[i * n * m..(i + 1) * n * m],
            jacobian: self.jacobian.map(|j| &j[i * n * n..(i + 1) * n * n]),
        }
    }
}

/// The rows of a batch given as states: `(B, n)` states, row-major, and their `(B,)` FSA
/// states. Sizes are checked by the call that takes it (`states.len() == qs.len() * n`, n > 0).
#[derive(Debug, Clone, Copy)]
pub struct StateBatch<'a> {
    /// The states, row after row.
    pub states: &'a [f64],
    /// The state length n.
    pub n: usize,
    /// Each row's FSA state.
    pub qs: &'a [usize],
}

impl<'a> StateBatch<'a> {
    /// `(B, n)` states row-major and their FSA states.
    pub fn new(states: &'a [f64], n: usize, qs: &'a [usize]) -> Self {
        StateBatch { states, n, qs }
    }

    /// The number of rows B.
    pub fn len(&self) -> usize {
        self.qs.len()
    }

    /// Whether the batch has no rows.
    pub fn is_empty(&self) -> bool {
        self.qs.is_empty()
    }

    /// Row `i`'s state.
    pub fn state(&self, i: usize) -> &'a [f64] {
        &self.states[i * self.n..(i + 1) * self.n]
    }
}

/// Where the rows of a batch read their state and FSA state.
#[derive(Clone, Copy)]
pub(super) enum BatchRows<'a> {
    /// Given states and FSA states.
    States(StateBatch<'a>),
    /// Each row's task monitor (its last state, FSA state, reading and goal).
    Monitors(&'a [Monitor]),
}

impl<'a> BatchRows<'a> {
    pub(super) fn len(&self) -> usize {
        match self {
            BatchRows::States(batch) => batch.len(),
            BatchRows::Monitors(monitors) => monitors.len(),
        }
    }

    pub(super) fn state_len(&self) -> usize {
        match self {
            BatchRows::States(batch) => batch.n,
            BatchRows::Monitors(monitors) => monitors[0].state().len(),
        }
    }

    /// The call of row `i`: its state, FSA state, monitor (if any), RL action, dynamics and
    /// drift.
    pub(super) fn call(
        &self,
        i: usize,
        a_rl: &'a [f64],
        dynamics: Option<BatchDynamics<'a>>,
        drift: Option<&'a [f64]>,
        m: usize,
    ) -> Call<'a> {
        let (s, q, task) = self.row(i);
        let n = s.len();
        Call {
            s,
            q,
            a_rl: &a_rl[i * m..(i + 1) * m],
            fg: dynamics.map(|d| d.row(i, n, m)),
            drift: drift.map(|d| &d[i * n..(i + 1) * n]),
            task,
        }
    }

    /// Row `i`: its state, FSA state and monitor (if any).
    pub(super) fn row(&self, i: usize) -> (&'a [f64], usize, Option<&'a Monitor>) {
        match *self {
            BatchRows::States(batch) => (batch.state(i), batch.qs[i], None),
            BatchRows::Monitors(monitors) => {
                let monitor = &monitors[i];
                (monitor.state(), monitor.q(), Some(monitor))
            }
        }
    }
}

/// The inputs of one single-state call.
#[derive(Clone, Copy)]
pub(super) struct Call<'a> {
    pub(super) s: &'a [f64],
    pub(super) q: usize,
    pub(super) a_rl: &'a [f64],
    pub(super) fg: Option<ControlAffine<'a>>,
    pub(super) drift: Option<&'a [f64]>,
    /// The task monitor whose reading and goal the step reuses (it holds `s` and `q`).
    pub(super) task: Option<&'a Monitor>,
}

/// What a filtering call fills in: the corrected action alone, or everything a caller may
/// inspect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Want {
    /// The corrected action and the solve's outcome (`a_cbf`, `a_clf`, `delta`, slack, status,
    /// solver); [`Filtered::goal`](super::Filtered::goal) and
    /// [`Filtered::barriers`](super::Filtered::barriers) are left empty: what a batch row or a
    /// vector environment's step needs.
    Action,
    /// Also the CLF goal and the enforced barriers ([`Shield::filter`](super::Shield::filter)).
    Record,
}

/// How far a shield step goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Stage {
    /// The QP only ([`Shield::problem`](super::Shield::problem)).
    Problem,
    /// The filtered action, with what `Want` asks for.
    Filter(Want),
}
