//! The shield's parameters: [`ShieldParams`] and its builder, the user's [`Barrier`]s, the
//! [`Bounds`] of the corrections and the [`SolverChoice`].

use crate::predicate::Predicate;
use crate::spec::Spec;

use super::ShieldError;

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

    /// The name of barrier `i` of a plain list of predicates: `h{i}`.
    pub fn default_name(i: usize) -> String {
        format!("h{i}")
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
    /// The largest CLF cost `k` Clarabel alone is given: above it its interior point cannot
    /// resolve `k delta` against `|a|^2` (on Channel-v0, 68 of 300 random steps FAILED at
    /// k = 3e11, returning `a_rl` uncorrected; none up to 1e11). [`SolverChoice::Auto`]'s
    /// active set is exact far beyond it.
    pub const CLARABEL_MAX_K: f64 = 1e11;

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

/// Lower and upper bounds per input (length m, finite, `lo <= hi`), or one pair for every
/// input ([`Bounds::uniform`]) that the shield broadcasts to its m inputs when it is built.
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    /// Lower bounds.
    pub lo: Vec<f64>,
    /// Upper bounds.
    pub hi: Vec<f64>,
    /// Given once for every input: `lo` and `hi` hold one value each until the shield, which
    /// knows m, broadcasts them.
    pub uniform: bool,
}

impl Bounds {
    /// One `(lo, hi)` per input.
    pub fn new(lo: Vec<f64>, hi: Vec<f64>) -> Self {
        Bounds {
            lo,
            hi,
            uniform: false,
        }
    }

    /// The same `(lo, hi)` for every input, however many the shield has.
    pub fn uniform(lo: f64, hi: f64) -> Self {
        Bounds {
            lo: vec![lo],
            hi: vec![hi],
            uniform: true,
        }
    }

    /// The number of inputs these bounds are given for (`None` when uniform).
    pub fn inputs(&self) -> Option<usize> {
        (!self.uniform).then_some(self.lo.len())
    }

    /// Uniform bounds repeated for `m` inputs; bounds per input are left as given. An `m`
    /// whose bounds cannot fit in memory is an error, not an abort.
    pub(super) fn broadcast(&mut self, what: &str, m: usize) -> Result<(), ShieldError> {
        if self.uniform && self.lo.len() == 1 && self.hi.len() == 1 {
            self.lo = crate::alloc::try_vec(what, m, self.lo[0])?;
            self.hi = crate::alloc::try_vec(what, m, self.hi[0])?;
            self.uniform = false;
        }
        Ok(())
    }

    /// Checks lengths, finiteness and order; `what` names the argument in the message.
    pub(super) fn check(&self, what: &str, m: usize) -> Result<(), ShieldError> {
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

/// A round (Euclidean) bound on two inputs of the CLF's correction,
/// `|(a_clf[i], a_clf[j])| <= radius`, beside the per-axis box: a bound that means a speed then
/// does not depend on which way the world faces. The QP holds it as the regular polygon of
/// [`RoundBound::SIDES`] sides inscribed in the circle, whose sides come within
/// `1 - cos(pi / SIDES)` (1.9%) of the radius: at most 1.9% less than the radius in some
/// directions, never more than it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoundBound {
    /// The two inputs (distinct, each `< m`).
    pub inputs: [usize; 2],
    /// The radius (finite, > 0).
    pub radius: f64,
}

impl RoundBound {
    /// Sides of the inscribed polygon.
    pub const SIDES: usize = 16;

    /// Checks the inputs against `m` and the radius.
    pub(super) fn check(&self, what: &str, m: usize) -> Result<(), ShieldError> {
        let [i, j] = self.inputs;
        if i == j || i >= m || j >= m {
            return Err(ShieldError::Config(format!(
                "{what}: inputs ({i}, {j}) must be two distinct inputs below m = {m}"
            )));
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(ShieldError::Config(format!(
                "{what}: radius = {}: expected a finite number > 0",
                self.radius
            )));
        }
        Ok(())
    }

    /// The polygon's rows `n_k . (a_i, a_j) <= radius cos(pi / SIDES)`, as `(n_k, rhs)`.
    pub fn rows(&self) -> impl Iterator<Item = ([f64; 2], f64)> + '_ {
        let half = std::f64::consts::PI / Self::SIDES as f64;
        let rhs = self.radius * half.cos();
        (0..Self::SIDES).map(move |k| {
            let angle = (2 * k + 1) as f64 * half;
            ([angle.cos(), angle.sin()], rhs)
        })
    }
}

/// The shield's parameters (names as in the paper).
#[derive(Debug, Clone, PartialEq)]
pub struct ShieldParams {
    /// CBF class-K gain: `dh/dt + alpha h >= 0` (> 0). For a second-order (HOCBF) row it is
    /// the first gain: `psi_1 = dh/dt + alpha h`.
    pub alpha: f64,
    /// The HOCBF's second gain: `dpsi_1/dt + alpha2 psi_1 >= 0` (> 0), required when a barrier
    /// has relative degree 2 under the model (see `shield/order.rs`).
    pub alpha2: Option<f64>,
    /// The plant's time step, when the shielded action is held for `dt` and the state is
    /// sampled after it (an explicit Euler step of the model, [`crate::Dynamics::euler_step`]).
    /// Set, the barrier rows hold the sampled states (`shield/sampled.rs`): `alpha dt` and
    /// `alpha2 dt` must then be at most 1. `None` (the default): the continuous-time rows,
    /// which hold only as `dt -> 0`.
    pub dt: Option<f64>,
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
    /// The range of the RL action, if known. With the CBF on, [`Shield::new`](super::Shield::new) checks that the
    /// CBF box can cancel every RL action in it plus every CLF correction (so applying no
    /// action, e.g. stopping, stays feasible and the barrier rows never need slack for want of
    /// authority), and each call refuses an `a_rl` outside it.
    pub rl_bounds: Option<Bounds>,
    /// Extra user barriers (the paper's `h(s)`), kept positive, with their names.
    pub barriers: Vec<Barrier>,
    /// State dimensions the CLF drives to the goal. Empty (the default): the model's position
    /// ([`Structure::position`](crate::Structure::position)), or
    /// [`ShieldParams::DEFAULT_POS`] for a model without one, filled in when the shield is
    /// built.
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
    /// The order in which barriers give way when the QP cannot hold them all: user barrier
    /// names and atoms of the task (a safe-set literal's atom), first named gives way first;
    /// the barriers not named give way last (`shield/give_way.rs`). Empty (the default): all
    /// at once, shared by the slack weights.
    pub give_way: Vec<String>,
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
    /// Whether the CLF's target is routed around the discs the shield keeps the state out of
    /// (its avoid literals and user barriers; see [`crate::route`]), instead of pointing
    /// straight at the goal, where the CLF-CBF QP would park the robot in front of an
    /// obstacle. On by default; with nothing in the way the target is the goal.
    pub route: bool,
    /// How far the router keeps from each disc, relative to its radius (>= 0; default
    /// [`crate::route::DEFAULT_CLEARANCE`]).
    pub route_clearance: f64,
    /// The state dimension of the robot's heading, when a turn input reaches the position only
    /// through it: routing's CLF then turns the heading towards where it pushes
    /// (`guidance/aim.rs`). `None` takes the built-in model's
    /// ([`Dynamics::steered_heading`](crate::Dynamics::steered_heading)); a custom model
    /// declares its own here.
    pub heading: Option<usize>,
    /// The state dimension of the robot's speed along its heading, when it turns only while
    /// moving (a car: its turn rate is the speed times the steering): routing's CLF then asks
    /// for the speed a turn needs, backing up where driving on would only circle the target
    /// (`guidance/aim.rs`). `None` takes the built-in model's
    /// ([`Dynamics::turns_only_moving`](crate::Dynamics::turns_only_moving)); a custom model
    /// declares its own here, with its `heading`.
    pub speed: Option<usize>,
    /// A round bound on two inputs of `a_clf`, beside `clf_bounds` (see [`RoundBound`]).
    pub clf_round: Option<RoundBound>,
    /// The number of inputs m, for a shield whose model does not say it (no model, and
    /// uniform `cbf_bounds`); when a model is given it must agree (see
    /// [`ShieldParams::input_count`]).
    pub inputs: Option<usize>,
}

impl ShieldParams {
    /// Default cost per unit of barrier slack in the relaxed problem.
    pub const DEFAULT_SLACK_PENALTY: f64 = 1e6;
    /// Default barrier margin: `h` is kept above this, so atoms (`rho > 0`) stay true.
    pub const DEFAULT_MARGIN: f64 = 1e-6;
    /// CLF dimensions for a model that names no position: `s[0], s[1]`.
    pub const DEFAULT_POS: [usize; 2] = [0, 1];
    /// Default gain of the second-order CLF.
    pub const DEFAULT_CLF_GAIN: f64 = 1.0;

    /// The gains and boxes every shield needs; everything else at its default: no actuator
    /// limits, no user barriers, the CLF on the model's position, both CBF and CLF on,
    /// [`SolverChoice::Auto`], [`ShieldParams::DEFAULT_SLACK_PENALTY`] and
    /// [`ShieldParams::DEFAULT_MARGIN`]. Validated by [`Shield::new`](super::Shield::new).
    pub fn new(alpha: f64, c3: f64, k: f64, cbf_bounds: Bounds, clf_bounds: Bounds) -> Self {
        ShieldParams {
            alpha,
            alpha2: None,
            dt: None,
            c3,
            k,
            cbf_bounds,
            clf_bounds,
            action_bounds: None,
            rl_bounds: None,
            barriers: Vec::new(),
            pos: Vec::new(),
            clf_gain: Self::DEFAULT_CLF_GAIN,
            use_cbf: true,
            use_clf: true,
            solver: SolverChoice::Auto,
            slack_penalty: Self::DEFAULT_SLACK_PENALTY,
            give_way: Vec::new(),
            margin: Self::DEFAULT_MARGIN,
            preserve_progress: true,
            disturbance: Vec::new(),
            route: true,
            route_clearance: crate::guidance::DEFAULT_CLEARANCE,
            heading: None,
            speed: None,
            clf_round: None,
            inputs: None,
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

    /// The order in which barriers give way (see [`ShieldParams::give_way`]).
    pub fn with_give_way(mut self, names: Vec<String>) -> Self {
        self.give_way = names;
        self
    }

    /// The plant's time step (see [`ShieldParams::dt`]).
    pub fn with_dt(mut self, dt: Option<f64>) -> Self {
        self.dt = dt;
        self
    }

    /// Whether the CLF's target is routed (see [`ShieldParams::route`]), and the router's
    /// clearance relative to each disc's radius.
    pub fn with_route(mut self, on: bool, clearance: f64) -> Self {
        self.route = on;
        self.route_clearance = clearance;
        self
    }

    /// A round bound on two inputs of the CLF's correction (see [`RoundBound`]).
    pub fn with_clf_round(mut self, round: Option<RoundBound>) -> Self {
        self.clf_round = round;
        self
    }

    /// The heading a turn input steers (see [`ShieldParams::heading`]).
    pub fn with_heading(mut self, heading: Option<usize>) -> Self {
        self.heading = heading;
        self
    }

    /// The speed of a robot that turns only while moving (see [`ShieldParams::speed`]).
    pub fn with_speed(mut self, speed: Option<usize>) -> Self {
        self.speed = speed;
        self
    }

    /// The number of inputs, for a shield without a model (see [`ShieldParams::inputs`]).
    pub fn with_inputs(mut self, inputs: Option<usize>) -> Self {
        self.inputs = inputs;
        self
    }

    /// The shield's number of inputs m: the model's (`model`, which [`ShieldParams::inputs`]
    /// must match when given), else [`ShieldParams::inputs`], else the length of per-input
    /// `cbf_bounds`. Uniform bounds alone do not say it.
    pub fn input_count(&self, model: Option<usize>) -> Result<usize, ShieldError> {
        match (model, self.inputs) {
            (Some(m), Some(given)) if given != m => Err(ShieldError::Config(format!(
                "inputs = {given}, but the model has {m} inputs"
            ))),
            (Some(m), _) => Ok(m),
            (None, Some(0)) => Err(ShieldError::Config(
                "inputs: expected at least 1, got 0".into(),
            )),
            (None, Some(given)) => Ok(given),
            (None, None) => self.cbf_bounds.inputs().ok_or_else(|| {
                ShieldError::Config(
                    "cbf_bounds: without a model the number of inputs is not known from scalar \
                     bounds; pass inputs=m, or per-input bounds ([lo_1, ..., lo_m], \
                     [hi_1, ..., hi_m])"
                        .into(),
                )
            }),
        }
    }

    /// Every uniform bound repeated for `m` inputs.
    pub(super) fn broadcast(&mut self, m: usize) -> Result<(), ShieldError> {
        self.cbf_bounds.broadcast("cbf_bounds", m)?;
        self.clf_bounds.broadcast("clf_bounds", m)?;
        if let Some(b) = &mut self.action_bounds {
            b.broadcast("action_bounds", m)?;
        }
        if let Some(b) = &mut self.rl_bounds {
            b.broadcast("rl_bounds", m)?;
        }
        Ok(())
    }

    /// The gain of the second-order CLF.
    pub fn with_clf_gain(mut self, clf_gain: f64) -> Self {
        self.clf_gain = clf_gain;
        self
    }
}

impl ShieldParams {
    /// Checks the parameters on their own and for a system of `m` inputs shielding the task of
    /// `spec` (with `pos` set: [`Shield::new`](super::Shield::new) fills in an empty one first): every gain and weight a finite number > 0, `margin` > 0, the routing clearance
    /// and the disturbance bounds >= 0, every box of `m` values and the RL box inside what the
    /// corrections can cancel, `pos` distinct dimensions matching the goal balls, and a spec
    /// with predicates. Each failure names the parameter ([`ShieldError::Config`]).
    pub fn validate(&self, m: usize, spec: &Spec) -> Result<(), ShieldError> {
        self.check_gains()?;
        self.check_settings()?;
        self.check_boxes(m)?;
        self.check_layout(spec)
    }

    /// The gains: each finite and > 0, `dt` with them, `k` within what the solver resolves.
    fn check_gains(&self) -> Result<(), ShieldError> {
        positive("alpha", self.alpha)?;
        if let Some(a2) = self.alpha2 {
            positive("alpha2", a2)?;
        }
        if let Some(dt) = self.dt {
            self.check_dt(dt)?;
        }
        positive("clf_gain", self.clf_gain)?;
        positive("c3", self.c3)?;
        positive("k", self.k)?;
        if self.solver == SolverChoice::Clarabel && self.k > SolverChoice::CLARABEL_MAX_K {
            return Err(ShieldError::Config(format!(
                "k = {:e} with solver = \"clarabel\": above {:e} Clarabel alone fails on \
                 many steps (each then returns a_rl uncorrected); use solver = \"auto\" \
                 (its exact active set is measured to 1e16) or k <= {:e}",
                self.k,
                SolverChoice::CLARABEL_MAX_K,
                SolverChoice::CLARABEL_MAX_K
            )));
        }
        Ok(())
    }

    /// The weights, the routing clearance, the margin and the disturbance bounds.
    fn check_settings(&self) -> Result<(), ShieldError> {
        positive("slack_penalty", self.slack_penalty)?;
        if let Some(h) = self.heading.filter(|h| self.pos.contains(h)) {
            return Err(ShieldError::Config(format!(
                "heading = {h}: it is one of the CLF's position dimensions pos = {:?}; the \
                 heading is the angle a turn input steers",
                self.pos
            )));
        }
        if let Some(v) = self.speed {
            if self.pos.contains(&v) || self.heading == Some(v) {
                return Err(ShieldError::Config(format!(
                    "speed = {v}: it is one of the CLF's position dimensions pos = {:?} or the \
                     heading {:?}; the speed is the state of the robot's speed along its heading",
                    self.pos, self.heading
                )));
            }
        }
        if !(self.route_clearance.is_finite() && self.route_clearance >= 0.0) {
            return Err(ShieldError::Config(format!(
                "route_clearance = {}: expected a finite number >= 0 (a fraction of each \
                 obstacle's radius)",
                self.route_clearance
            )));
        }
        if !(self.margin.is_finite() && self.margin > 0.0) {
            return Err(ShieldError::Config(format!(
                "margin = {}: expected a finite number > 0 (an atom holds only while its \
                 robustness is > 0, so barriers held at h >= 0 would let a state settle at \
                 h = 0, or just below it after a discrete step, where the task counts it \
                 violated)",
                self.margin
            )));
        }
        for (i, &(d, w)) in self.disturbance.iter().enumerate() {
            if !(w.is_finite() && w >= 0.0) {
                return Err(ShieldError::Config(format!(
                    "disturbance bound of dimension {d} = {w}: expected a finite number >= 0"
                )));
            }
            if self.disturbance[..i].iter().any(|&(e, _)| e == d) {
                return Err(ShieldError::Config(format!(
                    "disturbance: dimension {d} is given twice"
                )));
            }
        }
        Ok(())
    }

    /// The barriers' slack weights and every box of `m` values (the RL box inside what the
    /// corrections can cancel).
    fn check_boxes(&self, m: usize) -> Result<(), ShieldError> {
        for b in &self.barriers {
            positive(
                &format!("slack weight of barrier {:?}", b.name),
                b.slack_weight,
            )?;
        }
        if m == 0 {
            return Err(ShieldError::Config(
                "the system has no inputs (bounds are empty)".into(),
            ));
        }
        self.cbf_bounds.check("cbf_bounds", m)?;
        if let Some(round) = &self.clf_round {
            round.check("clf_round", m)?;
        }
        self.clf_bounds.check("clf_bounds", m)?;
        if let Some(b) = &self.action_bounds {
            b.check("action_bounds", m)?;
        }
        if let Some(rl) = &self.rl_bounds {
            rl.check("rl_bounds", m)?;
            if self.use_cbf {
                check_cover(self, rl)?;
            }
        }
        Ok(())
    }

    /// `pos` distinct dimensions matching the goal balls, and a spec with predicates.
    fn check_layout(&self, spec: &Spec) -> Result<(), ShieldError> {
        if self.pos.is_empty() || (1..self.pos.len()).any(|i| self.pos[..i].contains(&self.pos[i]))
        {
            return Err(ShieldError::Config(format!(
                "pos = {:?}: expected at least one distinct state dimension",
                self.pos
            )));
        }
        if !spec.is_bound() {
            return Err(ShieldError::Config(
                "the automaton was built from a formula alone (no predicates): build it from a \
                 Spec with predicates to shield states"
                    .into(),
            ));
        }
        if self.use_clf {
            for (name, p) in spec.atoms().iter().zip(spec.predicates()) {
                for leaf in crate::region::alternatives(p)
                    .into_iter()
                    .flatten()
                    .flatten()
                {
                    if let Predicate::Ball(ball) = leaf {
                        if ball.pos().len() != self.pos.len() {
                            return Err(ShieldError::Config(format!(
                                "pos has {} dimensions but the goal ball {name:?} has {}; the \
                                 CLF drives s[pos] to points inside balls, so they must match",
                                self.pos.len(),
                                ball.pos().len()
                            )));
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

impl ShieldParams {
    /// `dt` finite and > 0, and every class-K gain at most `1 / dt`: the sampled condition
    /// `h(s') >= (1 - alpha dt) h(s)` keeps `h >= 0` only while its factor is >= 0.
    fn check_dt(&self, dt: f64) -> Result<(), ShieldError> {
        positive("dt", dt)?;
        let gains = [("alpha", Some(self.alpha)), ("alpha2", self.alpha2)];
        for (what, gain) in gains {
            if let Some(gain) = gain.filter(|g| g * dt > 1.0) {
                return Err(ShieldError::Config(format!(
                    "{what} = {gain} with dt = {dt}: {what} * dt = {} > 1, so one step could \
                     carry the sampled state across a barrier; choose {what} <= 1 / dt = {}",
                    gain * dt,
                    1.0 / dt
                )));
            }
        }
        Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `validate` alone, without building a shield: each bad setting is refused by name.
    #[test]
    fn validate_names_the_bad_setting() {
        let spec = crate::fixtures::task_spec();
        let b = |lo: f64, hi: f64| Bounds::new(vec![lo; 2], vec![hi; 2]);
        // validate reads a set pos (Shield::new fills in an empty one from the model).
        let good =
            ShieldParams::new(2.0, 1.0, 1e4, b(-6.0, 6.0), b(-0.5, 0.5)).with_pos(vec![0, 1]);
        good.validate(2, &spec).unwrap();
        let err = |p: ShieldParams, m: usize| p.validate(m, &spec).unwrap_err().to_string();
        let mut bad = good.clone();
        bad.alpha = -1.0;
        assert!(err(bad, 2).contains("alpha"));
        let mut bad = good.clone();
        bad.margin = 0.0;
        assert!(err(bad, 2).contains("margin"));
        assert!(err(good.clone(), 3).contains("cbf_bounds"));
        assert!(err(good.clone(), 0).contains("no inputs"));
        let unbound = Spec::from_formula("F a").unwrap();
        let alone = good.validate(2, &unbound).unwrap_err().to_string();
        assert!(alone.contains("formula alone"), "{alone}");
        // A CLF cost Clarabel alone cannot resolve; the same k under Auto is accepted.
        let mut bad = good.clone().with_solver(SolverChoice::Clarabel);
        bad.k = 3e11;
        let msg = err(bad.clone(), 2);
        assert!(
            msg.contains("k = 3e11") && msg.contains("\"auto\""),
            "{msg}"
        );
        bad.k = SolverChoice::CLARABEL_MAX_K;
        bad.validate(2, &spec).unwrap();
        bad.solver = SolverChoice::Auto;
        bad.k = 1e16;
        bad.validate(2, &spec).unwrap();
    }

    #[test]
    fn the_round_bound_is_the_inscribed_polygon() {
        let round = RoundBound {
            inputs: [0, 1],
            radius: 2.0,
        };
        let inner = 2.0 * (std::f64::consts::PI / RoundBound::SIDES as f64).cos();
        for k in 0..720 {
            let (s, c) = (k as f64 * std::f64::consts::PI / 360.0).sin_cos();
            let holds = |r: f64| {
                round
                    .rows()
                    .all(|(n, h)| n[0] * r * c + n[1] * r * s <= h + 1e-12)
            };
            // Within 1.9% of the radius in every direction, never past it.
            assert!(holds(inner), "direction {k}");
            assert!(!holds(2.0 * (1.0 + 1e-9)), "direction {k}");
        }
        assert!(round.check("r", 2).is_ok());
        assert!(round.check("r", 1).is_err());
    }

    #[test]
    fn a_barrier_keeps_its_side_whatever_its_name() {
        let p = Predicate::halfspace(vec![1.0], 0.0).unwrap();
        let s = [2.0];
        assert_eq!(Barrier::inside("!wall", p.clone()).value(&s), 2.0);
        assert_eq!(Barrier::outside("wall", p).value(&s), -2.0);
        assert_eq!(Barrier::default_name(3), "h3");
    }

    /// The number of inputs: the model's, else `inputs`, else per-input bounds; uniform
    /// bounds are repeated for it, and a count past memory is an error, not an abort.
    #[test]
    fn inputs_are_counted_and_uniform_bounds_broadcast() {
        let uniform = || {
            ShieldParams::new(
                1.0,
                1.0,
                1.0,
                Bounds::uniform(-1.0, 1.0),
                Bounds::uniform(-2.0, 2.0),
            )
        };
        assert_eq!(uniform().input_count(Some(3)).unwrap(), 3);
        assert_eq!(uniform().with_inputs(Some(4)).input_count(None).unwrap(), 4);
        let msg = |r: Result<usize, ShieldError>| r.unwrap_err().to_string();
        assert!(msg(uniform().input_count(None)).contains("pass inputs=m"));
        assert!(msg(uniform().with_inputs(Some(0)).input_count(None)).contains("at least 1"));
        assert!(msg(uniform().with_inputs(Some(2)).input_count(Some(3)))
            .contains("inputs = 2, but the model has 3 inputs"));
        let per_input = ShieldParams::new(
            1.0,
            1.0,
            1.0,
            Bounds::new(vec![-1.0; 5], vec![1.0; 5]),
            Bounds::uniform(-2.0, 2.0),
        );
        assert_eq!(per_input.input_count(None).unwrap(), 5);

        let mut p = uniform().with_action_bounds(Some(Bounds::uniform(-3.0, 3.0)));
        p.broadcast(3).unwrap();
        assert_eq!(p.cbf_bounds, Bounds::new(vec![-1.0; 3], vec![1.0; 3]));
        assert_eq!(p.clf_bounds, Bounds::new(vec![-2.0; 3], vec![2.0; 3]));
        assert_eq!(
            p.action_bounds,
            Some(Bounds::new(vec![-3.0; 3], vec![3.0; 3]))
        );
        assert!(p.rl_bounds.is_none());
        // Per-input bounds are left as given (their length is checked by validate).
        let mut q = per_input.clone();
        q.broadcast(3).unwrap();
        assert_eq!(q.cbf_bounds, per_input.cbf_bounds);
        let huge = uniform().broadcast(usize::MAX / 2).unwrap_err().to_string();
        assert!(
            huge.contains("cbf_bounds") && huge.contains("do not fit in memory"),
            "{huge}"
        );
    }
}
