//! Eq. 5D2 for one state, top to bottom: the dynamics at `s`, the barrier rows (Lie
//! derivatives of every barrier; second-order HOCBF rows where the barrier has relative degree
//! 2, see `order.rs`), the CLF row of Eq. 5B1 (second-order form under acceleration-level
//! models) with its `delta_0` shift, and the QP `min x'Px/2 + c'x  s.t.  G x <= h` over
//! `x = [a_cbf | a_clf | d | sigma (relaxed only)]`.
//!
//! Every row has the form `L . (a_rl + a_cbf + a_clf) + r >= 0` for the barriers. First order:
//! `L = Lg h`, `r = Lf h + alpha (h - margin)`. Second order (Xiao & Belta): with
//! `psi_1 = Lf h + alpha (h - margin)`, `L = Lg psi_1 = (H f + J_f^T grad h)^T g` and
//! `r = Lf psi_1 + alpha2 psi_1`, `Lf psi_1 = f^T H f + grad h . J_f f + alpha Lf h`
//! (`H` the barrier's Hessian, `J_f` the Jacobian of the drift; both exact). With
//! disturbance bounds `w_d` ([`ShieldParams::disturbance`]) every `r` drops by
//! `sum_d |dB/ds_d| w_d`, `B` the row's function (`h`, or `psi_1` with
//! `dpsi_1/ds = H f + J_f^T grad h + alpha grad h`): the robust CBF.
//!
//! The buffers live in [`Program`] and are reused from step to step: nothing here allocates
//! once they have grown to the problem's size.

use super::give_way::GiveWay;
use super::order::{Form, Orders};
use super::sampled::{self, Sampled};
use super::{BarrierSource, Call, ControlAffine, ShieldParams};
use crate::automaton::{Automaton, Reading};
use crate::cnf::Literal;
use crate::dynamics::Dynamics;
use crate::guidance::{Aim, Manoeuvre, Routing, Turn};
use crate::linalg::dot;
use crate::monitor::Monitor;
use crate::predicate::Predicate;
use crate::qp::DenseQp;

/// What a shield fixed at construction, read by every step's rows.
#[derive(Clone, Copy)]
pub(super) struct Rules<'a> {
    pub(super) params: &'a ShieldParams,
    /// What the CLF routes around (`None`: it does not route).
    pub(super) routing: Option<&'a Routing>,
    pub(super) orders: &'a Orders,
    pub(super) automaton: &'a Automaton,
    pub(super) model: Option<&'a Dynamics>,
}

/// The rows of Eq. 5D2 at one state, and the buffers they are computed in.
#[derive(Debug, Default)]
pub(super) struct Program {
    /// `f(s)` (plus the drift) and `g(s)` (n x m).
    pub(super) f: Vec<f64>,
    pub(super) g: Vec<f64>,
    grad: Vec<f64>,
    /// Second-order terms: `H f` (a second-order barrier row's, then its `grad psi_1`),
    /// `J_f f` and `J_f^T w` (n each).
    hf: Vec<f64>,
    jf: Vec<f64>,
    jt: Vec<f64>,
    /// The second-order CLF's error `e` placed at the position dimensions (n values).
    clf_error: Vec<f64>,
    pub(super) safe: Vec<(Literal, f64)>,
    /// Per barrier: `Lg h` (m values), the row's right-hand side and its slack weight.
    pub(super) lg: Vec<f64>,
    rhs: Vec<f64>,
    weights: Vec<f64>,
    /// Per row: the barrier it holds (what gave way, when its slack is the largest).
    sources: Vec<BarrierSource>,
    /// Per row: whether it is a second-order sampled row linearised at the RL action, whose
    /// `L` then moves with `a_rl` (`sampled.rs`; the gradient reads it).
    pub(super) bent: Vec<bool>,
    /// The action the bent rows were last linearised at ([`Program::relinearise`]); empty
    /// when they are at `a = 0`, as every row is first.
    pub(super) relin: Vec<f64>,
    /// Where the CLF aims (the goal of Eq. 5B1 or the router's target in its place) and what
    /// guidance changed in its row (`crate::guidance`).
    pub(super) aim: Aim,
    /// The CLF's `Lg V` (m values).
    pub(super) clf_lg: Vec<f64>,
    /// Whether this step has a CLF goal (CLF on and a goal in this FSA state).
    pub(super) has_goal: bool,
    clf_rhs: f64,
    /// The closed-form lower bound of `delta` over the CLF box; the QP solves for
    /// `d = delta - delta_0 >= 0`.
    pub(super) delta_0: f64,
    /// The sampled rows' buffers (`sampled.rs`), used when the shield knows `dt`.
    sampled: Sampled,
    /// Variables of the unrelaxed problem: `a_cbf` (m if the CBF is on), `a_clf` and `d` (if
    /// there is a goal).
    pub(super) cbf_vars: usize,
    pub(super) clf_vars: usize,
}

/// What the rows of one call are built from: the parameters, the model (or the call's own `f`,
/// `g`), the state, the FSA state and the RL action.
#[derive(Clone, Copy)]
struct Site<'a> {
    params: &'a ShieldParams,
    model: Option<&'a Dynamics>,
    fg: Option<ControlAffine<'a>>,
    s: &'a [f64],
    q: usize,
    a_rl: &'a [f64],
    /// The drift of the dimensions no input moves (moving obstacles), constant over a step.
    drift: Option<&'a [f64]>,
}

/// `out = J_f(s) u` (or `J_f(s)^T u` when `transpose`): from the Jacobian passed with this
/// call when there is one, else from the model (the shield checks that one of them exists
/// whenever a row is second order).
fn jacobian_times(
    model: Option<&Dynamics>,
    fg: Option<ControlAffine<'_>>,
    s: &[f64],
    u: &[f64],
    out: &mut [f64],
    transpose: bool,
) {
    let n = s.len();
    match (fg.and_then(|fg| fg.jacobian), model) {
        (Some(jac), _) => {
            for (i, o) in out.iter_mut().enumerate() {
                *o = match transpose {
                    false => dot(&jac[i * n..(i + 1) * n], u),
                    true => (0..n).map(|k| jac[k * n + i] * u[k]).sum(),
                };
            }
        }
        (None, Some(model)) if transpose => model.jacobian_f_transpose_times(s, u, out),
        (None, Some(model)) => model.jacobian_f_times(s, u, out),
        (None, None) => unreachable!("second-order rows need a model or a Jacobian"),
    }
}

/// Appends a barrier row's `L = c^T g` (one value per input) to `lg`, for the row's state
/// coefficients `c` (`grad h`, or `grad psi_1` for a second-order row); returns `L . a_rl`.
fn push_lg(coefficients: &[f64], g: &[f64], a_rl: &[f64], lg: &mut Vec<f64>) -> f64 {
    let m = a_rl.len();
    let mut lg_a = 0.0;
    for (j, a) in a_rl.iter().enumerate() {
        let l = coefficients
            .iter()
            .enumerate()
            .map(|(k, c)| c * g[k * m + j])
            .sum::<f64>();
        lg_a += l * a;
        lg.push(l);
    }
    lg_a
}

/// The robust tightening of a row with state coefficients `c`: `sum_d |c_d| w_d` over the
/// disturbance bounds `(d, w)`.
fn tightening(coefficients: &[f64], disturbance: &[(usize, f64)]) -> f64 {
    disturbance
        .iter()
        .map(|&(d, w)| coefficients[d].abs() * w)
        .sum()
}

/// The continuous-time second-order (HOCBF) row of a barrier on `predicate` (signed by
/// `sign`) with `grad h` and `f` given: leaves `grad psi_1 = H f + J_f^T grad h + alpha grad h`
/// in `hf` (so `Lg psi_1 = hf^T g`; `alpha Lg h` is 0 at relative degree 2, not where it is
/// mixed) and returns `r = Lf psi_1 + alpha2 psi_1` for `psi_1 = Lf h + psi`, `psi = alpha (h -
/// margin)`, with `Lf psi_1 = f^T H f + grad h . J_f f + alpha Lf h`. `jf` and `jt` are
/// scratch.
fn second_order(
    (hf, jf, jt): (&mut [f64], &mut [f64], &mut [f64]),
    (grad, f): (&[f64], &[f64]),
    predicate: &Predicate,
    sign: f64,
    at: Site<'_>,
    psi: f64,
) -> f64 {
    let Site {
        params,
        model,
        fg,
        s,
        ..
    } = at;
    let lf = dot(grad, f);
    predicate.hessian_times(s, f, hf);
    hf.iter_mut().for_each(|v| *v *= sign);
    jacobian_times(model, fg, s, f, jf, false);
    jacobian_times(model, fg, s, grad, jt, true);
    let lf_psi = dot(f, hf) + dot(grad, jf) + params.alpha * lf;
    for ((a, b), g) in hf.iter_mut().zip(jt.iter()).zip(grad) {
        *a += b;
        *a += params.alpha * g;
    }
    let alpha2 = params.alpha2.expect("Orders requires alpha2");
    lf_psi + alpha2 * (lf + psi)
}

/// One enforced barrier: where it comes from, its predicate, sign (`h = sign rho`), value
/// `h(s)`, slack weight and row form.
type Enforced<'a> = (BarrierSource, &'a Predicate, f64, f64, f64, Form);

/// The barriers a step enforces, in row order: the user's barriers, then the literals `safe`
/// kept from the FSA state's safe set (Eq. 5C1, weight 1).
fn enforced<'a>(
    params: &'a ShieldParams,
    safe: &'a [(Literal, f64)],
    spec: &'a crate::spec::Spec,
    orders: &'a Orders,
    s: &'a [f64],
) -> impl Iterator<Item = Enforced<'a>> + 'a {
    let user = params.barriers.iter().enumerate().map(move |(i, b)| {
        let sign = if b.positive { 1.0 } else { -1.0 };
        let source = BarrierSource::User(i);
        (
            source,
            &b.predicate,
            sign,
            b.value(s),
            b.slack_weight,
            orders.barriers[i],
        )
    });
    let kept = safe.iter().map(move |&(lit, h)| {
        let sign = if lit.positive { 1.0 } else { -1.0 };
        let predicate = &spec.predicates()[lit.atom];
        (
            BarrierSource::SafeSet(lit),
            predicate,
            sign,
            h,
            1.0,
            orders.atoms[lit.atom],
        )
    });
    user.chain(kept)
}

/// The barrier (predicate, sign) a barrier row holds, from its source.
pub(super) fn row_barrier<'a>(
    source: BarrierSource,
    params: &'a ShieldParams,
    predicates: &'a [Predicate],
) -> (&'a Predicate, f64) {
    match source {
        BarrierSource::User(i) => {
            let bar = &params.barriers[i];
            (&bar.predicate, if bar.positive { 1.0 } else { -1.0 })
        }
        BarrierSource::SafeSet(lit) => {
            let sign = if lit.positive { 1.0 } else { -1.0 };
            (&predicates[lit.atom], sign)
        }
    }
}

/// Appends a zero row of `nv` coefficients with right-hand side `rhs`; returns it to fill.
fn push_row(qp: &mut DenseQp, nv: usize, rhs: f64) -> &mut [f64] {
    let start = qp.g.len();
    qp.g.resize(start + nv, 0.0);
    qp.h.push(rhs);
    &mut qp.g[start..]
}

impl Program {
    /// Buffers for states of length `n`.
    pub(super) fn with_state_len(n: usize) -> Self {
        Program {
            f: vec![0.0; n],
            grad: vec![0.0; n],
            hf: vec![0.0; n],
            jf: vec![0.0; n],
            jt: vec![0.0; n],
            clf_error: vec![0.0; n],
            ..Program::default()
        }
    }

    /// Barrier rows of the last [`Program::rows`].
    pub(super) fn barriers(&self) -> usize {
        self.rhs.len()
    }

    /// The barrier that barrier row `row` holds.
    pub(super) fn source(&self, row: usize) -> BarrierSource {
        self.sources[row]
    }

    /// Linearises the bent rows (`bent`) again at the action `a0` (`sampled.rs`): each
    /// becomes `r(a0) + L(a0) . (a - a0) >= 0`, in the QP's variables `L . (a_cbf + a_clf) >=
    /// -(r + L . (a_rl - a0))`. Every other row, the CLF's included, stays as built at `a =
    /// 0`. `predicates` are the spec's (the safe set's literals read them).
    pub(super) fn relinearise(
        &mut self,
        (params, predicates): (&ShieldParams, &[Predicate]),
        (model, drift): (&Dynamics, Option<&[f64]>),
        (s, a_rl, a0): (&[f64], &[f64], &[f64]),
    ) {
        let (m, dt) = (a_rl.len(), params.dt.expect("bent rows are sampled"));
        let fg = (&self.f[..], &self.g[..]);
        self.sampled.predict(s, fg, Some(model), (drift, a0), dt);
        self.relin.clear();
        self.relin.extend_from_slice(a0);
        for row in 0..self.bent.len() {
            if !self.bent[row] {
                continue;
            }
            let (predicate, sign) = row_barrier(self.sources[row], params, predicates);
            let h = sign * predicate.value(s);
            let barrier = sampled::Barrier { predicate, sign, h };
            let r = self.sampled.second(barrier, s, model, params, dt);
            let robust = tightening(&self.sampled.coefficients, &params.disturbance);
            let (mut lg_a, mut lg_0) = (0.0, 0.0);
            for j in 0..m {
                let l = (0..s.len())
                    .map(|k| self.sampled.coefficients[k] * self.g[k * m + j])
                    .sum::<f64>();
                self.lg[row * m + j] = l;
                lg_a += l * a_rl[j];
                lg_0 += l * a0[j];
            }
            self.rhs[row] = r + lg_a - lg_0 - robust;
        }
    }

    /// A bent row's `L` (`m` values, into `out`) were it linearised at `a0`: the barrier
    /// `(predicate, sign)` at `s`, with this step's `f` and `g` and the model's drift
    /// (`sampled.rs`). The gradient differences it over `a0`. Reuses the sampled rows'
    /// buffers: call it only once the step is solved.
    pub(super) fn bent_lg(
        &mut self,
        (predicate, sign): (&Predicate, f64),
        (s, a0): (&[f64], &[f64]),
        (model, drift): (&Dynamics, Option<&[f64]>),
        params: &ShieldParams,
        out: &mut [f64],
    ) {
        let dt = params.dt.expect("bent rows are sampled");
        let fg = (&self.f[..], &self.g[..]);
        self.sampled.predict(s, fg, Some(model), (drift, a0), dt);
        let h = sign * predicate.value(s);
        let barrier = sampled::Barrier { predicate, sign, h };
        self.sampled.second(barrier, s, model, params, dt);
        let m = a0.len();
        for (j, o) in out.iter_mut().enumerate() {
            *o = (0..s.len())
                .map(|k| self.sampled.coefficients[k] * self.g[k * m + j])
                .sum();
        }
    }

    /// The barrier each barrier row holds.
    pub(super) fn sources(&self) -> &[BarrierSource] {
        &self.sources
    }

    /// Variables of the unrelaxed problem.
    pub(super) fn vars(&self) -> usize {
        self.cbf_vars + self.clf_vars + usize::from(self.has_goal)
    }

    /// `f(s)` and `g(s)` from the per-call override or the model, plus the drift of the
    /// dimensions the agent does not control (e.g. moving obstacles).
    fn load_dynamics(
        &mut self,
        s: &[f64],
        m: usize,
        fg: Option<ControlAffine<'_>>,
        model: Option<&Dynamics>,
        drift: Option<&[f64]>,
    ) {
        let n = s.len();
        self.f.resize(n, 0.0);
        self.g.resize(n * m, 0.0);
        self.grad.resize(n, 0.0);
        self.hf.resize(n, 0.0);
        self.jf.resize(n, 0.0);
        self.jt.resize(n, 0.0);
        self.clf_error.resize(n, 0.0);
        match (fg, model) {
            (Some(ControlAffine { f, g, .. }), _) => {
                self.f.copy_from_slice(f);
                self.g.copy_from_slice(g);
            }
            (None, Some(d)) => d.eval(s, &mut self.f, &mut self.g),
            (None, None) => unreachable!("the shield checks that dynamics are given"),
        }
        if let Some(d) = drift {
            for (f, d) in self.f.iter_mut().zip(d) {
                *f += d;
            }
        }
    }

    /// Builds every row of Eq. 5D2 for the call's `(s, q, a_rl)`: the barrier rows, then the
    /// CLF row. `barriers_out` receives each enforced barrier and its value (the single-step
    /// path records them).
    pub(super) fn rows(
        &mut self,
        rules: Rules<'_>,
        call: Call<'_>,
        barriers_out: Option<&mut Vec<(BarrierSource, f64)>>,
    ) {
        let Rules {
            params,
            routing,
            orders,
            automaton,
            model,
        } = rules;
        let Call {
            s,
            q,
            a_rl,
            fg,
            drift,
            task,
        } = call;
        let m = a_rl.len();
        self.load_dynamics(s, m, fg, model, drift);
        self.lg.clear();
        self.rhs.clear();
        self.weights.clear();
        self.sources.clear();
        self.bent.clear();
        self.aim.start();
        // The atoms' robustness at s, once for both the safe set and the goal: the task
        // monitor's reading of this state when there is one.
        let reading = match task {
            Some(monitor) => monitor.reading(),
            None => automaton.read_validated(s),
        };

        let at = Site {
            params,
            model,
            fg,
            s,
            q,
            a_rl,
            drift,
        };
        if params.use_cbf {
            if params.preserve_progress {
                reading.progress_safe_set(q, &mut self.safe);
            } else {
                reading.safe_set(q, &mut self.safe);
            }
            self.barrier_rows(at, orders, automaton, barriers_out);
        }
        self.clf_row(at, orders.clf, task, routing, &reading);
        self.cbf_vars = if params.use_cbf { m } else { 0 };
        self.clf_vars = if self.has_goal { m } else { 0 };
    }

    /// The barrier rows (the user's barriers, then the safe set of Eq. 5C1 already in
    /// `self.safe`): value h, the row's L (m values) and right-hand side r + L . a_rl (see the
    /// module docs).
    fn barrier_rows(
        &mut self,
        at: Site<'_>,
        orders: &Orders,
        automaton: &Automaton,
        mut barriers_out: Option<&mut Vec<(BarrierSource, f64)>>,
    ) {
        let Site {
            params,
            model,
            s,
            a_rl,
            drift,
            ..
        } = at;
        let enforced = enforced(params, &self.safe, automaton.spec(), orders, s);
        if let Some(dt) = params.dt {
            // The sample after next only where a second-order row reads it.
            let model = model.filter(|_| orders.second_order());
            let fg = (&self.f[..], &self.g[..]);
            self.sampled.predict(s, fg, model, (drift, &[]), dt);
        }
        for (source, predicate, sign, h, weight, form) in enforced {
            self.weights.push(weight);
            self.sources.push(source);
            let bent = form == Form::Second && params.dt.is_some() && self.sampled.bent;
            self.bent.push(bent);
            predicate.gradient_into(s, &mut self.grad);
            self.grad.iter_mut().for_each(|v| *v *= sign);
            self.aim
                .note_row((predicate, sign), &params.pos, s, &self.grad);
            let lf = dot(&self.grad, &self.f);
            let psi = params.alpha * (h - params.margin);
            let barrier = sampled::Barrier { predicate, sign, h };
            // The second-order row's r (None: first order, r = Lf h + alpha (h - margin)).
            let (coefficients, second_r) = match (form, params.dt) {
                // Rows that hold the sampled states (sampled.rs); a mixed barrier keeps the
                // continuous-time rows.
                (Form::First, Some(dt)) => {
                    let r = self.sampled.first(barrier, s, params, dt);
                    (&self.sampled.coefficients, Some(r))
                }
                (Form::Second, Some(dt)) => {
                    let model = model.expect("second-order rows have a model");
                    let r = self.sampled.second(barrier, s, model, params, dt);
                    (&self.sampled.coefficients, Some(r))
                }
                _ if form.second() => {
                    let buffers = (&mut self.hf[..], &mut self.jf[..], &mut self.jt[..]);
                    let r = second_order(buffers, (&self.grad, &self.f), predicate, sign, at, psi);
                    (&self.hf, Some(r))
                }
                _ => (&self.grad, None),
            };
            // The robust tightening: sum_d |dB/ds_d| w_d, with dB/ds = grad h (first
            // order) or grad psi_1 (second order), the row's coefficients either way.
            let robust = tightening(coefficients, &params.disturbance);
            let lg_a = push_lg(coefficients, &self.g, a_rl, &mut self.lg);
            self.rhs.push(
                match second_r {
                    Some(r) => r + lg_a,
                    // In this order (Lf h + Lg h . a_rl first), bit for bit as before HOCBF rows.
                    None => lf + lg_a + psi,
                } - robust,
            );
            if form == Form::Mixed {
                // The input's share of dh/dt: Lg h . a >= -alpha (h - margin), tightened by the
                // disturbance on what h reads (see order.rs).
                let robust = tightening(&self.grad, &params.disturbance);
                let lg_a = push_lg(&self.grad, &self.g, a_rl, &mut self.lg);
                self.rhs.push(lg_a + psi - robust);
                self.weights.push(weight);
                self.sources.push(source);
                self.bent.push(false);
                self.aim.note_unrouted_row();
            }
            if let Some(out) = barriers_out.as_deref_mut() {
                out.push((source, h));
            }
        }
    }

    /// The CLF row of Eq. 5B1 towards the goal (or the target guidance aims at in its place,
    /// `crate::guidance`), and `delta_0`.
    fn clf_row(
        &mut self,
        at: Site<'_>,
        second_order: bool,
        task: Option<&Monitor>,
        routing: Option<&Routing>,
        reading: &Reading<'_>,
    ) {
        let Site {
            params, q, a_rl, ..
        } = at;
        let m = a_rl.len();
        // CLF row (Eq. 5B1's goal): V = |e|^2 with e = s[pos] - goal, or, when no input moves
        // pos directly (second order), e = f[pos] + k (s[pos] - goal) (drive the velocity
        // towards k times the remaining distance);
        // Lg V . a_clf - delta <= -(Lf V + Lg V . a_rl + c3 V).
        self.has_goal = params.use_clf
            && match task {
                Some(monitor) => monitor.goal().is_some_and(|g| {
                    self.aim.target.clear();
                    self.aim.target.extend_from_slice(g);
                    true
                }),
                None => reading.goal(q, &mut self.aim.target),
            };
        if let (true, Some(routing)) = (self.has_goal, routing) {
            // A monitor routed the same way has planned this state's way already; the safe
            // set is the rows' when they read it.
            let planned = task.and_then(|monitor| monitor.routed_target(routing));
            let safe = params.use_cbf.then_some(&self.safe[..]);
            self.aim.route(routing, planned, reading, q, safe);
        }
        self.clf_rhs = 0.0;
        self.delta_0 = 0.0;
        self.clf_lg.clear();
        self.clf_lg.resize(m, 0.0);
        if self.has_goal {
            let (v, lf) = match second_order {
                true => self.second_order_clf(at),
                false => self.first_order_clf(at),
            };
            if params.route {
                self.aim
                    .uncredit_blocked_progress(&mut self.clf_lg, &self.lg, &self.rhs);
                let heading = params
                    .heading
                    .or_else(|| at.model.and_then(Dynamics::heading));
                if let (2, Some(theta)) = (params.pos.len(), heading) {
                    let g_theta = &self.g[theta * m..(theta + 1) * m];
                    self.aim
                        .release_blocked_turn(at.s[theta], g_theta, a_rl, &self.rhs);
                    let car = params
                        .speed
                        .or_else(|| at.model.and_then(Dynamics::turns_only_moving));
                    if let Some(speed) = car {
                        let p = [at.s[params.pos[0]], at.s[params.pos[1]]];
                        let g_v = &self.g[speed * m..(speed + 1) * m];
                        self.aim
                            .release_blocked_throttle((at.s[theta], p), g_v, a_rl);
                    }
                }
            }
            self.clf_rhs = -(lf + dot(&self.clf_lg, a_rl) + params.c3 * v);
            // The CLF bounds give delta a lower bound in closed form; solving for the excess
            // d = delta - delta_0 >= 0 keeps the objective (and so the solver's relative gap)
            // of the order of |a|^2 instead of K * delta. The solution is the same.
            let best = (0..m)
                .map(|j| {
                    let (lo, hi) = self.clf_box(params, j);
                    (self.clf_lg[j] * lo).min(self.clf_lg[j] * hi)
                })
                .sum::<f64>();
            self.delta_0 = (best - self.clf_rhs).max(0.0);
        }
    }

    /// The CLF's box on input `j` this step: `clf_bounds`, widened by the RL action's turn
    /// routing released (`crate::guidance`).
    pub(super) fn clf_box(&self, params: &ShieldParams, j: usize) -> (f64, f64) {
        let bounds = &params.clf_bounds;
        self.aim.clf_box((bounds.lo[j], bounds.hi[j]), j)
    }

    /// The first-order CLF towards the target: `V = |e|^2`, `e = s[pos] - target`; writes
    /// `Lg V` into `clf_lg` (zeroed) and returns `(V, Lf V)`.
    fn first_order_clf(&mut self, at: Site<'_>) -> (f64, f64) {
        let Site {
            params, s, a_rl, ..
        } = at;
        let m = a_rl.len();
        let (mut v, mut lf) = (0.0, 0.0);
        for (&k, &c) in params.pos.iter().zip(&self.aim.target) {
            let e = s[k] - c;
            v += e * e;
            lf += 2.0 * e * self.f[k];
            for (j, l) in self.clf_lg.iter_mut().enumerate() {
                *l += 2.0 * e * self.g[k * m + j];
            }
        }
        (v, lf)
    }

    /// The second-order CLF towards the target: `V = |e|^2`, `e = f[pos] + k (s[pos] -
    /// target)`, with the turn towards the push where the model steers (`crate::guidance`);
    /// writes `Lg V` into `clf_lg` and returns `(V, Lf V)`.
    fn second_order_clf(&mut self, at: Site<'_>) -> (f64, f64) {
        let Site {
            params,
            model,
            fg,
            s,
            a_rl,
            ..
        } = at;
        let m = a_rl.len();
        let (mut v, mut lf) = (0.0, 0.0);
        // de_i/ds = J_f[pos_i, :] + k e_{pos_i}; g[pos, :] = 0 by construction.
        let k = params.clf_gain;
        jacobian_times(model, fg, s, &self.f, &mut self.jf, false);
        self.clf_error.fill(0.0);
        for (&p, &c) in params.pos.iter().zip(&self.aim.target) {
            let e = self.f[p] + k * (s[p] - c);
            self.clf_error[p] = e;
            v += e * e;
            lf += 2.0 * e * (self.jf[p] + k * self.f[p]);
        }
        jacobian_times(model, fg, s, &self.clf_error, &mut self.jt, true);
        for (j, l) in self.clf_lg.iter_mut().enumerate() {
            *l = 2.0
                * (0..s.len())
                    .map(|i| self.jt[i] * self.g[i * m + j])
                    .sum::<f64>();
        }
        let steered = params
            .heading
            .or_else(|| model.and_then(Dynamics::steered_heading));
        if let (true, Some(theta)) = (params.route && params.pos.len() == 2, steered) {
            let e = [self.clf_error[params.pos[0]], self.clf_error[params.pos[1]]];
            let row = (&self.g[theta * m..(theta + 1) * m], self.f[theta]);
            let turn = self
                .aim
                .turn_towards_push(e, s[theta], row, v, &mut self.clf_lg);
            let Turn { v: dv, lf: dlf } = turn;
            v += dv;
            lf += dlf;
            let car = params
                .speed
                .or_else(|| model.and_then(Dynamics::turns_only_moving));
            if let Some(speed) = car {
                let [p0, p1] = [params.pos[0], params.pos[1]];
                let target = &self.aim.target;
                let d = [k * (s[p0] - target[0]), k * (s[p1] - target[1])];
                // The fastest turn the CLF's own box drives at this speed, and its circle.
                let turn_rate = (0..m)
                    .map(|j| {
                        let (lo, hi) = self.clf_box(params, j);
                        self.g[theta * m + j].abs() * lo.abs().max(hi.abs())
                    })
                    .sum::<f64>();
                let car = Manoeuvre {
                    theta: s[theta],
                    speed: s[speed],
                    radius: (turn_rate > 0.0).then(|| s[speed].abs() / turn_rate),
                };
                let row = (&self.g[speed * m..(speed + 1) * m], self.f[speed]);
                let Turn { v: dv, lf: dlf } =
                    self.aim
                        .move_to_turn((d, [s[p0], s[p1]]), car, row, &mut self.clf_lg);
                v += dv;
                lf += dlf;
            }
        }
        (v, lf)
    }

    /// Writes the QP of the last [`Program::rows`] into `qp`; `relaxed` adds a slack
    /// `sigma_i >= 0` (cost `slack_penalty * weight_i`) to every barrier row.
    pub(super) fn assemble(
        &self,
        params: &ShieldParams,
        a_rl: &[f64],
        qp: &mut DenseQp,
        relaxed: Option<(&GiveWay, usize)>,
    ) {
        let m = a_rl.len();
        let (barriers, vars, has_goal) = (self.barriers(), self.vars(), self.has_goal);
        let cbf_vars = self.cbf_vars;
        let slacks = if relaxed.is_some() { barriers } else { 0 };
        let nv = vars + slacks;
        let delta = cbf_vars + self.clf_vars;
        qp.p_diag.clear();
        qp.p_diag.resize(nv, 0.0);
        qp.p_diag[..delta].fill(2.0);
        qp.c.clear();
        qp.c.resize(nv, 0.0);
        if has_goal {
            qp.c[delta] = params.k;
        }
        for (c, w) in qp.c[vars..].iter_mut().zip(&self.weights) {
            *c = params.slack_penalty * w;
        }
        qp.g.clear();
        qp.h.clear();
        for b in 0..barriers {
            let r = push_row(qp, nv, self.rhs[b]);
            for j in 0..m {
                let l = self.lg[b * m + j];
                if params.use_cbf {
                    r[j] = -l;
                }
                if has_goal {
                    r[cbf_vars + j] = -l;
                }
            }
            // A row above the level holds: its slack stays out of it (and at 0).
            if let Some((give_way, level)) = relaxed {
                if give_way.level(self.sources[b]) <= level {
                    r[vars + b] = -1.0;
                }
            }
        }
        if has_goal {
            let r = push_row(qp, nv, self.clf_rhs + self.delta_0);
            r[cbf_vars..delta].copy_from_slice(&self.clf_lg);
            r[delta] = -1.0;
            push_row(qp, nv, 0.0)[delta] = -1.0;
        }
        self.push_bounds(params, a_rl, qp, nv);
        for b in 0..slacks {
            push_row(qp, nv, 0.0)[vars + b] = -1.0;
        }
    }

    /// The box rows on `a_cbf` and `a_clf` (the CLF's widened by a released turn,
    /// [`Program::clf_box`]), the actuator limits on the applied action, then
    /// the round bound on `a_clf` (the gradient reads the limits' place), into `qp` of `nv`
    /// variables.
    fn push_bounds(&self, params: &ShieldParams, a_rl: &[f64], qp: &mut DenseQp, nv: usize) {
        let (m, cbf_vars, has_goal) = (a_rl.len(), self.cbf_vars, self.has_goal);
        for j in (0..m).filter(|_| params.use_cbf) {
            let bounds = &params.cbf_bounds;
            push_row(qp, nv, bounds.hi[j])[j] = 1.0;
            push_row(qp, nv, -bounds.lo[j])[j] = -1.0;
        }
        for j in (0..m).filter(|_| has_goal) {
            let (lo, hi) = self.clf_box(params, j);
            push_row(qp, nv, hi)[cbf_vars + j] = 1.0;
            push_row(qp, nv, -lo)[cbf_vars + j] = -1.0;
        }
        if let Some(bounds) = &params.action_bounds {
            for (sign, limit) in [(1.0, &bounds.hi), (-1.0, &bounds.lo)] {
                for j in 0..m {
                    let r = push_row(qp, nv, sign * (limit[j] - a_rl[j]));
                    if params.use_cbf {
                        r[j] = sign;
                    }
                    if has_goal {
                        r[cbf_vars + j] = sign;
                    }
                }
            }
        }
        // After the actuator limits, whose place the gradient reads: constant rows on a_clf.
        if let (true, Some(round)) = (has_goal, &params.clf_round) {
            let [i, j] = round.inputs;
            for (n, rhs) in round.rows() {
                let r = push_row(qp, nv, rhs);
                r[cbf_vars + i] = n[0];
                r[cbf_vars + j] = n[1];
            }
        }
    }
}
