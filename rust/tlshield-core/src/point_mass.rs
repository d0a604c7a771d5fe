//! `tlshield/PointMass-v0` as a world the core steps: a 2-D double integrator (state `x, y, vx,
//! vy`, input the acceleration) in a square room with two round obstacles. One step shields the
//! RL action with the task monitor's reading, clips it to the acceleration box, moves the plant
//! through the shield's own model, stops it at the walls, advances the monitor and returns the
//! reward and the measurements; [`PointMassWorld::observe`] writes the observation.
//!
//! The start is drawn by the caller (the Gymnasium class, from its own generator).

use crate::check::check_finite;
use crate::dynamics::Dynamics;
use crate::error::{InputError, ShieldError};
use crate::monitor::Monitor;
use crate::shield::{Shield, Want};
use crate::world::{Measure, World, WorldStep};

/// State length: position `x, y`, velocity `vx, vy`.
pub const STATE_DIM: usize = 4;
/// The state's position dimensions `(x, y)`.
pub const POS: [usize; 2] = [0, 1];
/// The state's velocity dimensions `(vx, vy)`.
pub const VEL: [usize; 2] = [2, 3];

/// The constants a step reads (the Python `PointMassParams` holds and checks them all).
#[derive(Debug, Clone)]
pub struct PointMassParams {
    /// Euler step (s).
    pub dt: f64,
    /// Episode length in steps.
    pub horizon: u32,
    /// The room `[lo, hi]^2`; a wall stops the robot (its velocity into the wall is zeroed).
    pub room: (f64, f64),
    /// The acceleration box `[-max_accel, max_accel]^2` the applied action is clipped to.
    pub max_accel: f64,
    /// The obstacle centres.
    pub obstacles: [[f64; 2]; 2],
    /// The obstacles' radius.
    pub obstacle_radius: f64,
    /// Paid per step inside an obstacle.
    pub collision_penalty: f64,
}

/// The PointMass-v0 world (see the module docs).
#[derive(Debug, Clone)]
pub struct PointMassWorld {
    params: PointMassParams,
    model: Dynamics,
    s: [f64; STATE_DIM],
    t: u32,
}

impl PointMassWorld {
    /// A world with these constants, stepping through the double integrator on `x, y` / `vx,
    /// vy` (the shield's model).
    pub fn new(params: PointMassParams) -> Self {
        let model = Dynamics::double_integrator(POS.to_vec(), VEL.to_vec())
            .expect("fixed, distinct dimensions");
        PointMassWorld {
            params,
            model,
            s: [0.0; STATE_DIM],
            t: 0,
        }
    }

    /// Starts an episode at `s0`.
    pub fn reset(&mut self, s0: [f64; STATE_DIM]) {
        self.s = s0;
        self.t = 0;
    }

    /// The current state.
    pub fn state(&self) -> &[f64; STATE_DIM] {
        &self.s
    }

    /// The constants of a step.
    pub fn params(&self) -> &PointMassParams {
        &self.params
    }

    /// Puts the world at state `s` after `t` steps of an episode (what [`PointMassWorld::state`]
    /// and [`PointMassWorld::steps`] read): values finite, `t` within the horizon.
    pub fn restore(&mut self, s: [f64; STATE_DIM], t: u32) -> Result<(), InputError> {
        check_finite("s", &s, STATE_DIM)?;
        crate::check::check_steps(t, self.params.horizon)?;
        self.s = s;
        self.t = t;
        Ok(())
    }

    /// Steps taken in this episode.
    pub fn steps(&self) -> u32 {
        self.t
    }

    /// One step for the RL action `a_rl` (accelerations), shielded by `shield` when given.
    /// `monitor` must have read the current state (its reset or last advance). [`Want::Record`]
    /// keeps the shield's whole answer (goal, barriers) in the step.
    pub fn step(
        &mut self,
        a_rl: [f64; 2],
        monitor: &mut Monitor,
        shield: Option<&Shield>,
        want: Want,
    ) -> Result<WorldStep, ShieldError> {
        check_finite("action", &a_rl, 2)?;
        let p = &self.params;
        let filtered = match shield {
            Some(shield) => Some(shield.filter_step(monitor, a_rl, None, want)?),
            None => None,
        };
        let wanted = filtered.as_ref().map_or(a_rl, |f| f.action);
        let applied = wanted.map(|a| a.clamp(-p.max_accel, p.max_accel));
        let mut nxt = [0.0; STATE_DIM];
        self.model.euler_step(&self.s, &applied, p.dt, &mut nxt);
        let (lo, hi) = p.room;
        for (pos, vel) in POS.into_iter().zip(VEL) {
            if !(lo..=hi).contains(&nxt[pos]) {
                nxt[pos] = nxt[pos].max(lo).min(hi);
                nxt[vel] = 0.0;
            }
        }
        self.s = nxt;
        self.t += 1;
        let task = monitor.advance(&self.s)?;
        let measure = self.measure();
        let reward = task.reward + -p.collision_penalty * f64::from(u8::from(measure.collision));
        Ok(WorldStep {
            a_rl,
            applied,
            shield: filtered,
            terminated: task.accepted,
            task,
            reward,
            truncated: self.t >= p.horizon,
            measure,
        })
    }

    /// The measurements at the current state.
    pub fn measure(&self) -> Measure {
        let p = &self.params;
        let h = p
            .obstacles
            .map(|c| (self.s[POS[0]] - c[0]).hypot(self.s[POS[1]] - c[1]) - p.obstacle_radius);
        let min = h[0].min(h[1]);
        Measure {
            h,
            min_obstacle_distance: min,
            collision: min < 0.0,
            violation: min < 0.0,
        }
    }

    /// The observation into `out`: the state, then the one-hot FSA state of `monitor`
    /// (`STATE_DIM + num_states` values).
    pub fn observe(&self, monitor: &Monitor, num_states: usize, out: &mut [f64]) {
        out[..STATE_DIM].copy_from_slice(&self.s);
        let onehot = &mut out[STATE_DIM..STATE_DIM + num_states];
        onehot.fill(0.0);
        onehot[monitor.q()] = 1.0;
    }
}

impl World for PointMassWorld {
    /// `scale` is ignored: PointMass-v0's actions are accelerations already.
    fn step_row(
        &mut self,
        action: [f64; 2],
        _scale: bool,
        monitor: &mut Monitor,
        shield: Option<&Shield>,
    ) -> Result<WorldStep, ShieldError> {
        self.step(action, monitor, shield, Want::Action)
    }

    fn observe_row(&self, monitor: &Monitor, num_states: usize, out: &mut [f64]) {
        self.observe(monitor, num_states, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::automaton::Automaton;
    use crate::monitor::TaskReward;
    use crate::predicate::{Center, Predicate};
    use crate::spec::Spec;

    fn params() -> PointMassParams {
        PointMassParams {
            dt: 0.1,
            horizon: 5,
            room: (0.0, 10.0),
            max_accel: 1.0,
            obstacles: [[1.5, 4.8], [5.0, 8.5]],
            obstacle_radius: 1.0,
            collision_penalty: 1.0,
        }
    }

    #[test]
    fn a_wall_stops_the_robot_and_the_horizon_truncates() {
        let goal = Predicate::ball(vec![0, 1], 0.6, Center::Fixed(vec![8.5, 8.5])).unwrap();
        let spec = Spec::new("F a", [("a", goal)]).unwrap();
        let automaton = std::sync::Arc::new(Automaton::build(&spec).unwrap());
        let paper = TaskReward::Paper {
            c_r: 1.0,
            trap_penalty: -100.0,
        };
        let mut monitor = Monitor::new(automaton, paper).unwrap();
        let mut world = PointMassWorld::new(params());
        world.reset([0.05, 1.0, -1.0, 0.0]);
        monitor.reset(world.state()).unwrap();
        let step = world
            .step([5.0, 0.0], &mut monitor, None, Want::Record)
            .unwrap();
        assert_eq!(step.applied, [1.0, 0.0]); // clipped to the box
        assert_eq!(world.state()[0], 0.0); // x = 0.05 - 0.1 left the room: held at the wall
        assert_eq!(world.state()[2], 0.0); // and its velocity into the wall is gone
        assert!(!step.truncated);
        for t in 2..=5 {
            let step = world
                .step([0.0, 0.0], &mut monitor, None, Want::Record)
                .unwrap();
            assert_eq!(step.truncated, t == 5);
        }
        crate::tests_support::assert_error(
            world.step([f64::NAN, 0.0], &mut monitor, None, Want::Record),
            "Input(NonFinite",
            "action[0]",
        );
    }
}
