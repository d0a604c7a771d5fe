//! Gradients through the shield: vector-Jacobian products of the safe action
//! `a = a_rl + a_cbf + a_clf` with respect to `a_rl` and to the state, for a batch.
//!
//! Each row is solved as [`Shield::filter_batch`] solves it; then the QP's adjoint
//! ([`crate::sensitivity`]) gives `dL/dh` and `dL/dG` on the active rows, and the chain rule runs
//! back through the rows of Eq. 5D2 (`program.rs`):
//! - `a_rl` enters every barrier row's and the CLF row's right-hand side through `Lg . a_rl`,
//!   the actuator-limit rows through `limit - a_rl`, and the action directly;
//! - the state enters a first-order barrier row through `h`, `grad h`, `f` and `g`
//!   (`d(Lf h)/ds = H f + J_f' grad h`, `d(Lg h)/ds = H g + (dg/ds)' grad h`, `H` the barrier's
//!   Hessian), and the first-order CLF row through `V`, `Lf V` and `Lg V` likewise.
//!
//! State gradients of second-order (HOCBF) rows would need third derivatives of the barriers
//! and second derivatives of the drift; a shield with such rows refuses them with an error
//! (the gradient with respect to `a_rl` is available for every shield).
//!
//! What each row's flags mean ([`GRAD_RELAXED`], [`GRAD_FAILED`], [`GRAD_DEGENERATE`],
//! [`GRAD_SINGULAR`], [`GRAD_ROUTED`]): the gradient is always that of the action actually returned. A relaxed
//! step is differentiated as the relaxed QP it solved; a failed step returned `a_rl`, whose
//! gradient is the identity. At a point where the active set changes, the one-sided derivative
//! of the piece on which every tight row stays tight (see `sensitivity.rs`).

use smallvec::SmallVec;

use super::program::row_barrier;
use super::{BatchDynamics, BatchRows, Shield, Stage, StateBatch, Status, Want, Workspace};
use crate::check::check_finite;
use crate::error::{InputError, ShieldError};
use crate::guidance::GoalChoice;
use crate::linalg::dot;
use crate::predicate::{Center, Predicate};
use crate::sensitivity::{QpAdjointSolver, Singular};

/// The central difference's step over the point the bent rows are linearised at, relative to
/// `1 + |a0_j|` ([`Shield::bent_jacobian`]): its error is the step squared times the third
/// derivative, far below the QP's own tolerance.
const BENT_STEP: f64 = 1e-5;
/// The fixed point of a relinearised step's adjoint ([`Shield::settled_cotangent`]) is reached
/// when no component moves more than this, relative to `1 + |v|`; it contracts by the rows'
/// curvature times the correction each pass, a few hundredths.
const ADJOINT_SETTLED: f64 = 1e-14;
/// The most passes of that fixed point.
const ADJOINT_PASSES: usize = 60;

/// Flag: the step was relaxed (slacks on the barrier rows); the gradient is the relaxed QP's.
pub const GRAD_RELAXED: u8 = 1;
/// Flag: the step failed and returned `a_rl`; the gradient is the identity.
pub const GRAD_FAILED: u8 = 2;
/// Flag: the active set changes here; the gradient is one-sided (see the module docs).
pub const GRAD_DEGENERATE: u8 = 4;
/// Flag: routing changed the CLF row (a target around an obstacle, progress into one
/// uncredited, or the RL action's turn into one released to the CLF's box; see
/// `crate::guidance`). `dL/da_rl` is exact; `dL/ds` holds the target, the uncredited direction
/// and the released inputs fixed, leaving out how the route moves with the state.
pub const GRAD_ROUTED: u8 = 16;
/// Flag: the KKT system on the active rows was singular; only the identity part of the
/// gradient (`da/da_rl` through `a_rl` itself) is returned.
pub const GRAD_SINGULAR: u8 = 8;

/// Gradients of a batch. From [`Shield::vjp_batch`]: `a_rl` `(B, m)`, `states` `(B, n)`
/// (empty when not asked for). From [`Shield::jacobian_batch`]: the Jacobians, `a_rl`
/// `(B, m, m)` with `[b, k, j] = da_k / da_rl_j` and `states` `(B, m, n)`, and the actions
/// `(B, m)`. A flag byte per row (`GRAD_*`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BatchGradient {
    /// `dL/da_rl` `(B, m)`, or the Jacobian `(B, m, m)`; row-major.
    pub a_rl: Vec<f64>,
    /// `dL/ds` `(B, n)`, or the Jacobian `(B, m, n)`; row-major; empty when not asked for.
    pub states: Vec<f64>,
    /// The shielded actions `(B, m)` ([`Shield::jacobian_batch`] only; empty otherwise).
    pub action: Vec<f64>,
    /// Per row, an OR of `GRAD_*` flags (0: an exact two-sided gradient of a solved step).
    pub flags: Vec<u8>,
}

impl BatchGradient {
    fn resize(
        &mut self,
        rows: usize,
        k: usize,
        m: usize,
        n: usize,
        action: bool,
    ) -> Result<(), InputError> {
        crate::alloc::try_resize(&mut self.a_rl, "rows", rows * k * m, 0.0)?;
        crate::alloc::try_resize(&mut self.states, "rows", rows * k * n, 0.0)?;
        crate::alloc::try_resize(
            &mut self.action,
            "rows",
            if action { rows * m } else { 0 },
            0.0,
        )?;
        crate::alloc::try_resize(&mut self.flags, "rows", rows, 0)
    }
}

/// The upstream gradients of each row.
#[derive(Clone, Copy)]
enum Cotangents<'a> {
    /// One per row, `(B, m)` row-major (a vector-Jacobian product).
    Given(&'a [f64]),
    /// The unit vectors `e_1 .. e_m` (the Jacobian's rows).
    Identity,
}

impl<'a> Cotangents<'a> {
    fn count(self, m: usize) -> usize {
        match self {
            Cotangents::Given(_) => 1,
            Cotangents::Identity => m,
        }
    }

    /// Upstream gradient `j` of row `row`, in `buf` when it has to be made.
    fn get<'b>(self, row: usize, j: usize, m: usize, buf: &'b mut [f64; 16]) -> &'b [f64]
    where
        'a: 'b,
    {
        match self {
            Cotangents::Given(v) => &v[row * m..(row + 1) * m],
            Cotangents::Identity => {
                buf[..m].fill(0.0);
                buf[j] = 1.0;
                &buf[..m]
            }
        }
    }
}

/// Buffers of one workspace's gradient pass (they only grow).
#[derive(Debug, Default)]
pub(super) struct Buffers {
    adjoint: QpAdjointSolver,
    dx: Vec<f64>,
    dh: Vec<f64>,
    dg: Vec<f64>,
    /// The barrier's gradient, the vector its Hessian multiplies and the products (n each).
    grad: Vec<f64>,
    u: Vec<f64>,
    hu: Vec<f64>,
    tmp: Vec<f64>,
    /// `dL/d(Lg h)` of one row (m).
    beta: Vec<f64>,
    /// `dL/de` of the CLF error (one per `pos`), the centre dimensions, a shifted state and
    /// the goals at `s +- step`.
    de: Vec<f64>,
    centres: Vec<usize>,
    /// The CLF goal's Jacobian over `centres` (goal length x centres), per row.
    goal_jac: Vec<f64>,
    shifted: Vec<f64>,
    plus: Vec<f64>,
    minus: Vec<f64>,
    /// Where an alternative passed over as empty is placed again (it must stay empty).
    spare: Vec<f64>,
    /// A sampled row's predicted sample `y = s + dt f(s)` (`sampled.rs`).
    ahead: Vec<f64>,
    /// Per bent row, `dL/da0` (m x m, column by column; [`Shield::bent_jacobian`]).
    bent_jac: Vec<f64>,
}

/// Adds to `gs` the state gradient of a sampled first-order row (`sampled.rs`) weighted by the
/// adjoint of its right-hand side, `alpha`, and of its `L`, `b.beta`: the row reads
/// `r = (~h(y) - (1 - alpha dt) ~h(s)) / dt` and `L_j = grad ~h(y) . g_j(s)` at
/// `y = s + dt f(s)`, so `dy/ds = I + dt J_f(s)` (the drift is constant).
#[allow(clippy::too_many_arguments)]
fn sampled_row_state_gradient(
    predicate: &Predicate,
    sign: f64,
    s: &[f64],
    dt: f64,
    alpha: f64,
    params: &super::ShieldParams,
    program: &super::program::Program,
    model: &crate::dynamics::Dynamics,
    b: &mut Buffers,
    gs: &mut [f64],
) {
    let (n, m) = (s.len(), b.beta.len());
    b.ahead.resize(n, 0.0);
    for ((y, &si), &fi) in b.ahead.iter_mut().zip(s).zip(&program.f) {
        *y = si + dt * fi;
    }
    predicate.gradient_into(&b.ahead, &mut b.grad);
    b.grad.iter_mut().for_each(|g| *g *= sign);
    // u = sum_j beta_j g_j(s) - alpha sum_d w_d sgn(c_d) e_d, c = grad ~h(y); then H(y) u.
    for k in 0..n {
        b.u[k] = dot(&program.g[k * m..(k + 1) * m], &b.beta);
    }
    for &(d, w) in &params.disturbance {
        b.u[d] -= alpha * w * b.grad[d].signum() * f64::from(b.grad[d] != 0.0);
    }
    predicate.hessian_times(&b.ahead, &b.u, &mut b.hu);
    // t = alpha grad ~h(y) / dt + H(y) u, carried back through dy/ds = I + dt J_f(s).
    for ((t, &g), &hu) in b.u.iter_mut().zip(&b.grad).zip(&b.hu) {
        *t = alpha * g / dt + sign * hu;
    }
    model.jacobian_f_transpose_times(s, &b.u, &mut b.tmp);
    for ((g, &t), &jt) in gs.iter_mut().zip(&b.u).zip(&b.tmp) {
        *g += t + dt * jt;
    }
    // - alpha (1 - alpha_cbf dt) grad ~h(s) / dt.
    predicate.gradient_into(s, &mut b.tmp);
    let w = alpha * (1.0 - params.alpha * dt) / dt * sign;
    gs.iter_mut().zip(&b.tmp).for_each(|(g, &t)| *g -= w * t);
    model.input_jacobian_contract(s, &b.grad, &b.beta, &mut b.tmp);
    gs.iter_mut().zip(&b.tmp).for_each(|(g, t)| *g += t);
}

/// Appends the state dimensions any ball in `p` reads its centre from.
fn centre_dims(p: &Predicate, out: &mut Vec<usize>) {
    match p {
        Predicate::Ball(b) => {
            if let Center::Dims(d) = b.center() {
                out.extend(
                    d.iter()
                        .filter(|d| !out.contains(d))
                        .copied()
                        .collect::<SmallVec<[usize; 4]>>(),
                );
            }
        }
        Predicate::Halfspace(_) => {}
        _ => p.parts().iter().for_each(|q| centre_dims(q, out)),
    }
}

/// One chunk of a gradient batch: its index, `dL/da_rl` rows, flags, actions and `dL/ds` rows.
type Part<'a> = (
    usize,
    &'a mut [f64],
    &'a mut [u8],
    Option<&'a mut [f64]>,
    Option<&'a mut [f64]>,
);

/// Gradient batches smaller than this run on the calling thread. Higher than
/// [`super::PARALLEL_MIN_ROWS`]: a layer's caller does other work between calls, so the pool's
/// threads are asleep when a batch arrives, and waking them costs more than a small batch's
/// work; through `ShieldLayer` (forward and backward) the parallel pass stops losing to the
/// serial one at about 128 rows (docs/benchmarks.md has the measurement).
pub const GRADIENT_PARALLEL_MIN_ROWS: usize = 128;

/// Relative step of the central differences of a moving goal.
const GOAL_STEP: f64 = 1e-6;
/// What rounding may add to two scores' difference when a lead is compared with their steps.
const LEAD_ROUNDING: f64 = 1e-9;

/// One column of the goal's Jacobian from its central difference (`plus`, `minus` at +-h;
/// written at `column[k * stride]`); true when the goal changes its choice within the step.
fn goal_column(
    goal: &[f64],
    plus: &[f64],
    minus: &[f64],
    h: f64,
    column: &mut [f64],
    stride: usize,
) -> bool {
    let mut kink = false;
    for (k, &x) in goal.iter().enumerate() {
        let (p, mm) = (plus[k], minus[k]);
        // A switch of goal within the step shows as a curvature far above rounding.
        if (p - 2.0 * x + mm).abs() > 1e-4 * h.max((p - mm).abs()) {
            kink = true;
        }
        column[k * stride] = (p - mm) / (2.0 * h);
    }
    kink
}

impl Shield {
    /// Why this shield cannot give state gradients, if it cannot.
    fn state_gradient_refusal(&self, custom_rows: bool) -> Option<String> {
        if self.dynamics.is_none() || custom_rows {
            return Some(
                "state gradients need a built-in dynamics model (f and g given per call have \
                 no derivatives); ask for the gradient with respect to a_rl only"
                    .into(),
            );
        }
        if self.orders.second_order() {
            return Some(
                "state gradients are not available for second-order (HOCBF) rows or the \
                 second-order CLF: they need third derivatives of the barriers; ask for the \
                 gradient with respect to a_rl only"
                    .into(),
            );
        }
        None
    }

    /// Vector-Jacobian products of [`Shield::filter_batch`]: for the rows `(states, qs, a_rl)`
    /// and `grad_action = dL/da` `(B, m)`, writes `dL/da_rl` and, with `want_states`,
    /// `dL/ds` into `out`, with a flag byte per row. `dynamics` as in
    /// [`Shield::filter_batch_with`] (then only `a_rl` gradients). Parallel over rows.
    #[allow(clippy::too_many_arguments)]
    pub fn vjp_batch(
        &self,
        rows: StateBatch<'_>,
        a_rl: &[f64],
        grad_action: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
        want_states: bool,
        out: &mut BatchGradient,
    ) -> Result<(), ShieldError> {
        self.check_state_batch(rows, a_rl, dynamics, drift)?;
        self.check_gradient(
            Some(grad_action),
            rows.len(),
            want_states,
            dynamics.is_some(),
        )?;
        let sn = if want_states { rows.n } else { 0 };
        out.resize(rows.len(), 1, self.m, sn, false)?;
        let rows = BatchRows::States(rows);
        let cotangents = Cotangents::Given(grad_action);
        self.gradient_rows(rows, a_rl, cotangents, dynamics, drift, out);
        Ok(())
    }

    /// The shielded actions of [`Shield::filter_batch`] and their Jacobians in one pass (one QP
    /// solve and one factorisation per row): `out.action` `(B, m)`, `out.a_rl` `(B, m, m)` and,
    /// with `want_states`, `out.states` `(B, m, n)`; `[b, k, .]` is the gradient of action
    /// component `k`. A layer's backward pass is then a product with the upstream gradient.
    pub fn jacobian_batch(
        &self,
        rows: StateBatch<'_>,
        a_rl: &[f64],
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
        want_states: bool,
        out: &mut BatchGradient,
    ) -> Result<(), ShieldError> {
        self.check_state_batch(rows, a_rl, dynamics, drift)?;
        self.check_gradient(None, rows.len(), want_states, dynamics.is_some())?;
        let m = self.m;
        let sn = if want_states { rows.n } else { 0 };
        out.resize(rows.len(), m, m, sn, true)?;
        let rows = BatchRows::States(rows);
        self.gradient_rows(rows, a_rl, Cotangents::Identity, dynamics, drift, out);
        Ok(())
    }

    fn check_gradient(
        &self,
        grad_action: Option<&[f64]>,
        rows: usize,
        want_states: bool,
        custom_rows: bool,
    ) -> Result<(), ShieldError> {
        if self.m > 16 {
            return Err(ShieldError::Config(format!(
                "gradients: at most 16 inputs are supported, the shield has {}",
                self.m
            )));
        }
        let Some(grad_action) = grad_action else {
            return self.check_state_gradient(want_states, custom_rows);
        };
        if grad_action.len() != rows * self.m {
            return Err(InputError::Shape {
                what: "grad_action".into(),
                expected: format!("({rows}, {})", self.m),
                got: format!("{} values", grad_action.len()),
            }
            .into());
        }
        check_finite("grad_action", grad_action, self.m)?;
        self.check_state_gradient(want_states, custom_rows)
    }

    fn check_state_gradient(
        &self,
        want_states: bool,
        custom_rows: bool,
    ) -> Result<(), ShieldError> {
        match want_states.then(|| self.state_gradient_refusal(custom_rows)) {
            Some(Some(why)) => Err(ShieldError::Config(why)),
            _ => Ok(()),
        }
    }

    /// The rows of a validated gradient batch, in parallel chunks as [`Shield::filter_batch`]:
    /// per row, its `cotangents.count(m)` upstream gradients through one factorisation.
    fn gradient_rows(
        &self,
        rows: BatchRows<'_>,
        a_rl: &[f64],
        cotangents: Cotangents<'_>,
        dynamics: Option<BatchDynamics<'_>>,
        drift: Option<&[f64]>,
        out: &mut BatchGradient,
    ) {
        let (m, n, len) = (self.m, rows.state_len(), rows.len());
        let k = cotangents.count(m);
        let sn = if out.states.is_empty() { 0 } else { n };
        let with_action = !out.action.is_empty();
        let chunk = crate::parallel::part_len(len, GRADIENT_PARALLEL_MIN_ROWS);
        let actions: SmallVec<[Option<&mut [f64]>; 16]> = match with_action {
            true => out.action.chunks_mut(chunk * m).map(Some).collect(),
            false => SmallVec::new(),
        };
        let states: SmallVec<[Option<&mut [f64]>; 16]> = match sn {
            0 => SmallVec::new(),
            _ => out.states.chunks_mut(chunk * k * sn).map(Some).collect(),
        };
        let mut actions = actions.into_iter();
        let mut states = states.into_iter();
        let mut parts: SmallVec<[_; 16]> = out
            .a_rl
            .chunks_mut(chunk * k * m)
            .zip(out.flags.chunks_mut(chunk))
            .enumerate()
            .map(|(c, (ga, f))| {
                let act = actions.next().flatten();
                let gs = states.next().flatten();
                (c, ga, f, act, gs)
            })
            .collect();
        let work = |(c, ga, flags, act, gs): &mut Part<'_>| {
            self.with_workspace(n, |ws| {
                let mut unit = [0.0; 16];
                for i in 0..flags.len() {
                    let row = *c * chunk + i;
                    let call = rows.call(row, a_rl, dynamics, drift, m);
                    let (s, q, a) = (call.s, call.q, call.a_rl);
                    self.step(ws, call, Stage::Filter(Want::Action));
                    if let Some(act) = act.as_deref_mut() {
                        act[i * m..(i + 1) * m].copy_from_slice(&ws.out.action);
                    }
                    let (mut f, ready) = self.row_factor(ws);
                    if ready && sn > 0 && ws.program.has_goal {
                        let Workspace { program, grad, .. } = &mut *ws;
                        if self.goal_jacobian(s, q, &program.aim.target, grad) {
                            f |= GRAD_DEGENERATE;
                        }
                    }
                    // A step whose bent rows were linearised again at its own action: the
                    // action is a fixed point, and so is its adjoint (`settled_cotangent`).
                    let bent = ready && !ws.program.relin.is_empty();
                    if bent {
                        self.bent_jacobian(ws, (s, call.drift));
                    }
                    let mut settled = [0.0; 16];
                    for j in 0..k {
                        let v = cotangents.get(row, j, m, &mut unit);
                        let v = match bent {
                            true => {
                                self.settled_cotangent(ws, a, v, &mut settled[..m]);
                                &settled[..m]
                            }
                            false => v,
                        };
                        let at = (i * k + j) * m;
                        let ga = &mut ga[at..at + m];
                        ga.copy_from_slice(v);
                        let gs = gs.as_deref_mut().map(|g| {
                            let at = (i * k + j) * sn;
                            let g = &mut g[at..at + sn];
                            g.fill(0.0);
                            g
                        });
                        if ready {
                            f |= self.row_chain(ws, s, a, v, ga, gs);
                        }
                    }
                    flags[i] = f;
                }
            });
        };
        crate::parallel::for_each_part(&mut parts, work);
    }

    /// `dL_k/da0_j` of every bent row (`b.bent_jac`, rows x m x m, in row order) at the point
    /// the step's last pass linearised them at, by central differences of
    /// `Program::bent_lg` (`program.rs`). Once per gradient row, after its step.
    fn bent_jacobian(&self, ws: &mut Workspace, (s, drift): (&[f64], Option<&[f64]>)) {
        let Workspace {
            program, grad: b, ..
        } = ws;
        let (params, m) = (&self.params, self.m);
        let model = self.dynamics.as_ref().expect("bent rows have a model");
        let predicates = self.automaton.spec().predicates();
        b.bent_jac.clear();
        let (mut a0, mut plus, mut minus) = ([0.0; 16], [0.0; 16], [0.0; 16]);
        let lin: SmallVec<[f64; 16]> = program.relin.iter().copied().collect();
        for row in 0..program.barriers() {
            if !program.bent[row] {
                continue;
            }
            let barrier = row_barrier(program.source(row), params, predicates);
            for j in 0..m {
                let step = BENT_STEP * (1.0 + lin[j].abs());
                for (shift, out) in [(step, &mut plus), (-step, &mut minus)] {
                    a0[..m].copy_from_slice(&lin);
                    a0[j] += shift;
                    let at = (s, &a0[..m]);
                    program.bent_lg(barrier, at, (model, drift), params, &mut out[..m]);
                }
                // Column j: dL_k/da0_j for every k.
                b.bent_jac
                    .extend((0..m).map(|k| (plus[k] - minus[k]) / (2.0 * step)));
            }
        }
    }

    /// The cotangent `w` (into `w`) that makes a relinearised step's gradient exact: its action
    /// `a* = a_rl + c(a_rl, a0)` is a fixed point `a0 = a*` (`Shield::step`), so `dL/da_rl =
    /// w + dc/da_rl' w` with `w = v + dc/da0' w`. `dc/da0' w` runs through the bent rows alone
    /// (every other row is built at `a = 0`): each holds `G = -L(a0)` on the `a_cbf` and
    /// `a_clf` columns and `h = r(a0) + L(a0) . (a_rl - a0)`, whose `a0`-derivative is
    /// `dL/da0' (a_rl - a0)`.
    fn settled_cotangent(&self, ws: &mut Workspace, a_rl: &[f64], v: &[f64], w: &mut [f64]) {
        let Workspace {
            program,
            qp,
            solvers,
            grad: b,
            ..
        } = ws;
        let (m, nv) = (self.m, qp.vars());
        let (cbf_vars, has_goal) = (program.cbf_vars, program.has_goal);
        let lin = &program.relin;
        w.copy_from_slice(v);
        let mut next = [0.0; 16];
        for _ in 0..ADJOINT_PASSES {
            b.dx.clear();
            b.dx.resize(nv, 0.0);
            if self.params.use_cbf {
                b.dx[..m].copy_from_slice(w);
            }
            if has_goal {
                b.dx[cbf_vars..cbf_vars + m].copy_from_slice(w);
            }
            b.dh.resize(qp.rows(), 0.0);
            b.dg.resize(qp.rows() * nv, 0.0);
            b.adjoint
                .apply(qp, &solvers.solution.x, &b.dx, &mut b.dh, &mut b.dg);
            next[..m].copy_from_slice(v);
            let mut at = 0;
            for row in 0..program.barriers() {
                if !program.bent[row] {
                    continue;
                }
                let jac = &b.bent_jac[at * m * m..(at + 1) * m * m];
                at += 1;
                for (j, n) in next[..m].iter_mut().enumerate() {
                    let col = &jac[j * m..(j + 1) * m];
                    let moved: f64 = (0..m).map(|k| col[k] * (a_rl[k] - lin[k])).sum();
                    let mut through_g = 0.0;
                    for (k, &dl) in col.iter().enumerate() {
                        let mut d = 0.0;
                        if self.params.use_cbf {
                            d += b.dg[row * nv + k];
                        }
                        if has_goal {
                            d += b.dg[row * nv + cbf_vars + k];
                        }
                        through_g -= d * dl;
                    }
                    *n += b.dh[row] * moved + through_g;
                }
            }
            let settled = w
                .iter()
                .zip(&next[..m])
                .all(|(a, n)| (a - n).abs() <= ADJOINT_SETTLED * (1.0 + n.abs()));
            w.copy_from_slice(&next[..m]);
            if settled {
                return;
            }
        }
    }

    /// The CLF goal's Jacobian over the centre dimensions (`b.goal_jac`, goal length x
    /// `b.centres`), once per row. A goal that is a moving ball's centre moves with it
    /// (exact); any other goal is differentiated by central differences of the automaton's
    /// goal. Returns true when the goal changes its choice within the step (a kink).
    fn goal_jacobian(&self, s: &[f64], q: usize, goal: &[f64], b: &mut Buffers) -> bool {
        b.centres.clear();
        for p in self.automaton.spec().predicates() {
            centre_dims(p, &mut b.centres);
        }
        let (g, c) = (goal.len(), b.centres.len());
        b.goal_jac.clear();
        b.goal_jac.resize(g * c, 0.0);
        if c == 0 {
            return false;
        }
        // The centre of a ball read from the state: goal_k = s[dims_k].
        for p in self.automaton.spec().predicates() {
            if let Predicate::Ball(ball) = p {
                if let Center::Dims(dims) = ball.center() {
                    if dims.len() == g && dims.iter().zip(goal).all(|(&d, &x)| s[d] == x) {
                        for (k, d) in dims.iter().enumerate() {
                            let ci = b.centres.iter().position(|x| x == d).expect("collected");
                            b.goal_jac[k * c + ci] = 1.0;
                        }
                        return false;
                    }
                }
            }
        }
        // How the goal was chosen at s, when that is the goal given (routing may aim elsewhere).
        let choice = self
            .automaton
            .read_validated(s)
            .goal_choice(q, &mut b.plus)
            .filter(|_| b.plus == goal);
        let mut kink = false;
        for ci in 0..c {
            let dim = b.centres[ci];
            let h = GOAL_STEP * (1.0 + s[dim].abs());
            // When no step of +-h can change which alternative wins (its lead beats what two
            // such steps can move two scores), the goal at the shifted states is that
            // alternative's point there: the same numbers as the automaton's whole choice,
            // without scoring the others, and exactly zero where it does not read `dim`.
            let lip = self.automaton.goal_score_lipschitz(dim);
            let leads = |ch: &&GoalChoice| ch.lead > 2.0 * h * lip + LEAD_ROUNDING;
            if let Some(ch) = choice.as_ref().filter(leads) {
                let moves = ch.reads(dim);
                let mut held = true;
                for (sign, into) in [(1.0, &mut b.plus), (-1.0, &mut b.minus)] {
                    b.shifted.clear();
                    b.shifted.extend_from_slice(s);
                    b.shifted[dim] += sign * h;
                    held &= ch.passed_stay_empty(&b.shifted, dim, &mut b.spare);
                    if moves {
                        held &= ch.place(&b.shifted, into) && into.len() == g;
                    }
                }
                if held {
                    if moves {
                        kink |= goal_column(goal, &b.plus, &b.minus, h, &mut b.goal_jac[ci..], c);
                    }
                    continue;
                }
                // The choice changes within the step: the automaton chooses again (below).
            }
            for (sign, into) in [(1.0, &mut b.plus), (-1.0, &mut b.minus)] {
                b.shifted.clear();
                b.shifted.extend_from_slice(s);
                b.shifted[dim] += sign * h;
                if !self.automaton.read_validated(&b.shifted).goal(q, into) {
                    into.clear();
                }
            }
            if b.plus.len() != g || b.minus.len() != g {
                kink = true;
                continue;
            }
            kink |= goal_column(goal, &b.plus, &b.minus, h, &mut b.goal_jac[ci..], c);
        }
        kink
    }

    /// Prepares the gradients of the step just taken in `ws`: the QP's active rows and their
    /// factors. Returns the row's flags and whether the QP part applies (false: the gradient
    /// is the identity, as for a failed step or one with nothing to correct).
    fn row_factor(&self, ws: &mut Workspace) -> (u8, bool) {
        let Workspace {
            program,
            qp,
            solvers,
            out,
            grad: b,
            ..
        } = ws;
        if out.status == Status::Failed {
            return (GRAD_FAILED, false);
        }
        let flags = if out.status == Status::Solved {
            0
        } else {
            GRAD_RELAXED
        };
        if program.vars() == 0 {
            return (flags, false);
        }
        // With delta_0 > 0, `d >= 0` is implied by the CLF row and the CLF box (delta_0 is their
        // bound in closed form): tight with them at a corner of the box, but no kink.
        let implied = (program.has_goal && program.delta_0 > 0.0).then_some(program.barriers() + 1);
        let (x, z) = (&solvers.solution.x, &solvers.solution.z);
        match b.adjoint.factor(qp, x, z, implied) {
            Err(Singular) => (flags | GRAD_SINGULAR, false),
            Ok(a) if a.degenerate => (flags | GRAD_DEGENERATE, true),
            Ok(_) => (flags, true),
        }
    }

    /// One upstream gradient `v = dL/da` through the step prepared by [`Shield::row_factor`]:
    /// `dL/da_rl` into `ga`, `dL/ds` into `gs` (when asked); returns flags it adds (a goal
    /// that switches within the difference step, a CLF box tie).
    #[allow(clippy::too_many_arguments)]
    fn row_chain(
        &self,
        ws: &mut Workspace,
        s: &[f64],
        a_rl: &[f64],
        v: &[f64],
        ga: &mut [f64],
        mut gs: Option<&mut [f64]>,
    ) -> u8 {
        let Workspace {
            program,
            qp,
            solvers,
            grad: b,
            ..
        } = ws;
        let mut flags = if program.aim.rerouted() {
            GRAD_ROUTED
        } else {
            0
        };
        let params = &self.params;
        let (m, n, nv, rows) = (self.m, s.len(), qp.vars(), qp.rows());
        let (cbf_vars, has_goal) = (program.cbf_vars, program.has_goal);
        let barriers = program.barriers();
        b.dx.clear();
        b.dx.resize(nv, 0.0);
        if params.use_cbf {
            b.dx[..m].copy_from_slice(v);
        }
        if has_goal {
            b.dx[cbf_vars..cbf_vars + m].copy_from_slice(v);
        }
        b.dh.resize(rows, 0.0);
        b.dg.resize(rows * nv, 0.0);
        let x = &solvers.solution.x;
        b.adjoint.apply(qp, x, &b.dx, &mut b.dh, &mut b.dg);
        for buf in [&mut b.grad, &mut b.u, &mut b.hu, &mut b.tmp] {
            buf.resize(n, 0.0);
        }
        b.beta.resize(m, 0.0);

        // Barrier rows: h_b = r_b + L_b . a_rl, G_b = -L_b on the a_cbf and a_clf columns.
        // State gradients come only without second-order rows, so then every barrier has one
        // row and the rows follow the sources (a mixed barrier's second row needs no source).
        let mut sources =
            params
                .barriers
                .iter()
                .map(|bar| (&bar.predicate, bar.positive))
                .chain(program.safe.iter().map(|&(lit, _)| {
                    (&self.automaton.spec().predicates()[lit.atom], lit.positive)
                }));
        for row in 0..barriers {
            let alpha = b.dh[row];
            let lg = &program.lg[row * m..(row + 1) * m];
            for j in 0..m {
                ga[j] += alpha * lg[j];
                let mut d = 0.0;
                if params.use_cbf {
                    d += b.dg[row * nv + j];
                }
                if has_goal {
                    d += b.dg[row * nv + cbf_vars + j];
                }
                b.beta[j] = -d + alpha * a_rl[j];
            }
            let Some(gs) = gs.as_deref_mut() else {
                continue;
            };
            let (predicate, positive) = sources.next().expect("first-order rows: one per source");
            let model = self
                .dynamics
                .as_ref()
                .expect("checked: state gradients need a model");
            let sign = if positive { 1.0 } else { -1.0 };
            if let Some(dt) = params.dt {
                sampled_row_state_gradient(
                    predicate, sign, s, dt, alpha, params, program, model, b, gs,
                );
                continue;
            }
            predicate.gradient_into(s, &mut b.grad);
            b.grad.iter_mut().for_each(|g| *g *= sign);
            // u = alpha f + sum_j beta_j g_j - alpha sum_d w_d sgn(grad_d) e_d; then H' u.
            for k in 0..n {
                let gk = &program.g[k * m..(k + 1) * m];
                b.u[k] = alpha * program.f[k] + dot(gk, &b.beta);
            }
            for &(d, w) in &params.disturbance {
                b.u[d] -= alpha * w * b.grad[d].signum() * f64::from(b.grad[d] != 0.0);
            }
            predicate.hessian_times(s, &b.u, &mut b.hu);
            model.jacobian_f_transpose_times(s, &b.grad, &mut b.tmp);
            for (k, g) in gs.iter_mut().enumerate() {
                *g += sign * b.hu[k] + alpha * (b.tmp[k] + params.alpha * b.grad[k]);
            }
            model.input_jacobian_contract(s, &b.grad, &b.beta, &mut b.tmp);
            gs.iter_mut().zip(&b.tmp).for_each(|(g, t)| *g += t);
        }

        // The CLF row: G = [Lg V on a_clf, -1 on d], h = clf_rhs + delta_0, where
        // clf_rhs = -(Lf V + Lg V . a_rl + c3 V); when delta_0 > 0, h = min over the box of
        // Lg V . a_clf, which reads Lg V alone.
        let mut next = barriers;
        if has_goal {
            let (alpha, l) = (b.dh[barriers], &program.clf_lg);
            let (mut lf_weight, mut v_weight) = (0.0, 0.0);
            let start = barriers * nv + cbf_vars;
            b.beta.copy_from_slice(&b.dg[start..start + m]);
            if program.delta_0 > 0.0 {
                for (j, (beta, &l)) in b.beta.iter_mut().zip(l).enumerate() {
                    let (lo, hi) = program.clf_box(params, j);
                    if l == 0.0 && lo != hi {
                        flags |= GRAD_DEGENERATE;
                    }
                    *beta += alpha * if l > 0.0 { lo } else { hi };
                    // The box side that is widened by a released turn moves with a_rl_j by -1.
                    let released = program.aim.released(j);
                    if (l > 0.0 && released > 0.0) || (l <= 0.0 && released < 0.0) {
                        ga[j] -= alpha * l;
                    }
                }
            } else {
                for j in 0..m {
                    b.beta[j] -= alpha * a_rl[j];
                    ga[j] -= alpha * l[j];
                }
                lf_weight = -alpha;
                v_weight = -alpha * params.c3;
            }
            if let Some(gs) = gs {
                // V = |e|^2, Lf V = 2 e . f[pos], Lg V_j = 2 e . g[pos, j], e = s[pos] - goal.
                let model = self
                    .dynamics
                    .as_ref()
                    .expect("checked: state gradients need a model");
                b.u.fill(0.0);
                for (&p, &c) in params.pos.iter().zip(&program.aim.target) {
                    b.u[p] = s[p] - c;
                }
                model.jacobian_f_transpose_times(s, &b.u, &mut b.tmp);
                gs.iter_mut()
                    .zip(&b.tmp)
                    .for_each(|(g, t)| *g += 2.0 * lf_weight * t);
                for &p in &params.pos {
                    let gp = &program.g[p * m..(p + 1) * m];
                    gs[p] +=
                        2.0 * (v_weight * b.u[p] + lf_weight * program.f[p] + dot(gp, &b.beta));
                }
                model.input_jacobian_contract(s, &b.u, &b.beta, &mut b.tmp);
                gs.iter_mut().zip(&b.tmp).for_each(|(g, t)| *g += 2.0 * t);
                // dL/de_k, then the goal's own motion when ball centres are read from the
                // state: e = s[pos] - goal(s).
                b.de.clear();
                for &p in &params.pos {
                    let gp = &program.g[p * m..(p + 1) * m];
                    b.de.push(
                        2.0 * (v_weight * b.u[p] + lf_weight * program.f[p] + dot(gp, &b.beta)),
                    );
                }
                // The goal's own motion (centres read from the state): e = s[pos] - goal(s).
                let c = b.centres.len();
                for (ci, &dim) in b.centres.iter().enumerate() {
                    gs[dim] -= (0..b.de.len())
                        .map(|k| b.de[k] * b.goal_jac[k * c + ci])
                        .sum::<f64>();
                }
            }
            next += 2;
        }

        // The box rows on a_cbf (constant), then on a_clf: h = hi_j, -lo_j, where the side
        // widened by a released turn reads a_rl_j (hi_j - a_rl_j, or -lo_j + a_rl_j).
        next += 2 * m * usize::from(params.use_cbf);
        if has_goal {
            for (j, (g, rows)) in ga.iter_mut().zip(b.dh[next..].chunks_exact(2)).enumerate() {
                let released = program.aim.released(j);
                if released < 0.0 {
                    *g -= rows[0];
                } else if released > 0.0 {
                    *g += rows[1];
                }
            }
            next += 2 * m;
        }

        // Actuator limits: h = hi - a_rl (upper rows), then a_rl - lo (lower rows).
        if params.action_bounds.is_some() {
            for (k, sign) in [1.0, -1.0].into_iter().enumerate() {
                let rows = &b.dh[next + k * m..next + (k + 1) * m];
                ga.iter_mut().zip(rows).for_each(|(g, d)| *g -= sign * d);
            }
        }
        flags
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::automaton::Automaton;
    use crate::dynamics::Dynamics;
    use crate::fixtures::{task_automaton, STATE_DIM as N};
    use crate::shield::{Bounds, ShieldParams, SolverChoice};
    use proptest::prelude::*;
    use std::sync::Arc;

    fn paper_shield(use_cbf: bool, use_clf: bool) -> Shield {
        let b = |lo: f64, hi: f64| Bounds::new(vec![lo; 2], vec![hi; 2]);
        let params = ShieldParams::new(2.0, 1.0, 1e4, b(-6.0, 6.0), b(-0.5, 0.5))
            .with_solver(SolverChoice::Auto)
            .with_action_bounds(Some(b(-4.0, 4.0)))
            .with_parts(use_cbf, use_clf);
        let model = Dynamics::unicycle(0.1, 0, 1, 2).unwrap();
        Shield::new(Arc::new(task_automaton()), Some(model), params).unwrap()
    }

    /// `v . a(s, a_rl)` for one row.
    fn value(sh: &Shield, s: &[f64], q: usize, a: &[f64], v: &[f64]) -> f64 {
        let out = sh.filter(s, q, a, None, None).unwrap();
        dot(v, &out.action)
    }

    proptest! {
        #![proptest_config(crate::tests_support::seeded(96))]

        /// The batch VJP equals central differences of the shielded action, in `a_rl` and in
        /// every state dimension (goal centres included), on rows that are not degenerate.
        #[test]
        fn vjp_matches_finite_differences(
            xy in (-1.0..4.0f64, -1.4..1.4f64),
            theta in -3.0..3.0f64,
            a in proptest::collection::vec(-3.5..3.5f64, 2),
            v in proptest::collection::vec(-1.0..1.0f64, 2),
            parts in 0..3usize,
        ) {
            let (use_cbf, use_clf) = [(true, true), (true, false), (false, true)][parts];
            let sh = paper_shield(use_cbf, use_clf);
            let mut s = vec![0.0; N];
            s[0] = xy.0 + xy.1 / 2.0;
            s[1] = xy.0 - xy.1 / 2.0;
            s[2] = theta;
            s[3..9].copy_from_slice(&[4.0, 4.0, 4.5, 6.5, 9.0, 9.0]);
            s[9..13].copy_from_slice(&[20.0, 20.0, 20.0, -20.0]);
            let aut: &Automaton = sh.automaton();
            let q = aut.read(&s).unwrap().step(aut.initial());
            let mut out = BatchGradient::default();
            sh.vjp_batch(StateBatch::new(&s, N, &[q]), &a, &v, None, None, true, &mut out).unwrap();
            prop_assume!(out.flags[0] == 0);
            let eps = 1e-6;
            for j in 0..2 {
                let (mut p, mut m) = (a.clone(), a.clone());
                p[j] += eps;
                m[j] -= eps;
                // The FSA state is read at s: a_rl moves nothing discrete.
                let fd = (value(&sh, &s, q, &p, &v) - value(&sh, &s, q, &m, &v)) / (2.0 * eps);
                prop_assert!((out.a_rl[j] - fd).abs() < 1e-5 * (1.0 + fd.abs()), "a_rl[{j}]: {} vs {fd}", out.a_rl[j]);
            }
            for i in 0..N {
                let (mut p, mut m) = (s.clone(), s.clone());
                p[i] += eps;
                m[i] -= eps;
                let fd = (value(&sh, &p, q, &a, &v) - value(&sh, &m, q, &a, &v)) / (2.0 * eps);
                prop_assert!((out.states[i] - fd).abs() < 1e-5 * (1.0 + fd.abs()), "s[{i}]: {} vs {fd}", out.states[i]);
            }
        }
    }

    /// The goal Jacobian by brute force: central differences of the automaton's whole choice
    /// in every centre dimension, kinks flagged as `goal_jacobian` flags them.
    fn goal_jacobian_by_brute_force(
        aut: &Automaton,
        s: &[f64],
        q: usize,
        goal: &[f64],
    ) -> (Vec<f64>, bool) {
        let centres = [3, 4, 5, 6, 7, 8];
        let (g, c) = (goal.len(), centres.len());
        let mut jac = vec![0.0; g * c];
        let mut kink = false;
        for (ci, &dim) in centres.iter().enumerate() {
            let h = GOAL_STEP * (1.0 + s[dim].abs());
            let at = |sign: f64| {
                let mut shifted = s.to_vec();
                shifted[dim] += sign * h;
                aut.goal(&shifted, q).unwrap().unwrap_or_default()
            };
            let (plus, minus) = (at(1.0), at(-1.0));
            if plus.len() != g || minus.len() != g {
                kink = true;
                continue;
            }
            let mut column = vec![0.0; g * c];
            kink |= goal_column(goal, &plus, &minus, h, &mut column[ci..], c);
            for k in 0..g {
                jac[k * c + ci] = column[k * c + ci];
            }
        }
        (jac, kink)
    }

    proptest! {
        #![proptest_config(crate::tests_support::seeded(1000))]

        /// The goal Jacobian that differentiates only the chosen alternative (when no step can
        /// change the choice) equals the brute-force differences of the whole choice bit for
        /// bit, kinks included: goal discs anywhere (straddling a wall, overlapping, tied).
        #[test]
        fn goal_jacobian_equals_the_whole_choice_differenced(
            xy in (-1.0..8.0f64, -1.6..1.6f64),
            goals in proptest::collection::vec(-1.0..10.0f64, 6),
            tie in 0..3usize,
        ) {
            let sh = paper_shield(true, true);
            let aut: &Automaton = sh.automaton();
            let mut s = vec![0.0; N];
            s[0] = xy.0 + xy.1 / 2.0;
            s[1] = xy.0 - xy.1 / 2.0;
            s[3..9].copy_from_slice(&goals);
            if tie == 1 {
                // g2 the mirror image of g1 across the robot: equally robust, a tie.
                s[5] = 2.0 * s[0] - s[3];
                s[6] = 2.0 * s[1] - s[4];
            }
            s[9..13].copy_from_slice(&[20.0, 20.0, 20.0, -20.0]);
            let mut b = Buffers::default();
            for q in 0..aut.num_states() {
                let Some(goal) = aut.goal(&s, q).unwrap() else {
                    continue;
                };
                // A goal at a ball's centre read from the state is differentiated exactly.
                if (3..9).step_by(2).any(|d| s[d..d + 2] == goal[..]) {
                    continue;
                }
                let kink = sh.goal_jacobian(&s, q, &goal, &mut b);
                let (jac, brute_kink) = goal_jacobian_by_brute_force(aut, &s, q, &goal);
                prop_assert_eq!(kink, brute_kink);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                prop_assert_eq!(bits(&b.goal_jac), bits(&jac), "s = {:?}, q = {}", s, q);
            }
        }
    }

    #[test]
    fn jacobian_rows_are_the_vjps_of_unit_vectors() {
        let sh = paper_shield(true, true);
        let mut states = Vec::new();
        let mut qs = Vec::new();
        let mut actions = Vec::new();
        for k in 0..40 {
            let t = k as f64;
            let mut s = vec![0.0; N];
            s[0] = 0.1 * t + 0.7 * (t * 1.3).sin();
            s[1] = 0.1 * t - 0.7 * (t * 1.3).sin();
            s[2] = (t * 0.77).sin() * 3.0;
            s[3..9].copy_from_slice(&[4.0, 4.0, 4.5, 6.5, 9.0, 9.0]);
            s[9..13].copy_from_slice(&[20.0, 20.0, 20.0, -20.0]);
            let q = sh
                .automaton()
                .read(&s)
                .unwrap()
                .step(sh.automaton().initial());
            states.extend_from_slice(&s);
            qs.push(q);
            actions.extend_from_slice(&[3.0 * (t * 0.3).cos(), 2.0 * (t * 0.5).sin()]);
        }
        let mut jac = BatchGradient::default();
        sh.jacobian_batch(
            StateBatch::new(&states, N, &qs),
            &actions,
            None,
            None,
            true,
            &mut jac,
        )
        .unwrap();
        let mut filtered = crate::shield::BatchOutput::default();
        sh.filter_batch(
            StateBatch::new(&states, N, &qs),
            &actions,
            None,
            &mut filtered,
        )
        .unwrap();
        assert_eq!(jac.action, filtered.action);
        for k in 0..2 {
            let unit: Vec<f64> = (0..40)
                .flat_map(|_| [f64::from(k == 0), f64::from(k == 1)])
                .collect();
            let mut vjp = BatchGradient::default();
            sh.vjp_batch(
                StateBatch::new(&states, N, &qs),
                &actions,
                &unit,
                None,
                None,
                true,
                &mut vjp,
            )
            .unwrap();
            assert_eq!(vjp.flags, jac.flags);
            for b in 0..40 {
                let row = (b * 2 + k) * 2;
                assert_eq!(&jac.a_rl[row..row + 2], &vjp.a_rl[b * 2..b * 2 + 2]);
                let row = (b * 2 + k) * N;
                assert_eq!(&jac.states[row..row + N], &vjp.states[b * N..(b + 1) * N]);
            }
        }
    }

    #[test]
    fn second_order_rows_refuse_state_gradients_but_not_action_gradients() {
        let b = |lo: f64, hi: f64| Bounds::new(vec![lo; 2], vec![hi; 2]);
        let params =
            ShieldParams::new(2.0, 1.0, 1e4, b(-6.0, 6.0), b(-0.5, 0.5)).with_alpha2(Some(2.0));
        let model = Dynamics::acceleration_unicycle(0, 1, 2, 12).unwrap();
        let sh = Shield::new(Arc::new(task_automaton()), Some(model), params).unwrap();
        let mut s = vec![0.0; N];
        s[3..9].copy_from_slice(&[4.0, 4.0, 4.5, 6.5, 9.0, 9.0]);
        let q = sh
            .automaton()
            .read(&s)
            .unwrap()
            .step(sh.automaton().initial());
        let mut out = BatchGradient::default();
        let err = sh
            .vjp_batch(
                StateBatch::new(&s, N, &[q]),
                &[1.0, 0.0],
                &[1.0, 1.0],
                None,
                None,
                true,
                &mut out,
            )
            .unwrap_err();
        assert!(err.to_string().contains("second-order"), "{err}");
        sh.vjp_batch(
            StateBatch::new(&s, N, &[q]),
            &[1.0, 0.0],
            &[1.0, 1.0],
            None,
            None,
            false,
            &mut out,
        )
        .unwrap();
        assert_eq!((out.a_rl.len(), out.states.len()), (2, 0));
    }
}
