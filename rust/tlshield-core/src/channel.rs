//! The paper's case study (Sec. VI) as a world the core steps: the unicycle's reference point
//! in a channel, three goal discs and two obstacles oscillating across the channel, whose motion
//! the agent and the shield only measure. One step applies the RL action (scaled from the
//! policy's box), shields it with the task monitor's reading, moves the plant through the
//! shield's own model and the obstacles along their paths, advances the monitor and returns the
//! reward terms and measurements; [`ChannelWorld::observe`] writes the observation.
//!
//! The episode draws (goals, obstacle paths, start) stay with the caller: the Gymnasium class
//! draws them from its own generator and hands the world the start.

use std::f64::consts::SQRT_2;

use crate::check::check_finite;
use crate::dynamics::Dynamics;
use crate::error::{InputError, ShieldError};
use crate::monitor::Monitor;
use crate::shield::{Shield, Want};
use crate::world::{Measure, World, WorldStep};

/// State length: x, y, theta, three goal centres, two obstacle centres.
pub const STATE_DIM: usize = 13;
/// Length of the relative observation, before the one-hot FSA state.
pub const RELATIVE_DIM: usize = 20;
/// Index of the reference point's x.
pub const X: usize = 0;
/// Index of the reference point's y.
pub const Y: usize = 1;
/// Index of the heading.
pub const THETA: usize = 2;
const GOALS: usize = 3;
const OBSTACLES: usize = 9;
/// The (x, y) indices of the goals g1, g2, g3.
pub const GOAL_DIMS: [[usize; 2]; 3] = [
    [GOALS, GOALS + 1],
    [GOALS + 2, GOALS + 3],
    [GOALS + 4, GOALS + 5],
];
/// The (x, y) indices of the obstacles o1, o2.
pub const OBSTACLE_DIMS: [[usize; 2]; 2] =
    [[OBSTACLES, OBSTACLES + 1], [OBSTACLES + 2, OBSTACLES + 3]];

/// The constants a step reads (the Python `ChannelParams` holds and checks them all).
#[derive(Debug, Clone)]
pub struct ChannelParams {
    /// Euler step (s).
    pub dt: f64,
    /// Episode length in steps.
    pub horizon: u32,
    /// The arena `[lo, hi]^2` the reference point is held in.
    pub arena: (f64, f64),
    /// `w` of the channel constraints.
    pub half_width: f64,
    /// Collision distance to an obstacle centre.
    pub obstacle_radius: f64,
    /// The obstacle reward term is `w * min(d - safe_distance, 0)`.
    pub safe_distance: f64,
    /// Weight of the obstacle term.
    pub w: f64,
    /// Paid per step in collision.
    pub collision_penalty: f64,
    /// Paid per shielded step as `intervention_penalty * |a_cbf|^2`.
    pub intervention_penalty: f64,
    /// The relative body-frame observation (else the paper's: the 13 state values).
    pub relative: bool,
    /// The RL action box, `(lo, hi)` per input: policy actions in `[-1, 1]` are scaled to it.
    pub rl_bounds: ([f64; 2], [f64; 2]),
    /// Whether the shield is told the obstacles' measured velocity.
    pub obstacle_drift: bool,
    /// The paper's evaluation rules: an episode also ends on a collision.
    pub evaluation: bool,
    /// An episode also ends on entering the trap (the task can no longer be done). The step
    /// entering it also pays, at once, the trap's task reward for every step left to the
    /// horizon, so that ending a bad episode early in the trap never pays better than going on
    /// outside it.
    pub end_on_trap: bool,
    /// Spec atom indices of the channel constraints c1, c2.
    pub channel_atoms: [usize; 2],
}

impl ChannelParams {
    /// The RL action in physical units of a policy action in `[-1, 1]^2` (clipped): the
    /// centre of the RL box plus the action times its half-width.
    pub fn rl_action(&self, action: [f64; 2]) -> [f64; 2] {
        let (lo, hi) = self.rl_bounds;
        [0, 1].map(|i| (hi[i] + lo[i]) / 2.0 + action[i].clamp(-1.0, 1.0) * ((hi[i] - lo[i]) / 2.0))
    }
}

/// One obstacle's path: centre at channel coordinates `(u, amplitude sin(frequency t + phase))`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Obstacle {
    /// Position along the channel.
    pub u: f64,
    /// Amplitude across it.
    pub amplitude: f64,
    /// Angular frequency (rad/s).
    pub frequency: f64,
    /// Phase (rad).
    pub phase: f64,
}

impl Obstacle {
    /// The centre at time `t`.
    pub fn position(&self, t: f64) -> [f64; 2] {
        xy(
            self.u,
            self.amplitude * (self.frequency * t + self.phase).sin(),
        )
    }
}

/// Channel coordinates `(u, v)` to `(x, y)`.
pub fn xy(u: f64, v: f64) -> [f64; 2] {
    [(u - v) / SQRT_2, (u + v) / SQRT_2]
}

/// What a channel world holds between steps, as data ([`ChannelWorld::snapshot`],
/// [`ChannelWorld::restore`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelState {
    /// The state.
    pub s: [f64; STATE_DIM],
    /// The obstacles' motion measured over the last step.
    pub drift: [f64; STATE_DIM],
    /// The obstacles' paths.
    pub obstacles: [Obstacle; 2],
    /// Steps taken in this episode.
    pub t: u32,
}

/// The case study's world (see the module docs).
#[derive(Debug, Clone)]
pub struct ChannelWorld {
    params: ChannelParams,
    model: Dynamics,
    s: [f64; STATE_DIM],
    drift: [f64; STATE_DIM],
    obstacles: [Obstacle; 2],
    t: u32,
}

impl ChannelWorld {
    /// A world with these constants stepping through `model` (the shield's model).
    pub fn new(params: ChannelParams, model: Dynamics) -> Self {
        ChannelWorld {
            params,
            model,
            s: [0.0; STATE_DIM],
            drift: [0.0; STATE_DIM],
            obstacles: [Obstacle::default(); 2],
            t: 0,
        }
    }

    /// Starts an episode at `s0` (its obstacle dimensions are ignored) with these obstacle
    /// paths: the obstacles are placed where their paths put them at time 0, and their measured
    /// velocity is their motion over the step before the start.
    pub fn reset(&mut self, s0: [f64; STATE_DIM], obstacles: [Obstacle; 2]) {
        self.s = s0;
        self.obstacles = obstacles;
        self.t = 0;
        self.drift = [0.0; STATE_DIM];
        for (k, o) in obstacles.iter().enumerate() {
            let (now, before) = (o.position(0.0), o.position(-self.params.dt));
            for d in 0..2 {
                self.s[OBSTACLES + 2 * k + d] = now[d];
                self.drift[OBSTACLES + 2 * k + d] = (now[d] - before[d]) / self.params.dt;
            }
        }
    }

    /// The model the plant steps through (the shield's).
    pub fn model(&self) -> &Dynamics {
        &self.model
    }

    /// The world between steps, as data.
    pub fn snapshot(&self) -> ChannelState {
        ChannelState {
            s: self.s,
            drift: self.drift,
            obstacles: self.obstacles,
            t: self.t,
        }
    }

    /// Puts the world where [`ChannelWorld::snapshot`] found it: the next step is the one the
    /// snapshotted world would have taken. Values must be finite and `t` within the horizon.
    pub fn restore(&mut self, state: &ChannelState) -> Result<(), InputError> {
        check_finite("s", &state.s, STATE_DIM)?;
        check_finite("drift", &state.drift, STATE_DIM)?;
        for (k, o) in state.obstacles.iter().enumerate() {
            let path = [o.u, o.amplitude, o.frequency, o.phase];
            check_finite(&format!("obstacles[{k}]"), &path, 4)?;
        }
        crate::check::check_steps(state.t, self.params.horizon)?;
        self.s = state.s;
        self.drift = state.drift;
        self.obstacles = state.obstacles;
        self.t = state.t;
        Ok(())
    }

    /// The current state.
    pub fn state(&self) -> &[f64; STATE_DIM] {
        &self.s
    }

    /// The obstacles' motion measured over the last step (zero elsewhere).
    pub fn drift(&self) -> &[f64; STATE_DIM] {
        &self.drift
    }

    /// Steps taken in this episode.
    pub fn steps(&self) -> u32 {
        self.t
    }

    /// The constants.
    pub fn params(&self) -> &ChannelParams {
        &self.params
    }

    /// One step for the policy action `action` (in `[-1, 1]^2`, clipped, scaled to the RL box;
    /// with `scale` false it is already the physical RL action), shielded by `shield` when
    /// given. `monitor` must have read the current state (its reset or last advance).
    pub fn step(
        &mut self,
        action: [f64; 2],
        scale: bool,
        monitor: &mut Monitor,
        shield: Option<&Shield>,
        want: Want,
    ) -> Result<WorldStep, ShieldError> {
        let p = &self.params;
        check_finite("action", &action, 2)?;
        let a_rl = if scale { p.rl_action(action) } else { action };
        let filtered = match shield {
            Some(shield) => {
                let drift = p.obstacle_drift.then_some(&self.drift[..]);
                Some(shield.filter_step(monitor, a_rl, drift, want)?)
            }
            None => None,
        };
        let applied = filtered.as_ref().map_or(a_rl, |f| f.action);
        // The plant through the shield's own model, held in the arena, heading wrapped.
        let mut nxt = [0.0; STATE_DIM];
        self.model.euler_step(&self.s, &applied, p.dt, &mut nxt);
        let (lo, hi) = p.arena;
        nxt[X] = nxt[X].max(lo).min(hi);
        nxt[Y] = nxt[Y].max(lo).min(hi);
        nxt[THETA] = (nxt[THETA] + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI;
        self.t += 1;
        let time = f64::from(self.t) * p.dt;
        for (k, o) in self.obstacles.iter().enumerate() {
            let at = o.position(time);
            nxt[OBSTACLES + 2 * k] = at[0];
            nxt[OBSTACLES + 2 * k + 1] = at[1];
        }
        self.drift = [0.0; STATE_DIM];
        for ((v, new), old) in self.drift[OBSTACLES..]
            .iter_mut()
            .zip(&nxt[OBSTACLES..])
            .zip(&self.s[OBSTACLES..])
        {
            *v = (new - old) / p.dt;
        }
        self.s = nxt;
        let task = monitor.advance(&self.s)?;
        let measure = self.measure(monitor);
        let mut reward = task.reward
            + p.w * (measure.min_obstacle_distance - p.safe_distance).min(0.0)
            - p.collision_penalty * f64::from(u8::from(measure.collision));
        if let Some(f) = &filtered {
            let push = f.a_cbf[0] * f.a_cbf[0] + f.a_cbf[1] * f.a_cbf[1];
            reward -= p.intervention_penalty * push;
        }
        let ended_in_trap = p.end_on_trap && task.trapped;
        if ended_in_trap {
            // The steps the episode would have spent in the trap, each paying the trap's task
            // reward (`task.reward` is that reward: this step entered the trap).
            reward += task.reward * f64::from(p.horizon.saturating_sub(self.t));
        }
        let terminated = task.accepted || ended_in_trap || (p.evaluation && measure.collision);
        Ok(WorldStep {
            a_rl,
            applied,
            shield: filtered,
            task,
            reward,
            terminated,
            truncated: self.t >= p.horizon && !terminated,
            measure,
        })
    }

    /// The measurements at the current state, the channel read from the monitor's atoms.
    pub fn measure(&self, monitor: &Monitor) -> Measure {
        let reading = monitor.reading();
        let rho = reading.rho();
        let h = [
            rho[self.params.channel_atoms[0]],
            rho[self.params.channel_atoms[1]],
        ];
        let s = &self.s;
        let d = (0..2)
            .map(|k| (s[X] - s[OBSTACLES + 2 * k]).hypot(s[Y] - s[OBSTACLES + 2 * k + 1]))
            .fold(f64::INFINITY, f64::min);
        Measure {
            h,
            min_obstacle_distance: d,
            collision: d < self.params.obstacle_radius,
            violation: h[0].min(h[1]) < 0.0,
        }
    }

    /// Length of the observation, one-hot FSA state of `num_states` values included.
    pub fn observation_len(&self, num_states: usize) -> usize {
        let head = if self.params.relative {
            RELATIVE_DIM
        } else {
            STATE_DIM
        };
        head + num_states
    }

    /// The observation at the current state into `out` (its length: the observation's, then
    /// the one-hot FSA state of `monitor`, `num_states` values).
    pub fn observe(&self, monitor: &Monitor, num_states: usize, out: &mut [f64]) {
        let s = &self.s;
        let head = if self.params.relative {
            let (si, c) = s[THETA].sin_cos();
            let w = self.params.half_width;
            out[0] = c;
            out[1] = si;
            out[2] = s[X] - s[Y] + w;
            out[3] = s[Y] - s[X] + w;
            // Goals, obstacles and obstacle velocities in the agent's frame (x ahead, y left).
            let frame = |dx: f64, dy: f64| [dx * c + dy * si, dx * -si + dy * c];
            for k in 0..5 {
                let r = frame(s[GOALS + 2 * k] - s[X], s[GOALS + 2 * k + 1] - s[Y]);
                out[4 + 2 * k..6 + 2 * k].copy_from_slice(&r);
            }
            for k in 0..2 {
                let r = frame(
                    self.drift[OBSTACLES + 2 * k],
                    self.drift[OBSTACLES + 2 * k + 1],
                );
                out[14 + 2 * k..16 + 2 * k].copy_from_slice(&r);
            }
            // The task's next goal as the automaton picks it (Eq. 5B1), zero without one.
            out[18..20].copy_from_slice(&match monitor.goal() {
                Some(g) => frame(g[0] - s[X], g[1] - s[Y]),
                None => [0.0, 0.0],
            });
            RELATIVE_DIM
        } else {
            out[..STATE_DIM].copy_from_slice(s);
            STATE_DIM
        };
        let onehot = &mut out[head..head + num_states];
        onehot.fill(0.0);
        onehot[monitor.q()] = 1.0;
    }
}

impl World for ChannelWorld {
    fn step_row(
        &mut self,
        action: [f64; 2],
        scale: bool,
        monitor: &mut Monitor,
        shield: Option<&Shield>,
    ) -> Result<WorldStep, ShieldError> {
        self.step(action, scale, monitor, shield, Want::Action)
    }

    fn observe_row(&self, monitor: &Monitor, num_states: usize, out: &mut [f64]) {
        self.observe(monitor, num_states, out);
    }
}
