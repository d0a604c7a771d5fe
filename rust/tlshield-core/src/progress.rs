//! A progress-aware task reward for any formula (beyond the paper; Eq. 5A1 stays the
//! reference).
//!
//! Eq. 5A1 alone pays dawdling: its scale changes with the FSA state (about 0 just outside the
//! first goal, about `-dist(next goal)` after entering it, 0 at acceptance), so parking outside
//! a goal out-earns finishing. Here the Eq. 5A1 value becomes the within-state part of a
//! potential over (state, FSA state), as in reward machines' automaton-distance shaping
//! (Camacho et al. 2019), plus a terminal reward:
//!
//! - `rank(q)`: fewest transitions from `q` to acceptance over *admissible* valuations (atoms
//!   declared mutually exclusive never hold together: two disjoint goal discs), 0 at
//!   acceptance, `None` for the trap;
//! - `Phi(s, q) = -rank(q) + squash(sigma_q(s))`, `sigma_q` the Eq. 5A1 value of being at `s`
//!   in `q` over the guard cubes whose goal can hold where it is (a goal disc outside the
//!   channel that its cube also requires does not pull; see
//!   [`Reading::reachable_reward`]), and `squash(x) = min(x, 0) / (scale + |min(x, 0)|)` in (-1, 0]: strictly increasing
//!   below 0 (slope `1 / scale` at the goal's edge, so the shaping never goes flat as a clip
//!   would); `Phi = 0` at acceptance. The bands `(-rank - 1, -rank]` never overlap the next
//!   state's, so entering a state closer to acceptance never lowers `Phi`;
//! - the reward of a step `(s, q) -> (s', q')` is the progress `Phi(s', q') - Phi(s, q)` minus
//!   `step_cost`, plus `bonus` on entering acceptance; `trap_penalty` on every step in the
//!   trap; 0 on steps that stay accepting. An episode starts from `Phi = 0` (the first step
//!   pays the whole distance to go). Standing still costs exactly `step_cost` a step.
//!
//! With `goal_weight = k > 0` the potential also measures the way to the CLF goal (Eq. 5B1, the
//! goal the shield's CLF drives to): `Phi(s, q) = -rank(q) B + squash(sigma_q(s)) - k min(d, span)`,
//! `d` the distance from `s` to the goal of `q` in the goal's space ([`Reading::goal_distance`]),
//! `span = goal_span` and `B = 1 + k span` the widened band, so bands still never overlap and
//! entering a state closer to acceptance still never lowers `Phi`. It gives a learner without
//! the CLF the CLF's information (which goal advances the task, and how far it is) as reward
//! rather than as a push: potential-based shaping (Ng, Harada and Russell 1999; undiscounted
//! differences, as for the rest of `Phi`, with the bonus sized for the discount). The squash
//! flattens far from a goal (slope `scale / (scale + x)^2`); the goal term keeps a slope of `k`
//! per metre out to `span`. Where `q` has no goal the term sits at its floor `-k span`. The
//! bonus, trap penalty and the bound below use the whole range `(max rank + 1) B`.
//!
//! Why undiscounted differences and a bonus: with `gamma * Phi' - Phi` (classic potential
//! shaping) every return telescopes to its end point, so reaching a sub-goal and stopping
//! there earns the same as never moving (measured: PPO then never finds the task). The
//! progress `Phi' - Phi` pays a sub-goal when it is reached. Summation by parts bounds what the
//! shaping can add over any trajectory by `max rank + 1`, so with the horizon `T` known a bonus
//! `bonus > (max rank + 1) (gamma^(1 - T) - 1) - 1` makes every trajectory that reaches
//! acceptance out-earn every one that does not, whatever the starts; the default bonus is
//! `(max rank + 1) gamma^(1 - T)`.
use crate::automaton::{Automaton, Reading};
use crate::error::{AutomatonError, InputError};

/// The default training discount of [`ProgressParams`].
pub const DEFAULT_GAMMA: f64 = 0.99;
/// The default episode length of [`ProgressParams`], for the bonus.
pub const DEFAULT_HORIZON: u32 = 200;
/// The default robustness scale of [`ProgressParams`].
pub const DEFAULT_SCALE: f64 = 1.0;
/// The default `goal_span` of [`ProgressParams`] (metres).
pub const DEFAULT_GOAL_SPAN: f64 = 10.0;

/// Parameters of [`ProgressReward`].
#[derive(Debug, Clone, PartialEq)]
pub struct ProgressParams {
    /// The training discount, in (0, 1].
    pub gamma: f64,
    /// Robustness scale of the squash `x / (scale + |x|)`: Eq. 5A1 at `-scale` sits halfway
    /// down its band. Smaller values shape harder near the goals, larger ones further away.
    pub scale: f64,
    /// Cost of every step outside acceptance; `None` picks `(1 - gamma) (max rank + 1)`.
    pub step_cost: Option<f64>,
    /// Paid once, on entering acceptance; `None` picks `(max rank + 1) gamma^(1 - horizon)`.
    /// A bonus too small to make finishing within the horizon out-earn not finishing is an
    /// error.
    pub bonus: Option<f64>,
    /// Episode length in steps, for the bonus.
    pub horizon: u32,
    /// Weight of the trap term inside Eq. 5A1.
    pub c_r: f64,
    /// Groups of atom indices of which at most one holds at a time (bitmasks).
    pub exclusive: Vec<u32>,
    /// Weight `k` of the goal term (potential per metre of approach to the CLF goal); 0 (the
    /// default) leaves it out.
    pub goal_weight: f64,
    /// Distance beyond which the goal term is flat (metres, > 0): pick at least the usual
    /// distance between consecutive goals.
    pub goal_span: f64,
}

impl Default for ProgressParams {
    fn default() -> Self {
        ProgressParams {
            gamma: DEFAULT_GAMMA,
            scale: DEFAULT_SCALE,
            step_cost: None,
            bonus: None,
            horizon: DEFAULT_HORIZON,
            c_r: crate::automaton::DEFAULT_C_R,
            exclusive: Vec::new(),
            goal_weight: 0.0,
            goal_span: DEFAULT_GOAL_SPAN,
        }
    }
}

/// The progress reward of one automaton (see the module docs).
#[derive(Debug, Clone)]
pub struct ProgressReward {
    ranks: Vec<Option<u32>>,
    max_rank: u32,
    gamma: f64,
    scale: f64,
    step_cost: f64,
    bonus: f64,
    c_r: f64,
    trap_penalty: f64,
    horizon: u32,
    goal_weight: f64,
    goal_span: f64,
    /// The width of one rank's band of `Phi`: `1 + goal_weight * goal_span`.
    band_width: f64,
}

/// Checks that `value` is finite and > 0 (`noun`: what the error says it must be).
fn finite_positive(what: &str, value: f64, noun: &str) -> Result<(), InputError> {
    if value.is_finite() && value > 0.0 {
        return Ok(());
    }
    Err(InputError::Value {
        what: what.into(),
        expected: format!("a finite {noun} > 0"),
        got: value.to_string(),
    })
}

fn finite_at_least(what: &str, value: f64, lo: f64) -> Result<(), InputError> {
    if value.is_finite() && value >= lo {
        return Ok(());
    }
    Err(InputError::Value {
        what: what.into(),
        expected: format!("a finite number >= {lo}"),
        got: value.to_string(),
    })
}

/// Fewest transitions from each state to acceptance, reading only valuations the regions'
/// geometry admits ([`Automaton::admissible`]) in which no two atoms of one `exclusive` group
/// hold (`None`: acceptance is unreachable, e.g. the trap).
pub fn ranks(automaton: &Automaton, exclusive: &[u32]) -> Vec<Option<u32>> {
    crate::automaton::ranks(
        automaton.num_states(),
        &(0..automaton.num_states())
            .map(|q| automaton.is_accepting(q))
            .collect::<Vec<_>>(),
        automaton.edges(),
        |v| {
            automaton.admissible(v as usize) && exclusive.iter().all(|&g| (v & g).count_ones() <= 1)
        },
    )
}

/// Checks each `exclusive` group against the geometry: two atoms of one group whose regions
/// overlap could hold together, and declaring them exclusive would hide the letters where they
/// do. Pairs the geometry cannot decide (moving regions) are trusted.
fn check_exclusive(automaton: &Automaton, exclusive: &[u32]) -> Result<(), InputError> {
    let atoms = automaton.spec().atoms();
    for &g in exclusive {
        let members: Vec<usize> = (0..atoms.len()).filter(|i| g >> i & 1 == 1).collect();
        for (k, &i) in members.iter().enumerate() {
            for &j in &members[k + 1..] {
                if automaton.can_hold_together(i, j) == Some(true) {
                    return Err(InputError::Value {
                        what: "exclusive".into(),
                        expected: "groups of atoms that never hold together".into(),
                        got: format!(
                            "{:?} and {:?} in one group, but their regions overlap",
                            atoms[i], atoms[j]
                        ),
                    });
                }
            }
        }
    }
    Ok(())
}

impl ProgressReward {
    /// The progress reward of `automaton`'s task.
    pub fn new(automaton: &Automaton, params: &ProgressParams) -> Result<Self, AutomatonError> {
        if !(params.gamma > 0.0 && params.gamma <= 1.0) {
            return Err(InputError::Value {
                what: "gamma".into(),
                expected: "a discount in (0, 1]".into(),
                got: params.gamma.to_string(),
            }
            .into());
        }
        finite_positive("scale", params.scale, "number")?;
        if params.horizon == 0 {
            return Err(InputError::Value {
                what: "horizon".into(),
                expected: "a positive number of steps".into(),
                got: "0".into(),
            }
            .into());
        }
        finite_positive("c_r", params.c_r, "weight")?;
        let atoms = automaton.spec().atoms().len();
        for &g in &params.exclusive {
            if atoms < 32 && g >> atoms != 0 {
                return Err(InputError::Value {
                    what: "exclusive".into(),
                    expected: format!("groups of atom indices below {atoms}"),
                    got: format!("{g:#b}"),
                }
                .into());
            }
        }
        check_exclusive(automaton, &params.exclusive)?;
        finite_at_least("goal_weight", params.goal_weight, 0.0)?;
        finite_positive("goal_span", params.goal_span, "distance")?;
        let ranks = ranks(automaton, &params.exclusive);
        if ranks[automaton.initial()].is_none() {
            return Err(InputError::Value {
                what: "task".into(),
                expected: "a formula whose acceptance is reachable from the initial state".into(),
                got: format!(
                    "no path to acceptance over the valuations the regions' geometry{} \
                     admits (the formula needs atoms to hold together whose regions are \
                     disjoint, or is unsatisfiable)",
                    if params.exclusive.is_empty() {
                        ""
                    } else {
                        " and the exclusive groups"
                    }
                ),
            }
            .into());
        }
        let max_rank = ranks.iter().flatten().copied().max().unwrap_or(0);
        let band = f64::from(max_rank + 1);
        let band_width = 1.0 + params.goal_weight * params.goal_span;
        if !band_width.is_finite() {
            return Err(InputError::Value {
                what: "goal_weight".into(),
                expected: "goal_weight * goal_span finite".into(),
                got: format!("{} * {}", params.goal_weight, params.goal_span),
            }
            .into());
        }
        // The whole range of `Phi` outside the trap: what shaping can add along a trajectory.
        let range = band * band_width;
        let step_cost = match params.step_cost {
            Some(c) => {
                finite_at_least("step_cost", c, 0.0)?;
                c
            }
            None => (1.0 - params.gamma) * band,
        };
        // gamma^(1 - T): how much the last step's bonus is discounted over the horizon.
        let stretch = params.gamma.powi(1 - params.horizon as i32);
        let least_bonus = range * (stretch - 1.0) - 1.0;
        let bonus = match params.bonus {
            Some(b) => {
                finite_at_least("bonus", b, 0.0)?;
                if b <= least_bonus {
                    return Err(InputError::Value {
                        what: "bonus".into(),
                        expected: format!(
                            "more than {least_bonus:.4} (max rank + 1 = {band}, band width \
                             {band_width}, gamma {}, horizon {}), so that finishing out-earns not \
                             finishing",
                            params.gamma, params.horizon
                        ),
                        got: b.to_string(),
                    }
                    .into());
                }
                b
            }
            None => range * stretch,
        };
        // Every step outside the trap pays at least -(K + 1) B - c; a trap step pays less, and
        // enough less (times gamma^(1 - T)) that entering it even at the last step loses.
        let trap_penalty = -(range + 1.0 + step_cost) * stretch;
        Ok(ProgressReward {
            ranks,
            max_rank,
            gamma: params.gamma,
            scale: params.scale,
            step_cost,
            bonus,
            c_r: params.c_r,
            trap_penalty,
            horizon: params.horizon,
            goal_weight: params.goal_weight,
            goal_span: params.goal_span,
            band_width,
        })
    }

    /// Transitions to acceptance per state (`None`: unreachable).
    pub fn ranks(&self) -> &[Option<u32>] {
        &self.ranks
    }

    /// The step cost in force (given or chosen).
    pub fn step_cost(&self) -> f64 {
        self.step_cost
    }

    /// The bonus in force (given or chosen).
    pub fn bonus(&self) -> f64 {
        self.bonus
    }

    /// The per-step reward in the trap (worse than any step outside it).
    pub fn trap_penalty(&self) -> f64 {
        self.trap_penalty
    }

    /// The episode length the bonus is sized for.
    pub fn horizon(&self) -> u32 {
        self.horizon
    }

    /// The training discount the bonus is sized for.
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// The goal term's weight (0: no goal term).
    pub fn goal_weight(&self) -> f64 {
        self.goal_weight
    }

    /// The distance beyond which the goal term is flat.
    pub fn goal_span(&self) -> f64 {
        self.goal_span
    }

    /// The potential `Phi(s, q)` at the state read by `reading`, a reading of the automaton the
    /// reward was built for. States without a path to acceptance sit one band below the
    /// farthest state that has one.
    pub fn potential(&self, reading: &Reading<'_>, q: usize) -> f64 {
        let distance = if self.goal_weight > 0.0 {
            reading.goal_distance(q, &mut Vec::new())
        } else {
            None
        };
        self.potential_at(reading, q, distance)
    }

    /// [`ProgressReward::potential`] given the distance to the CLF goal of `q` at this state
    /// ([`Reading::goal_distance`], read only with a goal term), for callers that already
    /// have it (the monitor, allocation-free).
    pub fn potential_at(&self, reading: &Reading<'_>, q: usize, goal_distance: Option<f64>) -> f64 {
        if reading.automaton().is_accepting(q) {
            return 0.0;
        }
        let rank = self.ranks[q].unwrap_or(self.max_rank + 1);
        let approach = if self.goal_weight > 0.0 {
            -self.goal_weight * goal_distance.map_or(self.goal_span, |d| d.min(self.goal_span))
        } else {
            0.0
        };
        let sigma = reading.reachable_reward(q, self.c_r).min(0.0);
        // -inf (a `false` guard) squashes to the band's floor, not to -inf / inf = NaN.
        let squashed = if sigma.is_finite() {
            sigma / (self.scale - sigma)
        } else {
            -1.0
        };
        -f64::from(rank) * self.band_width + squashed + approach
    }

    /// The reward of the step `q -> q_next` given `Phi` before (`phi`; 0 at an episode's
    /// start) and after (`phi_next`).
    pub fn reward(
        &self,
        automaton: &Automaton,
        q: usize,
        q_next: usize,
        phi: f64,
        phi_next: f64,
    ) -> f64 {
        if Some(q_next) == automaton.trap() {
            self.trap_penalty
        } else if automaton.is_accepting(q) {
            0.0
        } else if automaton.is_accepting(q_next) {
            -phi - self.step_cost + self.bonus
        } else {
            phi_next - phi - self.step_cost
        }
    }

    /// One step into `s_next` (validated here) from `(q, phi)`: `(q_next, reward, phi_next)`.
    pub fn advance(
        &self,
        automaton: &Automaton,
        s_next: &[f64],
        q: usize,
        phi: f64,
    ) -> Result<(usize, f64, f64), AutomatonError> {
        let q = automaton.check_state("q", q)?;
        if self.ranks.len() != automaton.num_states() {
            return Err(InputError::Value {
                what: "automaton".into(),
                expected: format!(
                    "the one the reward was built for ({} states)",
                    self.ranks.len()
                ),
                got: format!("{} states", automaton.num_states()),
            }
            .into());
        }
        crate::check::check_finite("phi", &[phi], crate::check::SCALAR)?;
        let reading = automaton.read(s_next)?;
        let q_next = reading.step(q);
        let phi_next = self.potential(&reading, q_next);
        Ok((
            q_next,
            self.reward(automaton, q, q_next, phi, phi_next),
            phi_next,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{co_safe, spec_for};
    use crate::{Center, Predicate, Spec};
    use proptest::prelude::*;

    fn channel_like() -> Automaton {
        // Two goal discs on a line and a wall: (F a | F b) & F c & (!c U (a | b)) & (w U c).
        let ball = |c: f64| Predicate::ball(vec![0], 0.5, Center::Fixed(vec![c])).unwrap();
        let spec = Spec::new(
            "(F a | F b) & F c & (!c U (a | b)) & (w U c)",
            [
                ("a", ball(2.0)),
                ("b", ball(-2.0)),
                ("c", ball(5.0)),
                ("w", Predicate::halfspace(vec![-1.0], 8.0).unwrap()),
            ],
        )
        .unwrap();
        Automaton::build(&spec).unwrap()
    }

    #[test]
    fn unreachable_acceptance_and_overlapping_exclusive_groups_are_refused() {
        let ball = |c: f64, r: f64| Predicate::ball(vec![0], r, Center::Fixed(vec![c])).unwrap();
        // a and b are disjoint: F(a & b) can never be accepted.
        let spec = Spec::new("F(a & b)", [("a", ball(0.0, 0.5)), ("b", ball(2.0, 0.5))]).unwrap();
        let err = ProgressReward::new(
            &Automaton::build(&spec).unwrap(),
            &ProgressParams::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("no path to acceptance"), "{err}");
        // Overlapping discs can hold together: declaring them exclusive is an error naming both.
        let spec = Spec::new("F a & F b", [("a", ball(0.0, 0.5)), ("b", ball(0.6, 0.5))]).unwrap();
        let aut = Automaton::build(&spec).unwrap();
        let params = ProgressParams {
            exclusive: vec![0b11],
            ..Default::default()
        };
        let err = ProgressReward::new(&aut, &params).unwrap_err().to_string();
        assert!(
            err.contains("\"a\" and \"b\"") && err.contains("overlap"),
            "{err}"
        );
        let err = spec.with_exclusive([["a", "b"]]).unwrap_err().to_string();
        assert!(err.contains("overlap"), "{err}");
    }

    #[test]
    fn exclusive_goals_rank_the_subgoal_state_between() {
        let aut = channel_like();
        let atoms = aut.spec().atoms().to_vec();
        let bit = |name: &str| 1u32 << atoms.iter().position(|a| a == name).unwrap();
        let loose = ranks(&aut, &[]);
        let tight = ranks(&aut, &[bit("a") | bit("b") | bit("c")]);
        let q0 = aut.initial();
        // The discs are disjoint, so the geometry alone rules out a and c at once.
        assert_eq!(loose[q0], Some(2));
        assert_eq!(tight[q0], Some(2));
        // The formula alone knows no geometry: a single valuation can satisfy a and c at once,
        // unless the exclusive group says otherwise.
        let formula = "(F a | F b) & F c & (!c U (a | b)) & (w U c)";
        let alone = Automaton::build(&Spec::from_formula(formula).unwrap()).unwrap();
        let names = alone.spec().atoms().to_vec();
        let bit = |name: &str| 1u32 << names.iter().position(|a| a == name).unwrap();
        assert_eq!(ranks(&alone, &[])[alone.initial()], Some(1));
        assert_eq!(
            ranks(&alone, &[bit("a") | bit("b") | bit("c")])[alone.initial()],
            Some(2)
        );
        assert_eq!(aut.trap().map(|t| tight[t]), Some(None));
    }

    #[test]
    fn a_goal_the_task_cannot_take_does_not_pull() {
        // b's disc (around 9) lies beyond the wall x < 8 that the task keeps until c.
        let ball = |c: f64| Predicate::ball(vec![0], 0.5, Center::Fixed(vec![c])).unwrap();
        let spec = Spec::new(
            "(F a | F b) & F c & (!c U (a | b)) & (w U c)",
            [
                ("a", ball(2.0)),
                ("b", ball(9.0)),
                ("c", ball(5.0)),
                ("w", Predicate::halfspace(vec![-1.0], 8.0).unwrap()),
            ],
        )
        .unwrap();
        let aut = Automaton::build(&spec).unwrap();
        let q0 = aut.step(&[7.5], aut.initial()).unwrap();
        let reading = aut.read(&[7.5]).unwrap();
        // Eq. 5A1 follows the nearer goal b (0.5 - 1.5); the reachable signal follows a.
        assert!((reading.reward(q0, 1.0) + 1.0).abs() < 1e-12);
        assert!((reading.reachable_reward(q0, 1.0) + 5.0).abs() < 1e-12);
    }

    #[test]
    fn bad_parameters_are_errors() {
        let aut = channel_like();
        // Each bad parameter is an input error that names it.
        for (p, names) in [
            (
                ProgressParams {
                    gamma: 0.0,
                    ..Default::default()
                },
                "gamma",
            ),
            (
                ProgressParams {
                    gamma: 1.5,
                    ..Default::default()
                },
                "gamma",
            ),
            (
                ProgressParams {
                    scale: 0.0,
                    ..Default::default()
                },
                "scale",
            ),
            (
                ProgressParams {
                    bonus: Some(-1.0),
                    ..Default::default()
                },
                "bonus",
            ),
            (
                ProgressParams {
                    bonus: Some(1.0),
                    ..Default::default()
                },
                "bonus",
            ),
            (
                ProgressParams {
                    horizon: 0,
                    ..Default::default()
                },
                "horizon",
            ),
            (
                ProgressParams {
                    step_cost: Some(f64::NAN),
                    ..Default::default()
                },
                "step_cost",
            ),
            (
                ProgressParams {
                    c_r: 0.0,
                    ..Default::default()
                },
                "c_r",
            ),
            (
                ProgressParams {
                    exclusive: vec![1 << 9],
                    ..Default::default()
                },
                "exclusive",
            ),
            (
                ProgressParams {
                    goal_weight: -0.5,
                    ..Default::default()
                },
                "goal_weight",
            ),
            (
                ProgressParams {
                    goal_weight: f64::INFINITY,
                    ..Default::default()
                },
                "goal_weight",
            ),
            (
                ProgressParams {
                    goal_weight: 0.5,
                    goal_span: 0.0,
                    ..Default::default()
                },
                "goal_span",
            ),
        ] {
            crate::tests_support::assert_error(ProgressReward::new(&aut, &p), "Input(Value", names);
        }
        let r = ProgressReward::new(&aut, &ProgressParams::default()).unwrap();
        crate::tests_support::assert_error(
            r.advance(&aut, &[0.0], 0, f64::NAN),
            "Input(NonFinite",
            "phi",
        );
        crate::tests_support::assert_error(r.advance(&aut, &[0.0], 99, 0.0), "UnknownState", "q");
        crate::tests_support::assert_error(
            r.advance(&aut, &[f64::INFINITY], 0, 0.0),
            "Input(NonFinite",
            "s[0]",
        );
    }

    /// Rewards and FSA states of a trajectory (rows of 3), the episode starting from Phi = 0.
    fn rollout(
        aut: &Automaton,
        r: &ProgressReward,
        data: &[f64],
    ) -> (Vec<f64>, Vec<usize>, Vec<f64>) {
        let q0 = aut.step(&data[..3], aut.initial()).unwrap();
        let (mut q, mut phi) = (q0, 0.0);
        let (mut rewards, mut qs, mut phis) = (vec![], vec![q0], vec![]);
        for s in data.chunks(3).skip(1) {
            let (qn, rew, pn) = r.advance(aut, s, q, phi).unwrap();
            rewards.push(rew);
            qs.push(qn);
            phis.push(pn);
            if aut.is_accepting(qn) {
                break; // training ends the episode on success
            }
            q = qn;
            phi = pn;
        }
        (rewards, qs, phis)
    }

    fn discounted(rewards: &[f64], gamma: f64) -> f64 {
        rewards.iter().rev().fold(0.0, |g, r| r + gamma * g)
    }

    fn trajectories() -> impl Strategy<Value = Vec<Vec<f64>>> {
        let value = prop_oneof![(-2i32..=2).prop_map(|v| v as f64 * 0.5), -2.0..2.0f64];
        prop::collection::vec(prop::collection::vec(value, 3 * 12), 2..10)
    }

    proptest! {
        #![proptest_config(crate::tests_support::seeded(400))]

        /// (a) Any accepting trajectory out-earns any non-accepting one over the horizon, and
        /// (d) a trajectory entering the trap earns less than any that never does.
        #[test]
        fn accepting_beats_not_accepting_and_the_trap_is_worst(
            f in co_safe(), trajs in trajectories(), gamma in 0.8..1.0f64, tight in any::<bool>(),
            goal_weight in prop_oneof![Just(0.0), 0.0..2.0f64], goal_span in 0.5..4.0f64
        ) {
            let spec = spec_for(&f);
            let aut = Automaton::build(&spec).unwrap();
            // An unsatisfiable task is refused (tested below).
            prop_assume!(ranks(&aut, &[])[aut.initial()].is_some());
            let horizon = 11; // every trajectory has 12 states = 11 steps
            let params = ProgressParams {
                gamma, scale: 2.0, horizon, goal_weight, goal_span, ..Default::default()
            };
            let mut r = ProgressReward::new(&aut, &params).unwrap();
            if tight {
                // The least bonus the guarantee allows (just above the bound).
                let band = f64::from(r.ranks().iter().flatten().max().copied().unwrap_or(0) + 1)
                    * (1.0 + goal_weight * goal_span);
                let least = band * (gamma.powi(1 - horizon as i32) - 1.0) - 1.0;
                let bonus = Some(least.max(0.0) + 1e-9);
                r = ProgressReward::new(&aut, &ProgressParams { bonus, ..params }).unwrap();
            }
            let horizon = horizon as usize;
            let (mut acc, mut non, mut trapped) = (vec![], vec![], vec![]);
            for data in &trajs {
                let (rewards, qs, _) = rollout(&aut, &r, data);
                let g = discounted(&rewards, gamma);
                let last = *qs.last().unwrap();
                if aut.is_accepting(last) {
                    acc.push(g);
                } else if qs.iter().any(|&q| Some(q) == aut.trap()) {
                    trapped.push(g);
                } else {
                    prop_assert_eq!(rewards.len(), horizon);
                    non.push(g);
                }
            }
            for a in &acc {
                for b in non.iter().chain(&trapped) {
                    prop_assert!(a > b, "accepting {a} <= non-accepting {b}");
                }
            }
            for n in &non {
                for b in &trapped {
                    prop_assert!(n > b, "never trapped {n} <= trapped {b}");
                }
            }
            // A trap step pays less than any step outside it.
            for data in &trajs {
                let (rewards, qs, _) = rollout(&aut, &r, data);
                for (k, rew) in rewards.iter().enumerate() {
                    if Some(qs[k + 1]) != aut.trap() {
                        prop_assert!(*rew > r.trap_penalty());
                    }
                }
            }
        }

        /// (b) Entering a state closer to acceptance never lowers Phi (bands ordered by rank)
        /// and pays at least what staying would have paid at the same s'.
        /// (c) Within one FSA state the reward orders next states by Eq. 5A1.
        #[test]
        fn progress_never_lowers_and_shaping_ranks_states(
            f in co_safe(), data in prop::collection::vec(-2.0..2.0f64, 3 * 12), gamma in 0.9..1.0f64,
            goal_weight in prop_oneof![Just(0.0), 0.0..2.0f64], goal_span in 0.5..4.0f64
        ) {
            let spec = spec_for(&f);
            let aut = Automaton::build(&spec).unwrap();
            prop_assume!(ranks(&aut, &[])[aut.initial()].is_some());
            let params = ProgressParams {
                gamma, scale: 2.0, goal_weight, goal_span, ..Default::default()
            };
            let width = 1.0 + goal_weight * goal_span;
            let r = ProgressReward::new(&aut, &params).unwrap();
            let states: Vec<&[f64]> = data.chunks(3).collect();
            let (mut q, mut phi) = (aut.step(states[0], aut.initial()).unwrap(), 0.0);
            for s in &states[1..] {
                let (qn, rew, pn) = r.advance(&aut, s, q, phi).unwrap();
                let rank = |q: usize| r.ranks()[q];
                if let (Some(a), Some(b)) = (rank(q), rank(qn)) {
                    if b < a && !aut.is_accepting(qn) {
                        let stay = r.potential(&aut.read(s).unwrap(), q);
                        prop_assert!(pn >= stay, "Phi {pn} < staying {stay}");
                        prop_assert!(rew >= stay - phi - r.step_cost() - 1e-12);
                    }
                }
                if aut.is_accepting(qn) { break; }
                q = qn;
                phi = pn;
            }
            // Bands: a state of rank k has Phi in [-(k + 1) B, -k B], so every Phi of a state is
            // at least every Phi of a state with a larger rank.
            for s in &states {
                let reading = aut.read(s).unwrap();
                for q in 0..aut.num_states() {
                    if let (Some(k), false) = (r.ranks()[q], aut.is_accepting(q)) {
                        let phi = r.potential(&reading, q);
                        let k = f64::from(k);
                        prop_assert!(
                            (-(k + 1.0) * width..=-k * width).contains(&phi),
                            "rank {k}: Phi {phi}"
                        );
                        // The goal term, against its definition from the public goal query.
                        let plain = ProgressReward::new(&aut, &ProgressParams {
                            goal_weight: 0.0, ..params.clone()
                        }).unwrap().potential(&reading, q);
                        let d = aut.goal(s, q).unwrap().map_or(goal_span, |g| {
                            // The goal lives in its region's position dimensions: a
                            // co_safe formula's predicates read s[0..g.len()].
                            g.iter().zip(s.iter()).map(|(g, x)| (x - g).powi(2)).sum::<f64>()
                                .sqrt().min(goal_span)
                        });
                        let want = plain - k * goal_weight * goal_span - goal_weight * d;
                        prop_assert!((phi - want).abs() < 1e-9, "Phi {phi}, want {want}");
                    }
                }
            }
            // (c) two next states that stay in q are ordered as Eq. 5A1 orders them (without
            // a goal term; with one, the bands' check above pins Phi down).
            let q = aut.step(states[0], aut.initial()).unwrap();
            if goal_weight == 0.0 && !aut.is_accepting(q) && Some(q) != aut.trap() {
                let mut stay = vec![];
                for s in &states[1..] {
                    if aut.step(s, q).unwrap() == q {
                        let (_, rew, _) = r.advance(&aut, s, q, -0.5).unwrap();
                        let sigma = aut.read(s).unwrap().reachable_reward(q, 1.0);
                        stay.push((sigma.min(0.0), rew));
                    }
                }
                for (s1, r1) in &stay {
                    for (s2, r2) in &stay {
                        if s1 > s2 { prop_assert!(r1 > r2); }
                        if s1 == s2 { prop_assert!((r1 - r2).abs() < 1e-12); }
                    }
                }
            }
        }
    }

    #[test]
    fn parking_loses_to_finishing_on_the_channel_like_task() {
        // A 1-D walk: a at 2, c at 5. Finish: walk 0 -> 2 -> 5. Park: walk to 1.4 and stay.
        let aut = channel_like();
        let atoms = aut.spec().atoms().to_vec();
        let bit = |name: &str| 1u32 << atoms.iter().position(|a| a == name).unwrap();
        let params = ProgressParams {
            scale: 10.0,
            exclusive: vec![bit("a") | bit("b") | bit("c")],
            ..Default::default()
        };
        let r = ProgressReward::new(&aut, &params).unwrap();
        let run = |path: &[f64]| {
            let (mut q, mut phi) = (aut.step(&path[..1], aut.initial()).unwrap(), 0.0);
            let mut rewards = vec![];
            for s in &path[1..] {
                let (qn, rew, pn) = r.advance(&aut, &[*s], q, phi).unwrap();
                rewards.push(rew);
                if aut.is_accepting(qn) {
                    break;
                }
                q = qn;
                phi = pn;
            }
            discounted(&rewards, 0.99)
        };
        let finish: Vec<f64> = (0..=60).map(|k| k as f64 * 0.1).collect();
        let park: Vec<f64> = (0..=200).map(|k| (k as f64 * 0.1).min(1.4)).collect();
        assert!(
            run(&finish) > run(&park) + 1.0,
            "{} vs {}",
            run(&finish),
            run(&park)
        );
    }
}
