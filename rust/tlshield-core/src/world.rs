//! What the bundled worlds (`ChannelWorld` of Channel-v0, `PointMassWorld` of PointMass-v0)
//! share: what one step gives ([`WorldStep`], with its [`Measure`]), and [`step_many`], which
//! steps N worlds of one kind in one call.

use smallvec::SmallVec;

use crate::error::{InputError, ShieldError};
use crate::monitor::{Monitor, TaskStep};
use crate::shield::Shield;
pub use crate::shield::ShieldStep;

/// What a world measures at a state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measure {
    /// The world's two constraints (Channel-v0: the channel's c1, c2 as the task's predicates
    /// evaluate them; PointMass-v0: each obstacle's clearance, distance minus radius).
    pub h: [f64; 2],
    /// Distance to the nearer obstacle (Channel-v0: to its centre; PointMass-v0: to its edge).
    pub min_obstacle_distance: f64,
    /// In collision.
    pub collision: bool,
    /// A constraint of the task is violated.
    pub violation: bool,
}

/// What one step of a bundled world gives.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldStep {
    /// The RL action in physical units.
    pub a_rl: [f64; 2],
    /// The action applied to the plant.
    pub applied: [f64; 2],
    /// The shield's answer, when it ran.
    pub shield: Option<ShieldStep>,
    /// The task's step (FSA state, task reward, acceptance, trap).
    pub task: TaskStep,
    /// The environment's reward.
    pub reward: f64,
    /// The episode ended.
    pub terminated: bool,
    /// The horizon was reached.
    pub truncated: bool,
    /// Measurements at the new state.
    pub measure: Measure,
}

/// A world the core steps: one action (2 inputs) per step, shielded with its monitor's reading.
pub trait World: Send {
    /// One step for `action` (scaled from `[-1, 1]` to the RL box when `scale` is true and the
    /// world has such a box), shielded by `shield` when given.
    fn step_row(
        &mut self,
        action: [f64; 2],
        scale: bool,
        monitor: &mut Monitor,
        shield: Option<&Shield>,
    ) -> Result<WorldStep, ShieldError>;

    /// The observation at the current state into `out`, then the one-hot FSA state of
    /// `monitor` (`num_states` values).
    fn observe_row(&self, monitor: &Monitor, num_states: usize, out: &mut [f64]);
}

/// Steps many worlds in one call, in parallel past [`crate::shield::PARALLEL_MIN_ROWS`] rows: row `i`
/// steps `worlds[i]` with `actions[2i..2i + 2]` and `monitors[i]`, shielded by `shield`, and
/// writes its observation into row `i` of `obs` (`width` values: the observation, then the
/// one-hot FSA state). Rows with `active[i]` false are left alone (`None`, observation row
/// untouched). The actions are checked first; an error steps no world.
#[allow(clippy::too_many_arguments)]
pub fn step_many<W: World>(
    worlds: &mut [&mut W],
    monitors: &mut [&mut Monitor],
    actions: &[f64],
    active: &[bool],
    scale: bool,
    shield: Option<&Shield>,
    obs: &mut [f64],
    width: usize,
) -> Result<Vec<Option<WorldStep>>, ShieldError> {
    let rows = worlds.len();
    if monitors.len() != rows || active.len() != rows || actions.len() != 2 * rows {
        return Err(InputError::Shape {
            what: "step_many".into(),
            expected: format!("{rows} monitors, {rows} active flags and ({rows}, 2) actions"),
            got: format!(
                "{} monitors, {} flags, {} action values",
                monitors.len(),
                active.len(),
                actions.len()
            ),
        }
        .into());
    }
    if obs.len() != rows * width {
        return Err(InputError::Shape {
            what: "observations".into(),
            expected: format!("({rows}, {width})"),
            got: format!("{} values", obs.len()),
        }
        .into());
    }
    crate::check::check_finite("actions", actions, 2)?;
    let states = monitors.first().map_or(0, |m| m.automaton().num_states());
    let step = |world: &mut W, monitor: &mut Monitor, a: &[f64], row: &mut [f64]| {
        let out = world.step_row([a[0], a[1]], scale, monitor, shield)?;
        world.observe_row(monitor, states, row);
        Ok(Some(out))
    };
    let mut results: Vec<Result<Option<WorldStep>, ShieldError>> = Vec::new();
    results.resize_with(rows, || Ok(None));
    // Contiguous parts of rows, claimed by the calling thread and the pool's.
    let chunk = crate::parallel::part_len(rows, crate::parallel::MIN_ROWS);
    let mut parts: SmallVec<[_; 16]> = worlds
        .chunks_mut(chunk)
        .zip(monitors.chunks_mut(chunk))
        .zip(actions.chunks(2 * chunk))
        .zip(obs.chunks_mut(width * chunk))
        .zip(active.chunks(chunk))
        .zip(results.chunks_mut(chunk))
        .collect();
    crate::parallel::for_each_part(&mut parts, |(((((w, m), a), o), on), r)| {
        for i in 0..w.len() {
            if on[i] {
                r[i] = step(
                    w[i],
                    m[i],
                    &a[2 * i..2 * i + 2],
                    &mut o[i * width..(i + 1) * width],
                );
            }
        }
    });
    drop(parts);
    results.into_iter().collect()
}
