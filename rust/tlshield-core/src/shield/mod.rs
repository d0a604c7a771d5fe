//! The shield: once per environment step, the TL-CLF-CBF quadratic program of the paper
//! (Eq. 5D2) corrects the RL action `a_rl`.
//!
//! Variables `a_cbf` (m), `a_clf` (m) and `delta`; minimise `|a_cbf|^2 + |a_clf|^2 + K delta`
//! subject to
//! - every barrier `h` (the user's barriers, then the CBF safe set of the FSA state, Eq. 5C1):
//!   `dh/ds (f + g (a_rl + a_cbf + a_clf)) + alpha (h - margin) >= 0` (a tiny `margin` keeps
//!   `h` strictly positive, as the automaton's atoms need);
//! - the CLF row towards the goal of Eq. 5B1, `V = |s[pos] - goal|^2`:
//!   `dV/ds (f + g (a_rl + a_clf)) + c3 V <= delta`, `delta >= 0`;
//! - box bounds on `a_cbf` and `a_clf`, and optional actuator limits on the applied action.
//!
//! What is off is dropped: no CBF -> no `a_cbf` and no barrier rows; no CLF, or no goal this
//! step (accepting state, or no positive Ball literal) -> no `a_clf`, `delta` and CLF row.
//!
//! Formulation detail: the CLF box gives `delta` a closed-form lower bound `delta_0` (the
//! row's smallest residual over the box, or 0), and the QP solves for `d = delta - delta_0 >= 0`.
//! Same solution; but the objective stays of the order of `|a|^2` instead of `K delta`, which
//! keeps an interior-point solver's relative gap (and so the actions) accurate to ~1e-9
//! instead of ~1e-4 when the CLF row cannot hold.
//! An infeasible or failed solve is retried with a slack `sigma_i >= 0` on every barrier row
//! (cost `slack_penalty * sigma_i`): status [`Status::Relaxed`]. If that fails too the
//! corrections are zero: [`Status::Failed`]. Numbers never come back NaN.
//!
//! Solvers: Clarabel is the solver of record; the dense active-set method
//! ([`crate::active_set`]) serves small problems in microseconds and hands anything it cannot
//! certify to Clarabel ([`SolverChoice::Auto`]).

use std::sync::Arc;

use rayon::prelude::*;
use smallvec::SmallVec;

use crate::active_set::ActiveSetQp;
use crate::automaton::Automaton;
use crate::cnf::Literal;
use crate::custom::CustomModel;
use crate::dynamics::{Dynamics, Structure};
use crate::error::{AutomatonError, InputError, ShieldError};
use crate::monitor::{Monitor, MonitorBatch};
use crate::predicate::Predicate;
use crate::qp::{ClarabelQp, DenseQp, QpSolution, QpStatus};
use crate::slots::Slots;
use crate::validate::check_finite;

mod gradient;
mod order;
mod program;
pub use gradient::{BatchGradient, GRAD_DEGENERATE, GRAD_FAILED, GRAD_RELAXED, GRAD_SINGULAR};
use order::Orders;
use program::Program;

/// Batches smaller than this are shielded on the calling thread.
pub const PARALLEL_MIN_ROWS: usize = crate::parallel::MIN_ROWS;

/// Every QP answer is checked against the constraints it was asked to satisfy: row `i` of
/// `G x <= h` may exceed its right-hand side by at most `RESIDUAL_TOL * (1 + |h_i| +
/// sum_j |G_ij x_j|)` (relative to the row's scale, well above the solvers' own 1e-8
/// tolerances). An answer outside it is not returned as solved (see [`Status::Inaccurate`]).
pub const RESIDUAL_TOL: f64 = 1e-7;

/// Whether `x` satisfies every row of `qp` within [`RESIDUAL_TOL`] (and is finite).
fn within_tolerance(qp: &DenseQp, x: &[f64]) -> bool {
    let n = qp.vars();
    x.len() == n
        && x.iter().all(|v| v.is_finite())
        && qp.h.iter().enumerate().all(|(i, &hi)| {
            let row = &qp.g[i * n..(i + 1) * n];
            let (gx, scale) = row
                .iter()
                .zip(x)
                .fold((0.0, 0.0), |(s, a), (g, x)| (s + g * x, a + (g * x).abs()));
            gx - hi <= RESIDUAL_TOL * (1.0 + hi.abs() + scale)
        })
}

/// Problems up to this many variables go to the active-set path under [`SolverChoice::Auto`]:
/// as many as its fixed-size workspace holds.
pub const ACTIVE_SET_MAX_VARS: usize = crate::active_set::MAX_VARS;

/// A user barrier: `h = rho(predicate)` (`positive`) or `h = -rho(predicate)` (keep out of
/// the predicate's region, e.g. a moving obstacle's disc), kept above the margin.
#[derive(Debug, Clone, PartialEq)]
pub struct Barrier {
    /// Its name in results.
    pub name: String,
    /// The predicate whose robustness (or its negation) is the barrier.
    pub predicate: Predicate,
    /// `false`: the barrier is the predicate's negation.
    pub positive: bool,
    /// Scales this row's slack cost when the QP has to be relaxed (safe-set rows: 1). A
    /// barrier with a smaller weight gives way first: e.g. a moving obstacle's row rather
    /// than the task's channel.
    pub slack_weight: f64,
}

impl Barrier {
    /// `h = rho(predicate)`.
    pub fn inside(name: impl Into<String>, predicate: Predicate) -> Self {
        Barrier {
            name: name.into(),
            predicate,
            positive: true,
            slack_weight: 1.0,
        }
    }

    /// `h = -rho(predicate)`: stay out of the predicate's region.
    pub fn outside(name: impl Into<String>, predicate: Predicate) -> Self {
        Barrier {
            name: name.into(),
            predicate,
            positive: false,
            slack_weight: 1.0,
        }
    }

    /// The barrier's value `h(s)` (the predicate's robustness, negated for an `outside`
    /// barrier): the barrier holds while it is > 0.
    pub fn value(&self, s: &[f64]) -> f64 {
        let h = self.predicate.value(s);
        if self.positive {
            h
        } else {
            -h
        }
    }

    /// The same barrier with slack weight `weight` (see [`Barrier::slack_weight`]).
    pub fn with_slack_weight(self, weight: f64) -> Self {
        Barrier {
            slack_weight: weight,
            ..self
        }
    }
}

/// Which QP solver the shield uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolverChoice {
    /// The active-set path for small problems, Clarabel when it cannot certify a solution.
    Auto,
    /// Clarabel only.
    Clarabel,
    /// The active-set path only (a problem it cannot solve counts as infeasible).
    ActiveSet,
}

impl SolverChoice {
    /// The name [`SolverChoice::parse`] reads.
    pub fn name(self) -> &'static str {
        match self {
            SolverChoice::Auto => "auto",
            SolverChoice::Clarabel => "clarabel",
            SolverChoice::ActiveSet => "active_set",
        }
    }

    /// Parses `"auto"`, `"clarabel"` or `"active_set"`.
    pub fn parse(name: &str) -> Result<Self, ShieldError> {
        match name {
            "auto" => Ok(SolverChoice::Auto),
            "clarabel" => Ok(SolverChoice::Clarabel),
            "active_set" => Ok(SolverChoice::ActiveSet),
            other => Err(ShieldError::Config(format!(
                "solver = {other:?}: expected \"auto\", \"clarabel\" or \"active_set\""
            ))),
        }
    }
}

/// How a shield step ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Status {
    /// The QP was solved as posed.
    Solved = 0,
    /// The barriers could not all hold; solved with slack on the barrier rows.
    Relaxed = 1,
    /// Even the relaxed problem failed; the corrections are zero.
    Failed = 2,
    /// The solver reported the problem as posed solved, but its answer broke a constraint by
    /// more than [`RESIDUAL_TOL`]; the action is the relaxed problem's answer, which passed the
    /// same check (the largest slack is reported).
    Inaccurate = 3,
}

impl Status {
    /// `"solved"`, `"relaxed"`, `"failed"` or `"inaccurate"`.
    pub fn name(self) -> &'static str {
        match self {
            Status::Solved => "solved",
            Status::Relaxed => "relaxed",
            Status::Failed => "failed",
            Status::Inaccurate => "inaccurate",
        }
    }
}

/// Which solver produced the answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum SolvedBy {
    /// No QP (nothing to correct: both CBF and CLF off, or no rows at all), or failed.
    Nothing = 0,
    /// The dense active-set path.
    ActiveSet = 1,
    /// Clarabel.
    Clarabel = 2,
}

impl SolvedBy {
    /// `"none"`, `"active_set"` or `"clarabel"`.
    pub fn name(self) -> &'static str {
        match self {
            SolvedBy::Nothing => "none",
            SolvedBy::ActiveSet => "active_set",
            SolvedBy::Clarabel => "clarabel",
        }
    }
}

/// Lower and upper bounds per input (length m, finite, `lo <= hi`).
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    /// Lower bounds.
    pub lo: Vec<f64>,
    /// Upper bounds.
    pub hi: Vec<f64>,
}

impl Bounds {
    /// Checks lengths, finiteness and order; `what` names the argument in the message.
    fn check(&self, what: &str, m: usize) -> Result<(), ShieldError> {
        if self.lo.len() != m || self.hi.len() != m {
            return Err(ShieldError::Config(format!(
                "{what}: expected (lo, hi) with {m} values each (one per input), got {} and {}",
                self.lo.len(),
                self.hi.len()
            )));
        }
        for (i, (lo, hi)) in self.lo.iter().zip(&self.hi).enumerate() {
            if !(lo.is_finite() && hi.is_finite()) {
                return Err(ShieldError::Config(format!(
                    "{what}[{i}] = ({lo}, {hi}): bounds must be finite"
                )));
            }
            if lo > hi {
                return Err(ShieldError::Config(format!(
                    "{what}[{i}] = ({lo}, {hi}): lower bound above upper bound"
                )));
            }
        }
        Ok(())
    }
}

/// The 0.1 name of [`ShieldParams`] ("config" now means only a configuration of the case
/// study: rl, rl_cbf, rl_clf, rl_cbf_clf).
#[deprecated(since = "0.2.0", note = "renamed `ShieldParams`")]
pub type ShieldConfig = ShieldParams;

/// The shield's parameters (names as in the paper).
#[derive(Debug, Clone, PartialEq)]
pub struct ShieldParams {
    /// CBF class-K gain: `dh/dt + alpha h >= 0` (> 0). For a second-order (HOCBF) row it is
    /// the first gain: `psi_1 = dh/dt + alpha h`.
    pub alpha: f64,
    /// The HOCBF's second gain: `dpsi_1/dt + alpha2 psi_1 >= 0` (> 0), required when a barrier
    /// has relative degree 2 under the model (see `shield/order.rs`).
    pub alpha2: Option<f64>,
    /// CLF decay rate: `dV/dt + c3 V <= delta` (> 0).
    pub c3: f64,
    /// Linear cost on the CLF relaxation `delta` (> 0; an exact penalty once it exceeds the
    /// CLF row's multiplier).
    pub k: f64,
    /// Box on `a_cbf`.
    pub cbf_bounds: Bounds,
    /// Box on `a_clf`.
    pub clf_bounds: Bounds,
    /// Optional limits on the applied action `a_rl + a_cbf + a_clf`.
    pub action_bounds: Option<Bounds>,
    /// The range of the RL action, if known. With the CBF on, [`Shield::new`] checks that the
    /// CBF box can cancel every RL action in it plus every CLF correction (so applying no
    /// action, e.g. stopping, stays feasible and the barrier rows never need slack for want of
    /// authority), and each call refuses an `a_rl` outside it.
    pub rl_bounds: Option<Bounds>,
    /// Extra user barriers (the paper's `h(s)`), kept positive, with their names.
    pub barriers: Vec<Barrier>,
    /// State dimensions the CLF drives to the goal.
    pub pos: Vec<usize>,
    /// Gain `k` of the second-order CLF `V = |dp/dt + k (p - goal)|^2`, used when no input
    /// moves `pos` directly (acceleration-level models) (> 0).
    pub clf_gain: f64,
    /// Whether the CBF part (barriers, safe set, `a_cbf`) is on.
    pub use_cbf: bool,
    /// Whether the CLF part (`a_clf`, `delta`) is on.
    pub use_clf: bool,
    /// Which solver.
    pub solver: SolverChoice,
    /// Cost per unit of barrier slack in the relaxed problem (> 0).
    pub slack_penalty: f64,
    /// Barrier rows enforce `h - margin` (>= 0): the CBF alone keeps `h >= 0`, but an atom
    /// holds only when `rho > 0`, so a state pressed against a barrier would otherwise decay
    /// to `h = 0` exactly and count as a violation. Small ([`ShieldParams::DEFAULT_MARGIN`]).
    pub margin: f64,
    /// Whether the safe set also keeps the state out of guards that set the task back (the
    /// progress-preserving safe set, [`crate::Reading::progress_safe_set`]; beyond the paper).
    /// The same as Eq. 5C1's safe set where the trap is the only setback. On by default.
    pub preserve_progress: bool,
    /// Bounds on the model's error, `(d, w_d)`: the plant's `ds_d/dt` may differ from the
    /// model's `f_d + (g a)_d` by up to `w_d` (>= 0) in state dimension `d`; every unlisted
    /// dimension is exact. Each barrier row asks for `sum_d |dB/ds_d| w_d` more than the
    /// nominal condition (`B` is `h` for a first-order row, `psi_1` for a second-order one),
    /// so it holds for every error within the bounds (a robust CBF; DESIGN.md: "Plants the
    /// shield only approximates"). Empty by default: the model is the plant.
    pub disturbance: Vec<(usize, f64)>,
}

impl ShieldParams {
    /// Default cost per unit of barrier slack in the relaxed problem.
    pub const DEFAULT_SLACK_PENALTY: f64 = 1e6;
    /// Default barrier margin: `h` is kept above this, so atoms (`rho > 0`) stay true.
    pub const DEFAULT_MARGIN: f64 = 1e-6;
    /// Default CLF dimensions: the position is `s[0], s[1]`.
    pub const DEFAULT_POS: [usize; 2] = [0, 1];
    /// Default gain of the second-order CLF.
    pub const DEFAULT_CLF_GAIN: f64 = 1.0;

    /// The gains and boxes every shield needs; everything else at its default: no actuator
    /// limits, no user barriers, the CLF on [`ShieldParams::DEFAULT_POS`], both CBF and CLF on,
    /// [`SolverChoice::Auto`], [`ShieldParams::DEFAULT_SLACK_PENALTY`] and
    /// [`ShieldParams::DEFAULT_MARGIN`]. Validated by [`Shield::new`].
    pub fn new(alpha: f64, c3: f64, k: f64, cbf_bounds: Bounds, clf_bounds: Bounds) -> Self {
        ShieldParams {
            alpha,
            alpha2: None,
            c3,
            k,
            cbf_bounds,
            clf_bounds,
            action_bounds: None,
            rl_bounds: None,
            barriers: Vec::new(),
            pos: Self::DEFAULT_POS.to_vec(),
            clf_gain: Self::DEFAULT_CLF_GAIN,
            use_cbf: true,
            use_clf: true,
            solver: SolverChoice::Auto,
            slack_penalty: Self::DEFAULT_SLACK_PENALTY,
            margin: Self::DEFAULT_MARGIN,
            preserve_progress: true,
            disturbance: Vec::new(),
        }
    }

    /// Bounds on the model's error per state dimension (see [`ShieldParams::disturbance`]).
    pub fn with_disturbance(mut self, disturbance: Vec<(usize, f64)>) -> Self {
        self.disturbance = disturbance;
        self
    }

    /// Limits on the applied action `a_rl + a_cbf + a_clf`.
    pub fn with_action_bounds(mut self, bounds: Option<Bounds>) -> Self {
        self.action_bounds = bounds;
        self
    }

    /// The range of the RL action (see [`ShieldParams::rl_bounds`]).
    pub fn with_rl_bounds(mut self, bounds: Option<Bounds>) -> Self {
        self.rl_bounds = bounds;
        self
    }

    /// The user's barriers.
    pub fn with_barriers(mut self, barriers: Vec<Barrier>) -> Self {
        self.barriers = barriers;
        self
    }

    /// The state dimensions the CLF drives to the goal.
    pub fn with_pos(mut self, pos: Vec<usize>) -> Self {
        self.pos = pos;
        self
    }

    /// Which parts are on (the paper's configurations).
    pub fn with_parts(mut self, use_cbf: bool, use_clf: bool) -> Self {
        self.use_cbf = use_cbf;
        self.use_clf = use_clf;
        self
    }

    /// The QP solver.
    pub fn with_solver(mut self, solver: SolverChoice) -> Self {
        self.solver = solver;
        self
    }

    /// Cost per unit of barrier slack in the relaxed problem.
    pub fn with_slack_penalty(mut self, slack_penalty: f64) -> Self {
        self.slack_penalty = slack_penalty;
        self
    }

    /// The barrier margin.
    pub fn with_margin(mut self, margin: f64) -> Self {
        self.margin = margin;
        self
    }

    /// Whether the safe set preserves progress (see [`ShieldParams::preserve_progress`]).
    pub fn with_preserve_progress(mut self, on: bool) -> Self {
        self.preserve_progress = on;
        self
    }

    /// The HOCBF's second gain (needed for barriers of relative degree 2).
    pub fn with_alpha2(mut self, alpha2: Option<f64>) -> Self {
        self.alpha2 = alpha2;
        self
    }

    /// The gain of the second-order CLF.
    pub fn with_clf_gain(mut self, clf_gain: f64) -> Self {
        self.clf_gain = clf_gain;
        self
    }
}

/// Where an enforced barrier comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BarrierSource {
    /// The user's barrier with this index in [`ShieldParams::barriers`].
    User(usize),
    /// The literal kept from a clause of the FSA state's safe set.
    SafeSet(Literal),
}

/// The outcome of one shield step.
#[derive(Debug, Clone, PartialEq)]
pub struct Filtered {
    /// The action to apply: `a_rl + a_cbf + a_clf`.
    pub action: Vec<f64>,
    /// The safety correction (zeros when the CBF is off).
    pub a_cbf: Vec<f64>,
    /// The task correction (zeros when the CLF is off or there is no goal).
    pub a_clf: Vec<f64>,
    /// The CLF relaxation (0 when the CLF row holds).
    pub delta: f64,
    /// How the step ended.
    pub status: Status,
    /// The largest barrier slack (0 unless [`Status::Relaxed`]).
    pub slack: f64,
    /// Which solver answered.
    pub solver: SolvedBy,
    /// The CLF goal this step, if any.
    pub goal: Option<Vec<f64>>,
    /// Every barrier enforced this step and its value `h(s)`.
    pub barriers: Vec<(BarrierSource, f64)>,
}

impl Filtered {
    fn new(m: usize) -> Self {
        Filtered {
            action: vec![0.0; m],
            a_cbf: vec![0.0; m],
            a_clf: vec![0.0; m],
            delta: 0.0,
            status: Status::Solved,
            slack: 0.0,
            solver: SolvedBy::Nothing,
            goal: None,
            barriers: Vec::new(),
        }
    }
}

/// Reusable buffers and solvers for one thread of shield steps.
struct Workspace {
    program: Program,
    qp: DenseQp,
    solvers: Solvers,
    out: Filtered,
    /// Buffers of the gradient pass (`gradient.rs`), empty until it first runs.
    grad: gradient::Buffers,
}

/// The two QP solvers and the last solution.
struct Solvers {
    solution: QpSolution,
    active_set: ActiveSetQp,
    clarabel: ClarabelQp,
}

impl Solvers {
    /// Solves `qp` into `self.solution` with the chosen solver.
    fn solve(&mut self, choice: SolverChoice, qp: &DenseQp) -> SolvedBy {
        let small = qp.vars() <= ACTIVE_SET_MAX_VARS;
        match choice {
            SolverChoice::ActiveSet => {
                self.active_set.solve_into(qp, &mut self.solution);
                SolvedBy::ActiveSet
            }
            SolverChoice::Auto if small => {
                self.active_set.solve_into(qp, &mut self.solution);
                if self.solution.status == QpStatus::Solved {
                    return SolvedBy::ActiveSet;
                }
                self.solution = self.clarabel.solve(qp);
                SolvedBy::Clarabel
            }
            _ => {
                self.solution = self.clarabel.solve(qp);
                SolvedBy::Clarabel
            }
        }
    }
}

impl Workspace {
    fn new(n: usize, m: usize) -> Self {
        Workspace {
            program: Program::with_state_len(n),
            qp: DenseQp {
                p_diag: Vec::new(),
                c: Vec::new(),
                g: Vec::new(),
                h: Vec::new(),
            },
            solvers: Solvers {
                solution: QpSolution {
                    status: QpStatus::Failed,
                    x: Vec::new(),
                    z: Vec::new(),
                    iterations: 0,
                },
                active_set: ActiveSetQp::new(),
                clarabel: ClarabelQp::new(),
            },
            out: Filtered::new(m),
            grad: gradient::Buffers::default(),
        }
    }
}

/// Per-call dynamics `f(s)` (length n) and `g(s)` (n x m, row-major), overriding the model,
/// and the drift's Jacobian `J_f(s)` (n x n, row-major) that second-order rows need. Without
/// `jacobian` a built-in model's own Jacobian is used; a [`CustomModel`] shield with
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
}

/// Per-row dynamics of a batch (a [`CustomModel`] shield's, or a shield without a model):
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
    fn row(&self, i: usize, n: usize, m: usize) -> ControlAffine<'a> {
        ControlAffine {
            f: &self.f[i * n..(i + 1) * n],
            g: &self.g[i * n * m..(i + 1) * n * m],
            jacobian: self.jacobian.map(|j| &j[i * n * n..(i + 1) * n * n]),
        }
    }
}

/// Results of [`Shield::filter_batch`], one row per state (`m` values per row where the
/// quantity is a vector).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BatchOutput {
    /// Applied actions, `(B, m)` row-major.
    pub action: Vec<f64>,
    /// Safety corrections, `(B, m)`.
    pub a_cbf: Vec<f64>,
    /// Task corrections, `(B, m)`.
    pub a_clf: Vec<f64>,
    /// CLF relaxations, `(B,)`.
    pub delta: Vec<f64>,
    /// [`Status`] codes, `(B,)`.
    pub status: Vec<u8>,
    /// Largest barrier slack, `(B,)`.
    pub slack: Vec<f64>,
    /// [`SolvedBy`] codes, `(B,)`.
    pub solver: Vec<u8>,
}

impl BatchOutput {
    /// Sizes every column for `rows` rows of `m` inputs (reusing the buffers); a size that
    /// cannot be allocated is [`InputError::TooLarge`].
    fn resize(&mut self, rows: usize, m: usize) -> Result<(), InputError> {
        let len = crate::alloc::checked_len("a_rl", &[rows, m])?;
        for column in [&mut self.action, &mut self.a_cbf, &mut self.a_clf] {
            crate::alloc::try_resize(column, "a_rl", len, 0.0)?;
        }
        crate::alloc::try_resize(&mut self.delta, "rows", rows, 0.0)?;
        crate::alloc::try_resize(&mut self.slack, "rows", rows, 0.0)?;
        crate::alloc::try_resize(&mut self.status, "rows", rows, 0)?;
        crate::alloc::try_resize(&mut self.solver, "rows", rows, 0)
    }

    /// Views of consecutive runs of `chunk` rows (the last may be shorter), one per worker.
    fn rows_mut(&mut self, chunk: usize, m: usize) -> impl Iterator<Item = OutRows<'_>> {
        self.action
            .chunks_mut(chunk * m)
            .zip(self.a_cbf.chunks_mut(chunk * m))
            .zip(self.a_clf.chunks_mut(chunk * m))
            .zip(self.delta.chunks_mut(chunk))
            .zip(self.status.chunks_mut(chunk))
            .zip(self.slack.chunks_mut(chunk))
            .zip(self.solver.chunks_mut(chunk))
            .map(
                |((((((action, a_cbf), a_clf), delta), status), slack), solver)| OutRows {
                    action,
                    a_cbf,
                    a_clf,
                    delta,
                    status,
                    slack,
                    solver,
                },
            )
    }
}

/// A run of consecutive rows of a [`BatchOutput`], written by one worker.
struct OutRows<'a> {
    action: &'a mut [f64],
    a_cbf: &'a mut [f64],
    a_clf: &'a mut [f64],
    delta: &'a mut [f64],
    status: &'a mut [u8],
    slack: &'a mut [f64],
    solver: &'a mut [u8],
}

impl OutRows<'_> {
    /// Row `i` of this run from one step's result.
    fn write(&mut self, i: usize, m: usize, out: &Filtered) {
        let cols = i * m..(i + 1) * m;
        self.action[cols.clone()].copy_from_slice(&out.action);
        self.a_cbf[cols.clone()].copy_from_slice(&out.a_cbf);
        self.a_clf[cols].copy_from_slice(&out.a_clf);
        self.delta[i] = out.delta;
        self.status[i] = out.status as u8;
        self.slack[i] = out.slack;
        self.solver[i] = out.solver as u8;
    }
}

/// The TL-CLF-CBF shield of one task automaton and one dynamics model.
pub struct Shield {
    automaton: Arc<Automaton>,
    dynamics: Option<Dynamics>,
    /// A user's model, whose values come with every call (then `dynamics` is `None`).
    custom: Option<CustomModel>,
    params: ShieldParams,
    /// Which rows are second order (HOCBF) under the model.
    orders: Orders,
    m: usize,
    /// Smallest state length every part can read.
    min_dim: usize,
    /// One workspace per concurrent caller, reused (no allocation in steady state).
    pool: Slots<Workspace>,
}

impl std::fmt::Debug for Shield {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shield")
            .field("dynamics", &self.dynamics)
            .field("custom", &self.custom)
            .field("params", &self.params)
            .field("inputs", &self.m)
            .finish()
    }
}

fn positive(what: &str, value: f64) -> Result<(), ShieldError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ShieldError::Config(format!(
            "{what} = {value}: expected a finite number > 0"
        )))
    }
}

/// Checks that applying no action stays feasible for every RL action in `rl`: the CBF box must
/// be able to cancel it (`cbf ⊇ -rl`, for steps without a goal, where `a_clf` is absent), and
/// with the CLF on, `cbf + clf ⊇ -rl` (only binding when the CLF box excludes 0), and actuator
/// limits must allow 0. Without that authority the barrier rows can become infeasible, and the
/// relaxed answer breaks them. (For the driftless models, unicycle and single integrator,
/// applying nothing keeps every barrier where it is; the CBF row then holds for any h >= margin.)
fn check_cover(params: &ShieldParams, rl: &Bounds) -> Result<(), ShieldError> {
    let (cbf, clf) = (&params.cbf_bounds, &params.clf_bounds);
    for j in 0..rl.lo.len() {
        let (need_lo, need_hi) = (-rl.hi[j], -rl.lo[j]);
        if cbf.lo[j] > need_lo || cbf.hi[j] < need_hi {
            return Err(ShieldError::Config(format!(
                "cbf_bounds[{j}] = ({}, {}) cannot cancel every RL action: rl_bounds[{j}] = \
                 ({}, {}), so the CBF box must contain ({need_lo}, {need_hi}) for the barriers \
                 to stay feasible",
                cbf.lo[j], cbf.hi[j], rl.lo[j], rl.hi[j]
            )));
        }
        let (sum_lo, sum_hi) = (cbf.lo[j] + clf.lo[j], cbf.hi[j] + clf.hi[j]);
        if params.use_clf && (sum_lo > need_lo || sum_hi < need_hi) {
            return Err(ShieldError::Config(format!(
                "cbf_bounds[{j}] = ({}, {}) plus clf_bounds[{j}] = ({}, {}) reach ({sum_lo}, \
                 {sum_hi}), which cannot cancel every RL action in rl_bounds[{j}] = ({}, {}): \
                 widen cbf_bounds or let the CLF box contain 0",
                cbf.lo[j], cbf.hi[j], clf.lo[j], clf.hi[j], rl.lo[j], rl.hi[j]
            )));
        }
        if let Some(act) = &params.action_bounds {
            if act.lo[j] > 0.0 || act.hi[j] < 0.0 {
                return Err(ShieldError::Config(format!(
                    "action_bounds[{j}] = ({}, {}) exclude 0: the shield needs to be able to \
                     apply no action",
                    act.lo[j], act.hi[j]
                )));
            }
        }
    }
    Ok(())
}

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

/// Checks a drift of `rows` rows of length `n`.
fn check_drift(d: &[f64], n: usize, rows: usize) -> Result<(), ShieldError> {
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
    /// A shield for `automaton`'s task. `dynamics` may be `None` when every call passes
    /// `f` and `g`; the number of inputs m then comes from the bounds, and every row is first
    /// order (a call whose `g` cannot move what a barrier reads is an error).
    pub fn new(
        automaton: Arc<Automaton>,
        dynamics: Option<Dynamics>,
        params: ShieldParams,
    ) -> Result<Self, ShieldError> {
        Self::build(automaton, dynamics, None, params)
    }

    /// A shield for `automaton`'s task under a user's model, whose `f`, `g` (and, where a row
    /// is second order, `J_f`) come with every call. Each barrier's relative degree comes from
    /// the model's structure, as under a built-in model.
    pub fn with_custom_model(
        automaton: Arc<Automaton>,
        model: CustomModel,
        params: ShieldParams,
    ) -> Result<Self, ShieldError> {
        Self::build(automaton, None, Some(model), params)
    }

    fn build(
        automaton: Arc<Automaton>,
        dynamics: Option<Dynamics>,
        custom: Option<CustomModel>,
        params: ShieldParams,
    ) -> Result<Self, ShieldError> {
        positive("alpha", params.alpha)?;
        if let Some(a2) = params.alpha2 {
            positive("alpha2", a2)?;
        }
        positive("clf_gain", params.clf_gain)?;
        positive("c3", params.c3)?;
        positive("k", params.k)?;
        positive("slack_penalty", params.slack_penalty)?;
        if !(params.margin.is_finite() && params.margin > 0.0) {
            return Err(ShieldError::Config(format!(
                "margin = {}: expected a finite number > 0 (an atom holds only while its \
                 robustness is > 0, so barriers held at h >= 0 would let a state settle at \
                 h = 0, or just below it after a discrete step, where the task counts it \
                 violated)",
                params.margin
            )));
        }
        for (i, &(d, w)) in params.disturbance.iter().enumerate() {
            if !(w.is_finite() && w >= 0.0) {
                return Err(ShieldError::Config(format!(
                    "disturbance bound of dimension {d} = {w}: expected a finite number >= 0"
                )));
            }
            if params.disturbance[..i].iter().any(|&(e, _)| e == d) {
                return Err(ShieldError::Config(format!(
                    "disturbance: dimension {d} is given twice"
                )));
            }
        }
        for b in &params.barriers {
            positive(
                &format!("slack weight of barrier {:?}", b.name),
                b.slack_weight,
            )?;
        }
        let m = match (&dynamics, &custom) {
            (Some(d), _) => d.inputs(),
            (None, Some(c)) => c.inputs(),
            (None, None) => params.cbf_bounds.lo.len(),
        };
        if m == 0 {
            return Err(ShieldError::Config(
                "the system has no inputs (bounds are empty)".into(),
            ));
        }
        params.cbf_bounds.check("cbf_bounds", m)?;
        params.clf_bounds.check("clf_bounds", m)?;
        if let Some(b) = &params.action_bounds {
            b.check("action_bounds", m)?;
        }
        if let Some(rl) = &params.rl_bounds {
            rl.check("rl_bounds", m)?;
            if params.use_cbf {
                check_cover(&params, rl)?;
            }
        }
        if params.pos.is_empty()
            || (1..params.pos.len()).any(|i| params.pos[..i].contains(&params.pos[i]))
        {
            return Err(ShieldError::Config(format!(
                "pos = {:?}: expected at least one distinct state dimension",
                params.pos
            )));
        }
        let spec = automaton.spec();
        if !spec.is_bound() {
            return Err(ShieldError::Config(
                "the automaton was built from a formula alone (no predicates): build it from a \
                 Spec with predicates to shield states"
                    .into(),
            ));
        }
        if params.use_clf {
            for (name, p) in spec.atoms().iter().zip(spec.predicates()) {
                for leaf in crate::region::alternatives(p)
                    .into_iter()
                    .flatten()
                    .flatten()
                {
                    if let Predicate::Ball(ball) = leaf {
                        if ball.pos().len() != params.pos.len() {
                            return Err(ShieldError::Config(format!(
                                "pos has {} dimensions but the goal ball {name:?} has {}; the \
                                 CLF drives s[pos] to points inside balls, so they must match",
                                params.pos.len(),
                                ball.pos().len()
                            )));
                        }
                    }
                }
            }
        }
        let mut min_dim = spec
            .predicates()
            .iter()
            .chain(params.barriers.iter().map(|b| &b.predicate))
            .map(Predicate::min_dim)
            .max()
            .unwrap_or(0)
            .max(params.pos.iter().max().map_or(0, |p| p + 1))
            .max(
                params
                    .disturbance
                    .iter()
                    .map(|&(d, _)| d + 1)
                    .max()
                    .unwrap_or(0),
            );
        if let Some(d) = &dynamics {
            min_dim = min_dim.max(d.min_dim());
        }
        if let Some(c) = &custom {
            if min_dim > c.state_len() {
                return Err(ShieldError::Config(format!(
                    "the shield reads {min_dim} state values (barriers, predicates, pos) but \
                     the model {c} has {}",
                    c.state_len()
                )));
            }
            min_dim = c.state_len();
        }
        // Where a predicate fixes the state length, an index past it can never be read: say so
        // here rather than at the first filter call.
        let fixed = spec
            .state_dim()
            .or_else(|| params.barriers.iter().find_map(|b| b.predicate.exact_dim()));
        if let Some(n) = fixed {
            if let Some(&p) = params.pos.iter().find(|&&p| p >= n) {
                return Err(ShieldError::Config(format!(
                    "pos = {:?}: dimension {p} is past the state length {n} that the \
                     predicates fix",
                    params.pos
                )));
            }
            if min_dim > n {
                return Err(ShieldError::Config(format!(
                    "the shield reads {min_dim} state values (model, barriers, disturbance) but the predicates fix \
                     the state length at {n}"
                )));
            }
        }
        let structure: Option<&dyn Structure> = match (&dynamics, &custom) {
            (Some(d), _) => Some(d),
            (None, Some(c)) => Some(c),
            (None, None) => None,
        };
        let orders = Orders::new(&automaton, &params, structure, min_dim)?;
        Ok(Shield {
            automaton,
            dynamics,
            custom,
            params,
            orders,
            m,
            min_dim,
            pool: Slots::default(),
        })
    }

    /// The automaton whose safe sets and goals the shield uses.
    pub fn automaton(&self) -> &Arc<Automaton> {
        &self.automaton
    }

    /// The parameters.
    pub fn params(&self) -> &ShieldParams {
        &self.params
    }

    /// The parameters (the 0.1 name of [`Shield::params`]).
    #[deprecated(since = "0.2.0", note = "renamed `params`")]
    pub fn config(&self) -> &ShieldParams {
        self.params()
    }

    /// Number of inputs m.
    pub fn inputs(&self) -> usize {
        self.m
    }

    /// The dynamics model, if any.
    pub fn dynamics(&self) -> Option<&Dynamics> {
        self.dynamics.as_ref()
    }

    /// Every user barrier's value at `s` (in the order of [`ShieldParams::barriers`]), into
    /// `out`: what an environment's step can be measured by, with no key of its own.
    pub fn barrier_values(&self, s: &[f64], out: &mut Vec<f64>) -> Result<(), ShieldError> {
        self.check_state("s", s)?;
        check_finite("s", s, s.len())?;
        out.clear();
        out.extend(self.params.barriers.iter().map(|b| b.value(s)));
        Ok(())
    }

    /// The user's model, if the shield was built with one.
    pub fn custom_model(&self) -> Option<&CustomModel> {
        self.custom.as_ref()
    }

    fn with_workspace<R>(&self, n: usize, run: impl FnOnce(&mut Workspace) -> R) -> R {
        self.pool.with(|| Workspace::new(n, self.m), run)
    }

    /// Checks the state length, finiteness and the barrier dimensions.
    fn check_state(&self, what: &str, s: &[f64]) -> Result<(), ShieldError> {
        self.check_state_len(what, s.len())
    }

    /// Checks a state length `n` against the spec, the dynamics and the barriers (an empty
    /// batch still says how long its rows are).
    fn check_state_len(&self, what: &str, n: usize) -> Result<(), ShieldError> {
        self.automaton.spec().check_state_len(n)?;
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
    fn check_call(
        &self,
        s: &[f64],
        q: usize,
        a_rl: &[f64],
        fg: Option<ControlAffine<'_>>,
        drift: Option<&[f64]>,
    ) -> Result<(), ShieldError> {
        self.check_state("s", s)?;
        check_finite("s", s, s.len())?;
        self.automaton.check_state("q", q)?;
        self.check_action("a_rl", a_rl)?;
        self.check_dynamics(s.len(), fg)?;
        if let Some(d) = drift {
            check_drift(d, s.len(), 1)?;
        }
        Ok(())
    }

    /// One shield step at state `s` in FSA state `q` for the RL action `a_rl`; `fg`
    /// overrides the dynamics model for this call. `drift` (length n) is added to `f`: the
    /// motion, measured for this step, of state dimensions the agent does not control (moving
    /// obstacles or goals read through `center_dims`), so a barrier on them sees
    /// `dh/dt = grad h . (f + drift + g a)`.
    pub fn filter(
        &self,
        s: &[f64],
        q: usize,
        a_rl: &[f64],
        fg: Option<ControlAffine<'_>>,
        drift: Option<&[f64]>,
    ) -> Result<Filtered, ShieldError> {
        let call = Call {
            s,
            q,
            a_rl,
            fg,
            drift,
            task: None,
        };
        self.checked_step(call, Want::Recorded, |ws| ws.out.clone())
    }

    /// [`Shield::filter`] at the task monitor's last state and FSA state, reusing its reading
    /// of the atoms and its CLF goal: with [`Monitor::advance`], one environment step reads
    /// the atoms once. The monitor must watch this shield's automaton and have started.
    pub fn filter_monitor(
        &self,
        monitor: &Monitor,
        a_rl: &[f64],
        fg: Option<ControlAffine<'_>>,
        drift: Option<&[f64]>,
    ) -> Result<Filtered, ShieldError> {
        self.filter_monitor_with(monitor, a_rl, fg, drift, true, Filtered::clone)
    }

    /// [`Shield::filter_monitor`] handing the answer to `take` in place: nothing is allocated
    /// when `take` copies what it needs (a vector environment's rows). With `record` false the
    /// goal and the barrier list are not filled in (as in a batch).
    pub fn filter_monitor_with<R>(
        &self,
        monitor: &Monitor,
        a_rl: &[f64],
        fg: Option<ControlAffine<'_>>,
        drift: Option<&[f64]>,
        record: bool,
        take: impl FnOnce(&Filtered) -> R,
    ) -> Result<R, ShieldError> {
        if !Arc::ptr_eq(monitor.automaton(), &self.automaton) {
            return Err(ShieldError::Config(
                "monitor: it watches another automaton; build it from this shield's automaton \
                 (shield.automaton)"
                    .into(),
            ));
        }
        if !monitor.started() {
            return Err(AutomatonError::NotReset.into());
        }
        let call = Call {
            s: monitor.state(),
            q: monitor.q(),
            a_rl,
            fg,
            drift,
            task: Some(monitor),
        };
        let want = if record {
            Want::Recorded
        } else {
            Want::Solution
        };
        self.checked_step(call, want, |ws| take(&ws.out))
    }

    /// The QP [`Shield::filter`] would solve at this step (before any relaxation), for
    /// inspection and benchmarks. Variables `[a_cbf | a_clf | d]` (parts that are off are
    /// absent; `d = delta - delta_0`, see the module docs); empty when nothing is corrected.
    pub fn problem(
        &self,
        s: &[f64],
        q: usize,
        a_rl: &[f64],
        fg: Option<ControlAffine<'_>>,
        drift: Option<&[f64]>,
    ) -> Result<DenseQp, ShieldError> {
        let call = Call {
            s,
            q,
            a_rl,
            fg,
            drift,
            task: None,
        };
        self.checked_step(call, Want::Problem, |ws| ws.qp.clone())
    }

    /// Checks one call's input, runs the step it wants and takes its result from the workspace.
    fn checked_step<R>(
        &self,
        c: Call<'_>,
        want: Want,
        take: impl FnOnce(&Workspace) -> R,
    ) -> Result<R, ShieldError> {
        self.check_call(c.s, c.q, c.a_rl, c.fg, c.drift)?;
        Ok(self.with_workspace(c.s.len(), |ws| {
            self.step(ws, c, want);
            take(ws)
        }))
    }

    /// [`Shield::filter`] for a batch: `states` is `(B, n)` row-major, `qs` `(B,)`, `a_rl`
    /// `(B, m)`, `drift` (optional) `(B, n)`. Rows are processed in parallel; the model's
    /// dynamics are used.
    pub fn filter_batch(
        &self,
        states: &[f64],
        n: usize,
        qs: &[usize],
        a_rl: &[f64],
        drift: Option<&[f64]>,
        out: &mut BatchOutput,
    ) -> Result<(), ShieldError> {
        self.filter_batch_with(states, n, qs, a_rl, None, drift, out)
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

    /// [`Shield::filter_batch`] with each row's `f`, `g` (and Jacobian) given: the batch of a
    /// shield built on a [`CustomModel`] or without a model.
    #[allow(clippy::too_many_arguments)]
    pub fn filter_batch_with(
        &self,
        states: &[f64],
        n: usize,
        qs: &[usize],
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
        out: &mut BatchOutput,
    ) -> Result<(), ShieldError> {
        self.check_state_batch(states, n, qs, a_rl, dynamics, drift)?;
        out.resize(qs.len(), self.m)?;
        // One contiguous chunk of rows per worker thread, each with its own workspace; small
        // batches stay on the calling thread (waking the pool costs more than they do).
        self.run_batch(
            BatchRows::States { states, n, qs },
            a_rl,
            dynamics,
            drift,
            out,
        );
        Ok(())
    }

    /// Checks the input of a batch over given states (see [`Shield::filter_batch_with`]).
    fn check_state_batch(
        &self,
        states: &[f64],
        n: usize,
        qs: &[usize],
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
    ) -> Result<(), ShieldError> {
        let rows = qs.len();
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
        self.check_batch_dynamics(rows, n, dynamics)?;
        check_finite("states", states, n)?;
        if let Some(d) = drift {
            check_drift(d, n, rows)?;
        }
        for (i, &q) in qs.iter().enumerate() {
            self.automaton.check_state(&format!("qs[{i}]"), q)?;
        }
        Ok(())
    }

    /// [`Shield::filter_batch`] at the monitors' last states and FSA states, reusing their
    /// readings and goals (with [`MonitorBatch::advance`], a vector environment reads each
    /// row's atoms once per step). `a_rl` is `(B, m)`, `drift` (optional) `(B, n)`.
    pub fn filter_monitors(
        &self,
        batch: &MonitorBatch,
        a_rl: &[f64],
        drift: Option<&[f64]>,
        out: &mut BatchOutput,
    ) -> Result<(), ShieldError> {
        self.filter_monitors_with(batch, a_rl, None, drift, out)
    }

    /// [`Shield::filter_monitors`] with each row's `f`, `g` (and Jacobian) given (see
    /// [`Shield::filter_batch_with`]).
    pub fn filter_monitors_with(
        &self,
        batch: &MonitorBatch,
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
        out: &mut BatchOutput,
    ) -> Result<(), ShieldError> {
        out.resize(batch.monitors().len(), self.m)?;
        if self
            .check_monitor_batch(batch, a_rl, dynamics, drift)?
            .is_some()
        {
            self.run_batch(
                BatchRows::Monitors(batch.monitors()),
                a_rl,
                dynamics,
                drift,
                out,
            );
        }
        Ok(())
    }

    /// Checks the input of a batch over monitors (see [`Shield::filter_monitors_with`]);
    /// returns the state length, `None` for an empty batch.
    fn check_monitor_batch(
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
            return Err(InputError::Value {
                what: format!("monitors row {row}"),
                expected: "a started episode (reset it first)".into(),
                got: "a monitor without one".into(),
            }
            .into());
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
        }
        Ok(Some(n))
    }

    /// The rows of a validated batch: one contiguous chunk of rows per worker thread, each
    /// with its own workspace; small batches stay on the calling thread (waking the pool
    /// costs more than they do).
    fn run_batch(
        &self,
        rows: BatchRows<'_>,
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
        out: &mut BatchOutput,
    ) {
        if rows.len() < PARALLEL_MIN_ROWS {
            self.batch_rows(rows, a_rl, dynamics, drift, out, 1);
        } else {
            crate::parallel::install(|| {
                let threads = rayon::current_num_threads().max(1);
                self.batch_rows(rows, a_rl, dynamics, drift, out, threads);
            });
        }
    }

    /// The rows of a validated batch in `threads` contiguous chunks of rows, each worker with
    /// its own workspace.
    fn batch_rows(
        &self,
        rows: BatchRows<'_>,
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
        out: &mut BatchOutput,
        threads: usize,
    ) {
        let (m, n) = (self.m, rows.state_len());
        let chunk = rows.len().div_ceil(threads).max(1);
        // One output view per chunk, on the stack (no allocation for up to 8 workers).
        let mut parts: SmallVec<[OutRows<'_>; 8]> = out.rows_mut(chunk, m).collect();
        parts.par_iter_mut().enumerate().for_each(|(c, part)| {
            self.with_workspace(n, |ws| {
                for i in 0..part.delta.len() {
                    let row = c * chunk + i;
                    let call = rows.call(row, a_rl, dynamics, drift, m);
                    self.step(ws, call, Want::Solution);
                    part.write(i, m, &ws.out);
                }
            });
        });
    }

    /// The shield step on validated input: `ws.qp` always, and the result in `ws.out` unless
    /// only the problem is wanted.
    fn step(&self, ws: &mut Workspace, call: Call<'_>, want: Want) {
        let a_rl = call.a_rl;
        let record = want == Want::Recorded;
        let cfg = &self.params;
        ws.out.barriers.clear();
        ws.program.rows(
            cfg,
            &self.orders,
            &self.automaton,
            self.dynamics.as_ref(),
            call,
            record.then_some(&mut ws.out.barriers),
        );
        let program = &ws.program;
        let (m, barriers, vars, has_goal) =
            (self.m, program.barriers(), program.vars(), program.has_goal);
        let (cbf_vars, clf_vars) = (program.cbf_vars, program.clf_vars);

        let out = &mut ws.out;
        out.action.copy_from_slice(a_rl);
        out.a_cbf.fill(0.0);
        out.a_clf.fill(0.0);
        out.delta = 0.0;
        out.slack = 0.0;
        out.status = Status::Solved;
        out.solver = SolvedBy::Nothing;
        out.goal = (record && has_goal).then(|| program.goal.clone());
        if vars == 0 {
            ws.qp = DenseQp {
                p_diag: Vec::new(),
                c: Vec::new(),
                g: Vec::new(),
                h: Vec::new(),
            };
            return;
        }

        program.assemble(cfg, a_rl, &mut ws.qp, false);
        if want == Want::Problem {
            return;
        }
        let mut status = Status::Solved;
        let mut by = ws.solvers.solve(cfg.solver, &ws.qp);
        let mut checked = ws.solvers.solution.status == QpStatus::Solved
            && within_tolerance(&ws.qp, &ws.solvers.solution.x);
        if !checked && barriers > 0 {
            status = if ws.solvers.solution.status == QpStatus::Solved {
                Status::Inaccurate
            } else {
                Status::Relaxed
            };
            program.assemble(cfg, a_rl, &mut ws.qp, true);
            by = ws.solvers.solve(cfg.solver, &ws.qp);
            checked = ws.solvers.solution.status == QpStatus::Solved
                && within_tolerance(&ws.qp, &ws.solvers.solution.x);
        }
        let out = &mut ws.out;
        let x = &ws.solvers.solution.x;
        if !checked {
            out.status = Status::Failed;
            return;
        }
        if cfg.use_cbf {
            out.a_cbf.copy_from_slice(&x[..m]);
        }
        if has_goal {
            out.a_clf.copy_from_slice(&x[cbf_vars..cbf_vars + m]);
            out.delta = program.delta_0 + x[cbf_vars + clf_vars].max(0.0);
        }
        if status != Status::Solved {
            out.slack = x[vars..].iter().fold(0.0, |a: f64, &b| a.max(b));
        }
        for (j, action) in out.action.iter_mut().enumerate() {
            *action = a_rl[j] + out.a_cbf[j] + out.a_clf[j];
        }
        out.status = status;
        out.solver = by;
    }
}

/// Where the rows of a batch read their state and FSA state.
#[derive(Clone, Copy)]
enum BatchRows<'a> {
    /// Given: `(B, n)` states row-major and `(B,)` FSA states.
    States {
        states: &'a [f64],
        n: usize,
        qs: &'a [usize],
    },
    /// Each row's task monitor (its last state, FSA state, reading and goal).
    Monitors(&'a [Monitor]),
}

impl<'a> BatchRows<'a> {
    fn len(&self) -> usize {
        match self {
            BatchRows::States { qs, .. } => qs.len(),
            BatchRows::Monitors(monitors) => monitors.len(),
        }
    }

    fn state_len(&self) -> usize {
        match self {
            BatchRows::States { n, .. } => *n,
            BatchRows::Monitors(monitors) => monitors[0].state().len(),
        }
    }

    /// The call of row `i`: its state, FSA state, monitor (if any), RL action, dynamics and
    /// drift.
    fn call(
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
    fn row(&self, i: usize) -> (&'a [f64], usize, Option<&'a Monitor>) {
        match *self {
            BatchRows::States { states, n, qs } => (&states[i * n..(i + 1) * n], qs[i], None),
            BatchRows::Monitors(monitors) => {
                let monitor = &monitors[i];
                (monitor.state(), monitor.q(), Some(monitor))
            }
        }
    }
}

/// The inputs of one single-state call.
#[derive(Clone, Copy)]
struct Call<'a> {
    s: &'a [f64],
    q: usize,
    a_rl: &'a [f64],
    fg: Option<ControlAffine<'a>>,
    drift: Option<&'a [f64]>,
    /// The task monitor whose reading and goal the step reuses (it holds `s` and `q`).
    task: Option<&'a Monitor>,
}

/// What a shield step is asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Want {
    /// The QP only ([`Shield::problem`]).
    Problem,
    /// The corrected action (the batch path: no goal, no barrier list).
    Solution,
    /// The corrected action, the goal and the enforced barriers ([`Shield::filter`]).
    Recorded,
}

impl From<AutomatonError> for ShieldError {
    fn from(err: AutomatonError) -> Self {
        match err {
            AutomatonError::Input(e) => ShieldError::Input(e),
            other => ShieldError::Automaton(other),
        }
    }
}

#[cfg(test)]
mod tests;
