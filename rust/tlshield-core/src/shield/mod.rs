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

use smallvec::SmallVec;

use crate::automaton::Automaton;
use crate::check::{check_finite, check_state_len, StateLen};
use crate::custom::CustomModel;
use crate::dynamics::{Dynamics, Structure};
use crate::error::{AutomatonError, InputError, ShieldError};
use crate::guidance::Routing;
use crate::monitor::{Monitor, MonitorBatch};
use crate::predicate::Predicate;
use crate::qp::{DenseQp, QpStatus};
use crate::slots::Slots;

mod check;
mod give_way;
mod gradient;
mod inputs;
mod layout;
mod order;
mod outcome;
mod params;
mod program;
mod sampled;
mod workspace;
use give_way::GiveWay;
pub use gradient::{
    BatchGradient, GRAD_DEGENERATE, GRAD_FAILED, GRAD_RELAXED, GRAD_ROUTED, GRAD_SINGULAR,
};
pub use inputs::{BatchDynamics, ControlAffine, StateBatch, Want};
use inputs::{BatchRows, Call, Stage};
use order::Orders;
use outcome::OutRows;
pub use outcome::{BarrierSource, BatchOutput, Filtered, ShieldStep, SolvedBy, Status};
pub use params::{Barrier, Bounds, RoundBound, ShieldParams, SolverChoice};
use program::Rules;
use workspace::Workspace;

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
    /// Every rule a state's length must meet (`check.rs`'s `state_rules`); an error for a
    /// spec that cannot evaluate states.
    state_len: Result<Vec<StateLen>, InputError>,
    /// One workspace per concurrent caller, reused (no allocation in steady state).
    pool: Slots<Workspace>,
    /// What the CLF routes around ([`Shield::routing`]), made once.
    routing: Option<Routing>,
    /// Each barrier's place in the declared give-way order.
    give_way: GiveWay,
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
        mut params: ShieldParams,
    ) -> Result<Self, ShieldError> {
        let m = params.input_count(match (&dynamics, &custom) {
            (Some(d), _) => Some(d.inputs()),
            (None, Some(c)) => Some(c.inputs()),
            (None, None) => None,
        })?;
        let structure = structure_of(&dynamics, &custom);
        layout::resolve_pos(&mut params, structure);
        params.broadcast(m)?;
        params.validate(m, automaton.spec())?;
        let spec = automaton.spec();
        let min_dim = min_dim(spec, &params, dynamics.as_ref(), custom.as_ref())?;
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
        // The relative degree first (its message names the order), then the layout.
        let orders = Orders::new(&automaton, &params, structure, min_dim)?;
        if let Some(model) = structure {
            layout::check(spec, &params, model)?;
        }
        let routing = routing_of(&params);
        let give_way = GiveWay::new(&params, spec)?;
        let state_len = check::state_rules(spec, custom.as_ref(), min_dim, &params.barriers);
        Ok(Shield {
            automaton,
            dynamics,
            custom,
            params,
            orders,
            m,
            state_len,
            pool: Slots::default(),
            routing,
            give_way,
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

    /// What this shield's CLF routes around, when it routes ([`ShieldParams::route`] with the
    /// CLF on and a two-dimensional position): for a [`Monitor`] whose goal term should read
    /// the way the shield drives ([`Monitor::route_with`]).
    pub fn routing(&self) -> Option<&Routing> {
        self.routing.as_ref()
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
        check_state_len("s", s.len(), self.state_rules()?)?;
        check_finite("s", s, s.len())?;
        out.clear();
        out.extend(self.params.barriers.iter().map(|b| b.value(s)));
        Ok(())
    }

    /// The user's model, if the shield was built with one.
    pub fn custom_model(&self) -> Option<&CustomModel> {
        self.custom.as_ref()
    }

    /// The model's structure (built-in or the user's), if the shield has a model.
    fn structure(&self) -> Option<&dyn Structure> {
        structure_of(&self.dynamics, &self.custom)
    }

    fn with_workspace<R>(&self, n: usize, run: impl FnOnce(&mut Workspace) -> R) -> R {
        self.pool.with(|| Workspace::new(n, self.m), run)
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
        self.checked_step(call, Stage::Filter(Want::Record), |ws| ws.out.clone())
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
        self.filter_monitor_with(monitor, a_rl, fg, drift, Want::Record, Filtered::clone)
    }

    /// [`Shield::filter_monitor`] handing the answer to `take` in place: nothing is allocated
    /// when `take` copies what it needs (a vector environment's rows). With [`Want::Action`]
    /// the goal and the barrier list are not filled in (as in a batch).
    pub fn filter_monitor_with<R>(
        &self,
        monitor: &Monitor,
        a_rl: &[f64],
        fg: Option<ControlAffine<'_>>,
        drift: Option<&[f64]>,
        want: Want,
        take: impl FnOnce(&Filtered) -> R,
    ) -> Result<R, ShieldError> {
        let call = self.monitor_call(monitor, a_rl, fg, drift)?;
        self.checked_step(call, Stage::Filter(want), |ws| take(&ws.out))
    }

    /// [`Shield::filter_monitor`] for one step of a bundled world (two inputs, the model's
    /// dynamics): the answer in fixed-size fields, and the whole of it with [`Want::Record`]
    /// (one allocation per step).
    pub fn filter_step(
        &self,
        monitor: &Monitor,
        a_rl: [f64; 2],
        drift: Option<&[f64]>,
        want: Want,
    ) -> Result<ShieldStep, ShieldError> {
        let call = self.monitor_call(monitor, &a_rl, None, drift)?;
        self.checked_step(call, Stage::Filter(want), |ws| {
            let f = &ws.out;
            let pair = |v: &[f64]| [v[0], v[1]];
            ShieldStep {
                action: pair(&f.action),
                a_cbf: pair(&f.a_cbf),
                a_clf: pair(&f.a_clf),
                delta: f.delta,
                slack: f.slack,
                status: f.status,
                solver: f.solver,
                gave_way: f.gave_way,
                record: (want == Want::Record).then(|| f.clone()),
            }
        })
    }

    /// The call at a task monitor's last state and FSA state; the monitor must watch this
    /// shield's automaton and have started.
    fn monitor_call<'a>(
        &self,
        monitor: &'a Monitor,
        a_rl: &'a [f64],
        fg: Option<ControlAffine<'a>>,
        drift: Option<&'a [f64]>,
    ) -> Result<Call<'a>, ShieldError> {
        if !Arc::ptr_eq(monitor.automaton(), &self.automaton) {
            return Err(ShieldError::Config(
                "monitor: it watches another automaton; build it from this shield's automaton \
                 (shield.automaton)"
                    .into(),
            ));
        }
        if !monitor.started() {
            return Err(AutomatonError::NotReset { row: None }.into());
        }
        Ok(Call {
            s: monitor.state(),
            q: monitor.q(),
            a_rl,
            fg,
            drift,
            task: Some(monitor),
        })
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
        self.checked_step(call, Stage::Problem, |ws| ws.qp.clone())
    }

    /// Checks one call's input, runs the step it wants and takes its result from the workspace.
    fn checked_step<R>(
        &self,
        c: Call<'_>,
        stage: Stage,
        take: impl FnOnce(&Workspace) -> R,
    ) -> Result<R, ShieldError> {
        self.check_call(&c)?;
        Ok(self.with_workspace(c.s.len(), |ws| {
            self.step(ws, c, stage);
            take(ws)
        }))
    }

    /// [`Shield::filter`] for a batch of `rows`: `a_rl` `(B, m)`, `drift` (optional) `(B, n)`.
    /// Rows are processed in parallel; the model's dynamics are used.
    pub fn filter_batch(
        &self,
        rows: StateBatch<'_>,
        a_rl: &[f64],
        drift: Option<&[f64]>,
        out: &mut BatchOutput,
    ) -> Result<(), ShieldError> {
        self.filter_batch_with(rows, a_rl, None, drift, out)
    }

    /// [`Shield::filter_batch`] with each row's `f`, `g` (and Jacobian) given: the batch of a
    /// shield built on a [`CustomModel`] or without a model.
    pub fn filter_batch_with(
        &self,
        rows: StateBatch<'_>,
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
        out: &mut BatchOutput,
    ) -> Result<(), ShieldError> {
        self.check_state_batch(rows, a_rl, dynamics, drift)?;
        out.resize(rows.len(), self.m)?;
        self.run_batch(BatchRows::States(rows), a_rl, dynamics, drift, out);
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

    /// The rows of a validated batch in contiguous parts, each with its own workspace, claimed
    /// by the calling thread and the pool's ([`crate::parallel::for_each_part`]); small batches
    /// stay on the calling thread (waking the pool costs more than they do).
    fn run_batch(
        &self,
        rows: BatchRows<'_>,
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
        out: &mut BatchOutput,
    ) {
        let (m, n) = (self.m, rows.state_len());
        let chunk = crate::parallel::part_len(rows.len(), PARALLEL_MIN_ROWS);
        // One output view per part, on the stack (no allocation for up to 16 parts).
        let mut parts: SmallVec<[(usize, OutRows<'_>); 16]> =
            out.rows_mut(chunk, m).enumerate().collect();
        crate::parallel::for_each_part(&mut parts, |(c, part)| {
            self.with_workspace(n, |ws| {
                for i in 0..part.delta.len() {
                    let row = *c * chunk + i;
                    let call = rows.call(row, a_rl, dynamics, drift, m);
                    self.step(ws, call, Stage::Filter(Want::Action));
                    part.write(i, m, &ws.out);
                }
            });
        });
    }

    /// Solves the assembled `ws.qp`; when its answer is not a checked solution and there are
    /// barrier rows, the relaxed problem in the declared give-way order: slack on the first
    /// level's rows, then on those and the next level's, until one is solved (`give_way.rs`).
    /// Returns the status, the solver and whether `ws.solvers.solution` passed the check.
    fn solve(&self, ws: &mut Workspace, a_rl: &[f64], relaxable: bool) -> (Status, SolvedBy, bool) {
        let params = &self.params;
        let mut by = ws.solvers.solve(params.solver, &ws.qp);
        let mut checked = ws.solvers.solution.status == QpStatus::Solved
            && within_tolerance(&ws.qp, &ws.solvers.solution.x);
        if checked || !relaxable {
            return (Status::Solved, by, checked);
        }
        let status = if ws.solvers.solution.status == QpStatus::Solved {
            Status::Inaccurate
        } else {
            Status::Relaxed
        };
        let program = &ws.program;
        let mut level = self.give_way.next(program.sources(), None);
        while let Some(l) = level {
            program.assemble(params, a_rl, &mut ws.qp, Some((&self.give_way, l)));
            by = ws.solvers.solve(params.solver, &ws.qp);
            checked = ws.solvers.solution.status == QpStatus::Solved
                && within_tolerance(&ws.qp, &ws.solvers.solution.x);
            level = match checked {
                true => None,
                false => self.give_way.next(program.sources(), Some(l)),
            };
        }
        (status, by, checked)
    }

    /// The shield step on validated input: `ws.qp` always, and the result in `ws.out` unless
    /// only the problem is wanted.
    fn step(&self, ws: &mut Workspace, call: Call<'_>, stage: Stage) {
        let a_rl = call.a_rl;
        ws.program.relin.clear();
        let record = stage == Stage::Filter(Want::Record);
        let params = &self.params;
        ws.out.barriers.clear();
        let rules = Rules {
            params,
            routing: self.routing.as_ref(),
            orders: &self.orders,
            automaton: &self.automaton,
            model: self.dynamics.as_ref(),
        };
        ws.program
            .rows(rules, call, record.then_some(&mut ws.out.barriers));
        let program = &ws.program;
        let (vars, has_goal) = (program.vars(), program.has_goal);

        let out = &mut ws.out;
        out.action.copy_from_slice(a_rl);
        out.a_cbf.fill(0.0);
        out.a_clf.fill(0.0);
        out.delta = 0.0;
        out.slack = 0.0;
        out.gave_way = None;
        out.status = Status::Solved;
        out.solver = SolvedBy::Nothing;
        out.goal = (record && has_goal).then(|| program.aim.target.clone());
        out.goal_unreachable = has_goal && program.aim.goal_unreachable();
        if vars == 0 {
            ws.qp = DenseQp {
                p_diag: Vec::new(),
                c: Vec::new(),
                g: Vec::new(),
                h: Vec::new(),
            };
            return;
        }

        program.assemble(params, a_rl, &mut ws.qp, None);
        // A model that bends the step: its second-order sampled rows, first linearised at
        // a = 0, are linearised again at the action found until it settles (`sampled.rs`);
        // the problem asked for is the last one assembled, unrelaxed.
        let model = self.dynamics.as_ref().filter(|m| m.bends_step());
        let model = model.filter(|_| ws.program.bent.contains(&true));
        if stage == Stage::Problem && model.is_none() {
            return;
        }
        self.solve_and_report(ws, a_rl);
        let Some(model) = model else {
            return;
        };
        self.relinearise_until_settled(ws, call, model);
        if stage == Stage::Problem {
            ws.program.assemble(params, a_rl, &mut ws.qp, None);
        }
    }

    /// The passes of [`Shield::step`] that linearise the bent rows again at the last action
    /// found, while the QP solves, until the action settles.
    fn relinearise_until_settled(&self, ws: &mut Workspace, call: Call<'_>, model: &Dynamics) {
        let (params, a_rl) = (&self.params, call.a_rl);
        let predicates = self.automaton.spec().predicates();
        let mut a0 = [0.0; 16];
        for _ in 0..RELINEARISE {
            if ws.out.status != Status::Solved {
                return;
            }
            a0[..self.m].copy_from_slice(&ws.out.action);
            let at = (call.s, a_rl, &a0[..self.m]);
            ws.program
                .relinearise((params, predicates), (model, call.drift), at);
            ws.program.assemble(params, a_rl, &mut ws.qp, None);
            self.solve_and_report(ws, a_rl);
            let settled = ws
                .out
                .action
                .iter()
                .zip(&a0)
                .all(|(a, b)| (a - b).abs() <= SETTLED * (1.0 + b.abs()));
            if settled {
                return;
            }
        }
    }

    /// Solves the QP assembled in `ws` and writes the step's outcome into `ws.out`.
    fn solve_and_report(&self, ws: &mut Workspace, a_rl: &[f64]) {
        let params = &self.params;
        let (m, barriers, vars, has_goal) = {
            let p = &ws.program;
            (self.m, p.barriers(), p.vars(), p.has_goal)
        };
        let (cbf_vars, clf_vars) = (ws.program.cbf_vars, ws.program.clf_vars);
        let (status, by, checked) = self.solve(ws, a_rl, barriers > 0);
        let program = &ws.program;
        let out = &mut ws.out;
        let x = &ws.solvers.solution.x;
        if !checked {
            out.status = Status::Failed;
            return;
        }
        if params.use_cbf {
            out.a_cbf.copy_from_slice(&x[..m]);
        }
        if has_goal {
            out.a_clf.copy_from_slice(&x[cbf_vars..cbf_vars + m]);
            out.delta = program.delta_0 + x[cbf_vars + clf_vars].max(0.0);
        }
        if status != Status::Solved {
            // The row that took the most slack gave way; the largest slack is its.
            out.gave_way = x[vars..]
                .iter()
                .enumerate()
                .filter(|&(_, &sigma)| sigma > 0.0)
                .max_by(|a, b| a.1.total_cmp(b.1))
                .map(|(row, &sigma)| (program.source(row), sigma));
            out.slack = out.gave_way.map_or(0.0, |(_, sigma)| sigma);
        }
        for (j, action) in out.action.iter_mut().enumerate() {
            *action = a_rl[j] + out.a_cbf[j] + out.a_clf[j];
        }
        out.status = status;
        out.solver = by;
    }
}

/// The most passes that linearise the bent rows again at the last pass's action (each
/// shrinks the change by the rows' curvature times the correction, a few hundredths).
const RELINEARISE: usize = 12;
/// The action has settled when no input moves more than this, relative to `1 + |a_j|`: far
/// below what a central difference of the action reads, so that its gradient (a fixed point's,
/// `gradient.rs`) is that of the action returned.
const SETTLED: f64 = 1e-13;

/// The smallest state length every part of a shield reads: the predicates, the barriers,
/// `pos`, the heading, the disturbance bounds and the model (a user's model fixes it, and
/// must cover what the rest reads).
fn min_dim(
    spec: &crate::spec::Spec,
    params: &ShieldParams,
    dynamics: Option<&Dynamics>,
    custom: Option<&CustomModel>,
) -> Result<usize, ShieldError> {
    let read = spec
        .predicates()
        .iter()
        .chain(params.barriers.iter().map(|b| &b.predicate))
        .map(Predicate::min_dim)
        .max()
        .unwrap_or(0)
        .max(params.pos.iter().max().map_or(0, |p| p + 1))
        .max(params.heading.map_or(0, |h| h + 1))
        .max(params.speed.map_or(0, |v| v + 1))
        .max(
            params
                .disturbance
                .iter()
                .map(|&(d, _)| d + 1)
                .max()
                .unwrap_or(0),
        )
        .max(dynamics.map_or(0, Dynamics::min_dim));
    match custom {
        Some(c) if read > c.state_len() => Err(ShieldError::Config(format!(
            "the shield reads {read} state values (barriers, predicates, pos) but the model {c} \
             has {}",
            c.state_len()
        ))),
        Some(c) => Ok(c.state_len()),
        None => Ok(read),
    }
}

/// The structure of a shield's model: the built-in one, else the user's, if any.
fn structure_of<'a>(
    dynamics: &'a Option<Dynamics>,
    custom: &'a Option<CustomModel>,
) -> Option<&'a dyn Structure> {
    match (dynamics, custom) {
        (Some(d), _) => Some(d),
        (None, Some(c)) => Some(c),
        (None, None) => None,
    }
}

/// What a shield with `params` routes around (see [`Shield::routing`]).
fn routing_of(p: &ShieldParams) -> Option<Routing> {
    (p.route && p.use_clf && p.pos.len() == 2).then(|| Routing {
        pos: [p.pos[0], p.pos[1]],
        clearance: p.route_clearance,
        avoid: p
            .barriers
            .iter()
            .filter(|b| !b.positive)
            .map(|b| b.predicate.clone())
            .collect(),
        inside: p
            .barriers
            .iter()
            .filter(|b| b.positive)
            .map(|b| b.predicate.clone())
            .collect(),
        preserve_progress: p.preserve_progress,
    })
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
