//! The task monitor: the automaton along one episode, in one object. It holds the automaton
//! state `q`, the last reading of the atoms and the task reward's state, so that one call per
//! step ([`Monitor::advance`]) gives the next FSA state, the task reward, acceptance, the trap
//! and the CLF goal, and the shield (`Shield::filter_monitor`) reuses the same
//! reading: the atoms are evaluated once per step.

use std::sync::Arc;

use rayon::prelude::*;

use crate::automaton::{Automaton, Reading, MAX_ATOMS};
use crate::check::{check_finite, check_state, check_state_rows, SCALAR};
use crate::cnf::Literal;
use crate::error::{AutomatonError, InputError};
use crate::guidance::{Routed, Router, Routing, Scratch};
use crate::progress::ProgressReward;

/// The task reward's defaults, owned by Eq. 5A1 (`automaton::reward`), here too because a
/// monitor is where most callers meet them.
pub use crate::automaton::{DEFAULT_C_R, DEFAULT_TRAP_PENALTY};

/// The task reward a monitor pays.
#[derive(Debug, Clone)]
pub enum TaskReward {
    /// The progress-aware reward (see [`ProgressReward`]) and the automaton it was built for,
    /// which must be the monitor's.
    Progress(ProgressReward, Arc<Automaton>),
    /// The paper's Eq. 5A1 with weight `c_r`; every step in the trap pays `trap_penalty`.
    Paper {
        /// The weight of the trap-avoidance term (> 0).
        c_r: f64,
        /// The reward of a step in the trap (finite).
        trap_penalty: f64,
    },
}

/// What one step of the task gives (see [`Monitor::advance`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaskStep {
    /// The FSA state after reading the state.
    pub q: usize,
    /// The task reward of the transition (0 at a reset).
    pub reward: f64,
    /// Whether `q` is accepting (the task is done).
    pub accepted: bool,
    /// Whether `q` is the trap (the task can no longer be done).
    pub trapped: bool,
}

/// What a monitor holds between steps, as data ([`Monitor::snapshot`], [`Monitor::restore`]):
/// the atoms' reading and the CLF goal follow from the state read.
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorState {
    /// The FSA state.
    pub q: usize,
    /// The progress reward's potential at the last state.
    pub phi: f64,
    /// Whether an episode has started.
    pub started: bool,
    /// The last state read (empty before the first reset).
    pub s: Vec<f64>,
}

/// The automaton along one episode (see the module docs). Allocation-free per step once the
/// first state has been read.
#[derive(Debug, Clone)]
pub struct Monitor {
    automaton: Arc<Automaton>,
    reward: TaskReward,
    q: usize,
    phi: f64,
    started: bool,
    s: Vec<f64>,
    rho: [f64; MAX_ATOMS],
    goal: Vec<f64>,
    has_goal: bool,
    /// The way to the goal at the last state: routed with [`Monitor::route_with`].
    distance: Option<f64>,
    route: Option<Box<Route>>,
}

/// A monitor's routing and its scratch.
#[derive(Debug, Clone)]
struct Route {
    routing: Routing,
    router: Router,
    safe: Vec<(Literal, f64)>,
    scratch: Scratch,
    /// The routed decision at the last state (when the goal is a point of its plane).
    target: Option<Routed>,
}

impl Monitor {
    /// A monitor of `automaton` paying `reward`; checks that a progress reward belongs to this
    /// automaton and that the paper reward's weights are finite (`c_r > 0`).
    pub fn new(automaton: Arc<Automaton>, reward: TaskReward) -> Result<Self, AutomatonError> {
        match &reward {
            TaskReward::Progress(_, of) if !Arc::ptr_eq(of, &automaton) => {
                return Err(InputError::Value {
                    what: "progress".into(),
                    expected: "a ProgressReward of the monitor's automaton".into(),
                    got: "one of another automaton".into(),
                }
                .into());
            }
            TaskReward::Paper { c_r, trap_penalty } => {
                if !(c_r.is_finite() && *c_r > 0.0) {
                    return Err(InputError::Value {
                        what: "c_r".into(),
                        expected: "a finite weight > 0".into(),
                        got: c_r.to_string(),
                    }
                    .into());
                }
                check_finite("trap_penalty", &[*trap_penalty], SCALAR)?;
            }
            TaskReward::Progress(..) => {}
        }
        let q = automaton.initial();
        Ok(Monitor {
            automaton,
            reward,
            q,
            phi: 0.0,
            started: false,
            s: Vec::new(),
            rho: [0.0; MAX_ATOMS],
            goal: Vec::new(),
            has_goal: false,
            distance: None,
            route: None,
        })
    }

    /// Starts an episode at `s0`: `q = step(initial, s0)`, the potential back to 0 (reward 0).
    pub fn reset(&mut self, s0: &[f64]) -> Result<TaskStep, AutomatonError> {
        self.check("s0", s0)?;
        Ok(self.reset_checked(s0))
    }

    /// [`Monitor::reset`] of a state already checked with [`Monitor::check`].
    fn reset_checked(&mut self, s0: &[f64]) -> TaskStep {
        self.read(s0);
        self.q = self.reading().step(self.automaton.initial());
        self.phi = 0.0;
        self.started = true;
        let _ = self.update_goal();
        self.report(0.0)
    }

    /// Reads `s_next`: moves `q` to `step(s_next, q)` and returns the reward of that transition.
    pub fn advance(&mut self, s_next: &[f64]) -> Result<TaskStep, AutomatonError> {
        if !self.started {
            return Err(AutomatonError::NotReset { row: None });
        }
        self.check("s_next", s_next)?;
        Ok(self.advance_checked(s_next))
    }

    /// [`Monitor::advance`] of a started monitor and a state checked with [`Monitor::check`].
    fn advance_checked(&mut self, s_next: &[f64]) -> TaskStep {
        self.read(s_next);
        let q = self.q;
        let q_next = self.reading().step(q);
        self.q = q_next;
        // The goal at (s', q') is the shield's next goal and the progress reward's goal term.
        let distance = self.update_goal();
        let reading = self.reading();
        let (reward, phi) = match &self.reward {
            TaskReward::Progress(p, _) => {
                let phi_next = p.potential_at(&reading, q_next, distance);
                let r = p.reward(&self.automaton, q, q_next, self.phi, phi_next);
                (r, phi_next)
            }
            TaskReward::Paper { trap_penalty, .. } if Some(q) == self.automaton.trap() => {
                (*trap_penalty, self.phi)
            }
            TaskReward::Paper { c_r, .. } => (reading.reward(q, *c_r), self.phi),
        };
        self.phi = phi;
        self.report(reward)
    }

    /// Checks a state for this monitor's automaton: its length (the error names it `{what}
    /// length`) and finiteness.
    fn check(&self, what: &str, s: &[f64]) -> Result<(), AutomatonError> {
        Ok(check_state(what, s, self.automaton.spec().state_len()?)?)
    }

    /// Reads the atoms of a checked state into the monitor (the state is copied into a buffer
    /// that steady steps reuse).
    fn read(&mut self, s: &[f64]) {
        let reading = self.automaton.read_validated(s);
        let rho = reading.rho();
        self.rho[..rho.len()].copy_from_slice(rho);
        self.s.clear();
        self.s.extend_from_slice(s);
    }

    /// Places the CLF goal of `q` at the last state read; returns the way to it (routed
    /// around the discs of `q`'s safe set with [`Monitor::route_with`], when the goal is a
    /// point of the routing's plane).
    fn update_goal(&mut self) -> Option<f64> {
        let reading = Reading::from_parts(&self.automaton, &self.s, self.rho);
        let found = reading.goal_distance_in(self.q, &mut self.goal);
        if let Some(route) = self.route.as_deref_mut() {
            route.target = None;
        }
        let distance = match (found, self.route.as_deref_mut()) {
            (Some((_, dims)), Some(route)) if dims == route.routing.pos => {
                let goal = [self.goal[0], self.goal[1]];
                let Route {
                    routing,
                    router,
                    safe,
                    scratch,
                    target,
                } = route;
                let routed = routing.target(&reading, self.q, goal, router, (safe, scratch));
                *target = Some(routed);
                // The goal the way leads to: Eq. 5B1's, its free part, or another that can be
                // reached (`crate::guidance`).
                self.goal.copy_from_slice(&routed.goal);
                let (p, aim) = (
                    [self.s[routing.pos[0]], self.s[routing.pos[1]]],
                    routed.target,
                );
                Some((p[0] - aim[0]).hypot(p[1] - aim[1]))
            }
            (found, _) => found.map(|(d, _)| d),
        };
        self.has_goal = distance.is_some();
        self.distance = distance;
        distance
    }

    /// Measures the way to the goal as `routing` drives it (a shield's
    /// `Shield::routing`): the progress reward's goal term and
    /// [`Monitor::goal_distance`] then read the routed way left instead of the straight
    /// distance. `None` goes back to the straight distance. Takes effect at the next state read.
    pub fn route_with(&mut self, routing: Option<Routing>) {
        self.route = routing.map(|routing| {
            Box::new(Route {
                routing,
                router: Router::default(),
                safe: Vec::new(),
                scratch: Scratch::default(),
                target: None,
            })
        });
    }

    /// The target `routing` aims the CLF at from the last state, when this monitor routes
    /// exactly so (then a shield need not plan the same way again).
    pub(crate) fn routed_target(&self, routing: &Routing) -> Option<Routed> {
        let route = self.route.as_deref()?;
        (route.routing == *routing)
            .then_some(route.target)
            .flatten()
    }

    /// The way from the last state to the CLF goal: the straight distance in the goal's space,
    /// or, routed ([`Monitor::route_with`]), the length of the router's way around the discs.
    /// `None` without a goal.
    pub fn goal_distance(&self) -> Option<f64> {
        self.distance
    }

    fn report(&self, reward: f64) -> TaskStep {
        TaskStep {
            q: self.q,
            reward,
            accepted: self.automaton.is_accepting(self.q),
            trapped: Some(self.q) == self.automaton.trap(),
        }
    }

    /// The monitor's state, as data.
    pub fn snapshot(&self) -> MonitorState {
        MonitorState {
            q: self.q,
            phi: self.phi,
            started: self.started,
            s: self.s.clone(),
        }
    }

    /// Puts the monitor where [`Monitor::snapshot`] found it (of a monitor of the same
    /// automaton): it reads the state again, so the atoms and the goal are as they were, bit
    /// for bit. Checked first: an error changes nothing.
    pub fn restore(&mut self, state: &MonitorState) -> Result<(), AutomatonError> {
        self.check_snapshot(state)?;
        self.restore_checked(state);
        Ok(())
    }

    fn check_snapshot(&self, state: &MonitorState) -> Result<(), AutomatonError> {
        self.automaton.check_state("q", state.q)?;
        check_finite("phi", &[state.phi], SCALAR)?;
        if state.started {
            self.check("s", &state.s)?;
        } else if !state.s.is_empty() {
            return Err(InputError::Value {
                what: "s".into(),
                expected: "no state before the first reset".into(),
                got: format!("{} values", state.s.len()),
            }
            .into());
        }
        Ok(())
    }

    fn restore_checked(&mut self, state: &MonitorState) {
        self.q = state.q;
        self.phi = state.phi;
        self.started = state.started;
        if state.started {
            self.read(&state.s);
            let _ = self.update_goal();
        } else {
            self.s.clear();
            self.has_goal = false;
            self.distance = None;
        }
    }

    /// The last state read, with its atoms (valid once an episode started).
    pub fn reading(&self) -> Reading<'_> {
        Reading::from_parts(&self.automaton, &self.s, self.rho)
    }

    /// The automaton monitored.
    pub fn automaton(&self) -> &Arc<Automaton> {
        &self.automaton
    }

    /// The task reward paid.
    pub fn task_reward(&self) -> &TaskReward {
        &self.reward
    }

    /// The current FSA state.
    pub fn q(&self) -> usize {
        self.q
    }

    /// The progress reward's potential `Phi` at the last state (0 for the paper's reward).
    pub fn phi(&self) -> f64 {
        self.phi
    }

    /// Whether an episode has started (`reset` was called).
    pub fn started(&self) -> bool {
        self.started
    }

    /// The last state read.
    pub fn state(&self) -> &[f64] {
        &self.s
    }

    /// The CLF goal of Eq. 5B1 at the last state and `q` (rank-aware), if there is one.
    pub fn goal(&self) -> Option<&[f64]> {
        self.has_goal.then_some(self.goal.as_slice())
    }
}

/// N task monitors of one automaton, stepped together: the batch twin of [`Monitor`] for vector
/// environments (no one-hot argmax to recover `q`: each row's monitor holds it). Large batches
/// run in parallel.
#[derive(Debug, Clone)]
pub struct MonitorBatch {
    /// The automaton every row watches (an empty batch still has one).
    automaton: Arc<Automaton>,
    monitors: Vec<Monitor>,
}

impl MonitorBatch {
    /// `count` monitors of `automaton` paying `reward` (see [`Monitor::new`]), none started.
    pub fn new(
        automaton: Arc<Automaton>,
        reward: TaskReward,
        count: usize,
    ) -> Result<Self, AutomatonError> {
        let monitor = Monitor::new(automaton.clone(), reward)?;
        Ok(MonitorBatch {
            automaton,
            monitors: crate::alloc::try_vec("num", count, monitor)?,
        })
    }

    /// The monitors, one per row.
    pub fn monitors(&self) -> &[Monitor] {
        &self.monitors
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.monitors.len()
    }

    /// [`Monitor::route_with`] for every row.
    pub fn route_with(&mut self, routing: Option<Routing>) {
        for monitor in &mut self.monitors {
            monitor.route_with(routing.clone());
        }
    }

    /// Every row's state, as data (see [`Monitor::snapshot`]).
    pub fn snapshot(&self) -> Vec<MonitorState> {
        self.monitors.iter().map(Monitor::snapshot).collect()
    }

    /// Puts every row where [`MonitorBatch::snapshot`] found it (one state per row). Checked
    /// first: an error changes no row.
    pub fn restore(&mut self, states: &[MonitorState]) -> Result<(), AutomatonError> {
        if states.len() != self.monitors.len() {
            return Err(InputError::Shape {
                what: "states".into(),
                expected: format!("{} monitor states, one per row", self.monitors.len()),
                got: states.len().to_string(),
            }
            .into());
        }
        for (monitor, state) in self.monitors.iter().zip(states) {
            monitor.check_snapshot(state)?;
        }
        for (monitor, state) in self.monitors.iter_mut().zip(states) {
            monitor.restore_checked(state);
        }
        Ok(())
    }

    /// The automaton every row watches.
    pub fn automaton(&self) -> &Arc<Automaton> {
        &self.automaton
    }

    /// Whether the batch has no rows.
    pub fn is_empty(&self) -> bool {
        self.monitors.is_empty()
    }

    /// Starts the episodes of `rows` at the rows of `states` (`(rows.len(), dim)` row-major,
    /// in the order of `rows`) and writes their steps into `out`. Everything is checked first:
    /// an error changes no monitor.
    pub fn reset(
        &mut self,
        rows: &[usize],
        states: &[f64],
        dim: usize,
        out: &mut Vec<TaskStep>,
    ) -> Result<(), AutomatonError> {
        self.check_states(states, dim, rows.len())?;
        for (i, &row) in rows.iter().enumerate() {
            if row >= self.monitors.len() || rows[..i].contains(&row) {
                return Err(InputError::Value {
                    what: format!("rows[{i}]"),
                    expected: format!("distinct rows of the batch (0..{})", self.monitors.len()),
                    got: row.to_string(),
                }
                .into());
            }
        }
        out.clear();
        for (&row, s) in rows.iter().zip(states.chunks(dim)) {
            out.push(self.monitors[row].reset_checked(s));
        }
        Ok(())
    }

    /// Advances every row's monitor on its row of `states` (`(len, dim)` row-major) and writes
    /// the steps into `out`; every monitor must have started. Checked first: an error changes
    /// no monitor.
    pub fn advance(
        &mut self,
        states: &[f64],
        dim: usize,
        out: &mut Vec<TaskStep>,
    ) -> Result<(), AutomatonError> {
        self.check_states(states, dim, self.monitors.len())?;
        if let Some(row) = self.monitors.iter().position(|m| !m.started) {
            return Err(InputError::Value {
                what: format!("row {row}"),
                expected: "a started episode (reset it first)".into(),
                got: "a monitor without one".into(),
            }
            .into());
        }
        let step = |(monitor, s): (&mut Monitor, &[f64])| monitor.advance_checked(s);
        if self.monitors.len() < crate::parallel::MIN_ROWS {
            out.clear();
            out.extend(self.monitors.iter_mut().zip(states.chunks(dim)).map(step));
        } else {
            let monitors = &mut self.monitors;
            crate::parallel::install(|| {
                monitors
                    .par_iter_mut()
                    .zip(states.par_chunks(dim))
                    .map(step)
                    .collect_into_vec(out);
            });
        }
        Ok(())
    }

    /// Checks `(rows, dim)` states for the automaton: shape, length and finiteness.
    fn check_states(&self, states: &[f64], dim: usize, rows: usize) -> Result<(), AutomatonError> {
        Ok(check_state_rows(
            states,
            dim,
            rows,
            self.automaton.spec().state_len()?,
        )?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::task_automaton;
    use crate::progress::ProgressParams;
    use crate::tests_support::seeded;
    use proptest::prelude::*;

    fn task() -> Arc<Automaton> {
        Arc::new(task_automaton())
    }

    #[test]
    fn a_routed_monitor_hands_its_target_only_to_the_same_routing() {
        let aut = task();
        let mut monitor = Monitor::new(
            aut.clone(),
            TaskReward::Paper {
                c_r: 1.0,
                trap_penalty: -100.0,
            },
        )
        .unwrap();
        let routing = Routing {
            pos: [0, 1],
            clearance: 0.2,
            avoid: Vec::new(),
            inside: Vec::new(),
            preserve_progress: false,
        };
        let s = [
            0.0, 0.0, 0.5, 2.0, 2.0, 3.0, 3.5, 8.0, 8.0, 20.0, 20.0, 20.0, -20.0,
        ];
        monitor.reset(&s).unwrap();
        assert_eq!(monitor.routed_target(&routing), None);
        monitor.route_with(Some(routing.clone()));
        monitor.reset(&s).unwrap();
        let target = monitor
            .routed_target(&routing)
            .expect("a goal in the plane")
            .target;
        let way = (s[0] - target[0]).hypot(s[1] - target[1]);
        assert_eq!(monitor.goal_distance(), Some(way));
        let other = Routing {
            clearance: 0.3,
            ..routing
        };
        assert_eq!(monitor.routed_target(&other), None);
    }

    proptest! {
        #![proptest_config(seeded(64))]

        /// The monitor equals the separate calls it replaces: `step`, the progress reward's
        /// `advance`, Eq. 5A1's `reward` and the automaton's `goal`, on random episodes.
        #[test]
        fn monitor_matches_the_separate_calls(
            traj in prop::collection::vec(prop::collection::vec(-2.0f64..12.0, 13), 2..40),
            paper in any::<bool>(),
        ) {
            let aut = task();
            let progress = ProgressReward::new(&aut, &ProgressParams::default()).unwrap();
            let reward = if paper {
                TaskReward::Paper { c_r: 2.0, trap_penalty: -50.0 }
            } else {
                TaskReward::Progress(progress.clone(), aut.clone())
            };
            let mut monitor = Monitor::new(aut.clone(), reward).unwrap();
            let first = monitor.reset(&traj[0]).unwrap();
            let mut q = aut.step(&traj[0], aut.initial()).unwrap();
            prop_assert_eq!(first.q, q);
            prop_assert_eq!(first.reward, 0.0);
            let mut phi = 0.0;
            for s in &traj[1..] {
                let got = monitor.advance(s).unwrap();
                let (q_next, r) = if paper {
                    let r = aut.reward(s, q, 2.0, Some(-50.0)).unwrap();
                    (aut.step(s, q).unwrap(), r)
                } else {
                    let (q_next, r, phi_next) = progress.advance(&aut, s, q, phi).unwrap();
                    phi = phi_next;
                    (q_next, r)
                };
                prop_assert_eq!(got.q, q_next);
                prop_assert_eq!(got.reward.to_bits(), r.to_bits());
                prop_assert_eq!(got.accepted, aut.is_accepting(q_next));
                prop_assert_eq!(got.trapped, Some(q_next) == aut.trap());
                let goal = aut.goal(s, q_next).unwrap();
                prop_assert_eq!(monitor.goal().map(<[f64]>::to_vec), goal);
                q = q_next;
            }
        }
    }

    #[test]
    fn advance_before_reset_and_bad_settings_are_refused() {
        let aut = task();
        let mut monitor = Monitor::new(
            aut.clone(),
            TaskReward::Paper {
                c_r: 1.0,
                trap_penalty: -1.0,
            },
        )
        .unwrap();
        assert_eq!(
            monitor.advance(&[0.0; 13]).unwrap_err(),
            AutomatonError::NotReset { row: None }
        );
        crate::tests_support::assert_error(monitor.reset(&[0.0; 12]), "Input(Shape", "s0 length");
        crate::tests_support::assert_error(
            monitor.reset(&[f64::NAN; 13]),
            "Input(NonFinite",
            "s0[0]",
        );
        for (c_r, trap_penalty, kind, names) in [
            (0.0, -1.0, "Input(Value", "c_r"),
            (f64::NAN, -1.0, "Input(Value", "c_r"),
            (1.0, f64::INFINITY, "Input(NonFinite", "trap_penalty"),
        ] {
            let bad = Monitor::new(aut.clone(), TaskReward::Paper { c_r, trap_penalty });
            crate::tests_support::assert_error(bad, kind, names);
        }
        // Another automaton, even one of the same task and size, is refused.
        let other = task();
        let foreign = ProgressReward::new(&other, &ProgressParams::default()).unwrap();
        crate::tests_support::assert_error(
            Monitor::new(aut, TaskReward::Progress(foreign, other)),
            "Input(Value",
            "progress",
        );
    }
}
