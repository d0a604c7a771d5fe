"""The progress-aware task reward: its Python API, bad input, and the reward-loophole checks
on Channel-v0 with scripted policies (finish vs. park, barge vs. go around, the trap)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tlshield
from tests.scripted import discounted_return, finish, first_goal, park, towards
from tlshield import Ball, Spec
from tlshield.envs.channel import ChannelEnv, ChannelParams, task_spec
from tlshield.envs.layout import OBSTACLE_DIMS
from tlshield.wrappers import FsaTracker


def automaton():
    return task_spec(ChannelParams()).automaton()


def test_ranks_count_transitions_with_exclusive_goals() -> None:
    aut = automaton()
    # The goals' centres live in the state: without the spec's declared exclusivity the
    # geometry cannot tell them apart, and one valuation could hold g1 and g3 at once.
    declared = aut.spec
    assert declared.exclusive == [["g1", "g2", "g3"]]
    undeclared = Spec(str(declared), declared.predicates).automaton()
    loose = undeclared.progress_reward()
    tight = undeclared.progress_reward(exclusive=[["g1", "g2", "g3"]])
    q0, acc, trap = aut.initial, aut.accepting[0], aut.trap
    assert tight.ranks[q0] == 2 and loose.ranks[q0] == 1
    assert aut.progress_reward().ranks == tight.ranks == aut.ranks
    assert tight.ranks[acc] == 0 and tight.ranks[trap] is None
    # Defaults: step cost (1 - gamma) (max rank + 1); bonus (max rank + 1) gamma^(1 - T).
    assert tight.step_cost == pytest.approx(0.01 * 3)
    assert tight.bonus == pytest.approx(3 * 0.99 ** (1 - 200))
    assert tight.trap_penalty < -3 - tight.step_cost
    assert "ranks=[2, None, 0, 1]" in repr(tight)
    # Shorter episodes or a longer discount need a smaller bonus.
    assert aut.progress_reward(horizon=50).bonus < loose.bonus


def test_potential_and_the_monitors_reward_agree() -> None:
    aut = automaton()
    r = aut.progress_reward(gamma=0.9, scale=2.0, exclusive=[["g1", "g2", "g3"]])
    s = np.zeros(13)
    s[3:9] = [3.0, 3.0, 2.0, 4.0, 8.0, 8.0]
    s2 = s.copy()
    s2[:2] = [0.5, 0.5]
    q = aut.step(s, aut.initial)
    phi = r.potential(s, q)
    assert -3.0 < phi <= -2.0
    monitor = tlshield.Monitor(aut, r)
    monitor.reset(s)  # an episode starts at phi = 0; one step at s makes it Phi(s, q)
    monitor.advance(s)
    step = monitor.advance(s2)
    phi2 = r.potential(s2, q)
    assert step.q == q
    assert step.reward == pytest.approx(phi2 - phi - r.step_cost)
    assert phi2 > phi  # closer to g1


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"gamma": 0.0}, "gamma"),
        ({"gamma": 1.5}, "gamma"),
        ({"scale": -1.0}, "scale"),
        ({"bonus": -1.0}, "bonus"),
        ({"bonus": 5.0}, "finishing out-earns not finishing"),
        ({"horizon": 0}, "horizon"),
        ({"horizon": -5}, "horizon"),
        ({"step_cost": math.nan}, "step_cost"),
        ({"exclusive": [["g1", "nope"]]}, 'exclusive names "nope", which is not an atom'),
        ({"goal_weight": -0.5}, "goal_weight"),
        ({"goal_weight": math.inf}, "goal_weight"),
        ({"goal_weight": 0.5, "goal_span": 0.0}, "goal_span"),
        ({"goal_weight": 0.5, "goal_span": math.nan}, "goal_span"),
        ({"goal_weight": 1e300, "goal_span": 1e300}, "goal_weight"),
    ],
)
def test_bad_parameters_raise(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        automaton().progress_reward(**kwargs)


def test_bad_calls_raise() -> None:
    r = automaton().progress_reward()
    with pytest.raises(ValueError, match="state 99 does not exist"):
        r.potential(np.zeros(13), 99)
    with pytest.raises(ValueError, match="state length: expected 13, got 3"):
        r.potential(np.zeros(3), 0)
    with pytest.raises(ValueError, match="another automaton"):
        other = Spec("F g", {"g": Ball(pos=[0, 1], radius=1.0, center=[0.0, 0.0])}).automaton()
        FsaTracker(other, 1.0, -1.0, r)


def test_goal_term_is_the_distance_to_the_clf_goal() -> None:
    """The goal term against its definition, from the public goal query and ranks:
    ``Phi_k = Phi_0 - k span rank(q) - k min(|p - goal(s, q)|, span)`` (floor ``-k span``
    without a goal), on random states in every FSA state."""
    import pickle

    aut = automaton()
    k, span = 0.5, 6.0
    plain = aut.progress_reward(scale=2.0)
    shaped = aut.progress_reward(scale=2.0, goal_weight=k, goal_span=span)
    assert (shaped.goal_weight, shaped.goal_span) == (k, span)
    copy = pickle.loads(pickle.dumps(shaped))
    assert (copy.goal_weight, copy.goal_span, copy.bonus) == (k, span, shaped.bonus)
    # The bonus and trap penalty cover the widened bands: (max rank + 1) (1 + k span).
    assert shaped.bonus == pytest.approx(plain.bonus * (1 + k * span))
    assert shaped.trap_penalty < plain.trap_penalty
    rng = np.random.default_rng(0)
    seen_far = False
    for _ in range(300):
        s = np.zeros(13)
        s[:2] = rng.uniform(-3, 13, size=2)
        s[2] = rng.uniform(-math.pi, math.pi)
        s[3:13] = rng.uniform(-1, 10, size=10)
        for q in range(aut.num_states):
            if q in aut.accepting:
                assert shaped.potential(s, q) == 0.0
                continue
            goal = aut.goal(s, q)
            d = span if goal is None else min(float(np.linalg.norm(s[:2] - goal)), span)
            seen_far |= goal is not None and d == span
            rank = aut.ranks[q]
            rank = max(r for r in aut.ranks if r is not None) + 1 if rank is None else rank
            want = plain.potential(s, q) - k * span * rank - k * d
            assert shaped.potential(s, q) == pytest.approx(want, abs=1e-9)
    assert seen_far  # the clamp at span was exercised


@pytest.mark.parametrize(
    ("config", "overrides"),
    [
        ("rl_cbf_clf", {}),  # Channel-v0's default
        ("rl_cbf", {}),
        # Without a shield the straight-line finisher sometimes drives through an obstacle; the
        # collision cost is checked by the barging test, so here the task reward alone.
        ("rl", {"collision_penalty": 0.0, "w": 0.0}),
        # Without the goal term, and with a strong one.
        ("rl_cbf", {"goal_weight": 0.0}),
        ("rl_cbf", {"goal_weight": 2.0}),
    ],
)
def test_finishing_out_earns_parking_on_every_seed(config: str, overrides: dict) -> None:
    env = ChannelEnv(config=config, **overrides)
    for seed in range(20):
        done, ok, _ = discounted_return(env, finish, seed)
        parked, parked_ok, _ = discounted_return(env, park, seed)
        assert ok and not parked_ok
        assert done > parked, f"seed {seed}: finish {done:.2f} <= park {parked:.2f}"


def _leave_the_channel(env: ChannelEnv) -> np.ndarray:
    """Drives straight across the channel's wall (into the trap)."""
    p = env.state[:2]
    return towards(env, p + 3.0 * np.array([1.0, -1.0]) / math.sqrt(2))


@pytest.mark.parametrize("goal_weight", [0.0, 0.5])
def test_ending_early_in_the_trap_never_pays(goal_weight: float) -> None:
    """With ``end_on_trap`` an episode ends in the trap: leaving the channel at once must still
    earn less than parking and than finishing (no escape from a bad episode by ending it)."""
    env = ChannelEnv(config="rl", end_on_trap=True, goal_weight=goal_weight, w=0.0)
    for seed in range(20):
        left, left_ok, _ = discounted_return(env, _leave_the_channel, seed)
        assert not left_ok and env.tracker.trapped
        parked, _, _ = discounted_return(env, park, seed)
        done, ok, _ = discounted_return(env, finish, seed)
        assert ok and left < parked < done, f"seed {seed}: {left:.2f}, {parked:.2f}, {done:.2f}"


def test_the_paper_reward_pays_parking() -> None:
    """The loophole the progress reward closes, measured on Eq. 5A1 itself."""
    env = ChannelEnv(config="rl", reward="paper")
    wins = sum(
        discounted_return(env, park, s)[0] > discounted_return(env, finish, s)[0] for s in range(20)
    )
    assert wins == 20


def _static_obstacle_on_the_way(env: ChannelEnv, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Resets with obstacle 1 standing halfway to the first goal and obstacle 2 far away (the
    episode's own start and goals: the same seed, the paths given as reset options)."""
    env.reset(seed=seed)
    p, g = env.state[:2].copy(), first_goal(env)
    middle = (p + g) / 2
    # (u, amplitude, frequency, phase): frequency 0 stands still at v = amplitude.
    u, v = (middle[0] + middle[1]) / math.sqrt(2), (middle[1] - middle[0]) / math.sqrt(2)
    paths = [(u, v, 0.0, math.pi / 2), (50.0, 0.0, 0.0, 0.0)]
    env.reset(seed=seed, options={"obstacles": paths})
    assert np.allclose(env.state[:2], p) and np.allclose(first_goal(env), g)
    assert np.allclose(env.state[list(OBSTACLE_DIMS[0])], middle)
    assert not env.drift.any()
    return middle, g


@pytest.mark.parametrize("seed", range(10))
def test_barging_through_an_obstacle_never_out_earns_going_around(seed: int) -> None:
    gamma = ChannelParams().gamma
    returns = {}
    for way in ("barge", "around"):
        env = ChannelEnv(config="rl")
        middle, g = _static_obstacle_on_the_way(env, seed)
        p = env.state[:2].copy()
        d = (g - p) / np.linalg.norm(g - p)
        side = np.array([-d[1], d[0]])
        # Pass on the side nearer the channel's centre line, 0.7 m from the obstacle.
        waypoint = min((middle + 0.7 * side, middle - 0.7 * side), key=lambda w: abs(w[1] - w[0]))
        detour = [waypoint, g] if way == "around" else [g]
        total, discount, collisions = 0.0, 1.0, 0
        for _ in range(env.params.horizon):
            if env.tracker.q == env.tracker.automaton.initial:
                while len(detour) > 1 and np.linalg.norm(env.state[:2] - detour[0]) < 0.15:
                    detour.pop(0)
                action = towards(env, detour[0])
            else:
                action = towards(env, env.state[7:9])
            _, reward, terminated, truncated, info = env.step(action)
            total += discount * reward
            discount *= gamma
            collisions += info["collision"]
            if terminated or truncated:
                break
        assert info["success"], way
        returns[way] = (total, collisions)
    (barge, hits), (around, missed) = returns["barge"], returns["around"]
    assert hits > 0 and missed == 0
    assert around > barge, f"around {around:.2f} <= barge {barge:.2f}"


@pytest.mark.parametrize("reward", ["progress", "paper"])
def test_trap_never_pays_better_than_outside(reward: str) -> None:
    # Episodes go on in the trap, so every trap step's reward is seen.
    env = ChannelEnv(config="rl", reward=reward, end_on_trap=False)
    rng = np.random.default_rng(1)
    worst, trapped_steps = math.inf, 0
    penalty = env.tracker.trap_penalty
    for seed in range(30):
        env.reset(seed=seed)
        in_trap = False
        for _ in range(200):
            _, _, term, trunc, info = env.step(rng.uniform(-1, 1, size=2))
            if in_trap or (info["trap"] and reward == "progress"):
                # Eq. 5A1 pays the step entering the trap from its source state.
                assert info["tl_reward"] == penalty
                trapped_steps += 1
            elif not info["trap"]:
                worst = min(worst, info["tl_reward"])
            in_trap = info["trap"]
            if term or trunc:
                break
    assert trapped_steps > 0
    assert penalty <= worst


def test_progress_defaults_live_once_in_the_core() -> None:
    """Issue 36: the progress reward's defaults are the core's (tlshield._core.DEFAULT_*),
    read by Automaton.progress_reward and FsaAugmented alike, not typed again."""
    import inspect

    from tlshield import _core
    from tlshield.wrappers import FsaAugmented

    spec = Spec("F a", {"a": Ball([0, 1], 0.5, [1.0, 0.0])})
    implicit = spec.automaton().progress_reward()
    explicit = spec.automaton().progress_reward(
        gamma=_core.DEFAULT_GAMMA,
        horizon=_core.DEFAULT_HORIZON,
        scale=_core.DEFAULT_PROGRESS_SCALE,
        c_r=_core.DEFAULT_C_R,
    )
    assert (implicit.bonus, implicit.step_cost) == (explicit.bonus, explicit.step_cost)
    other = spec.automaton().progress_reward(horizon=_core.DEFAULT_HORIZON + 1)
    assert other.bonus != implicit.bonus  # the bonus depends on the horizon it defaults
    defaults = inspect.signature(FsaAugmented).parameters
    assert defaults["gamma"].default == _core.DEFAULT_GAMMA
    assert defaults["horizon"].default == _core.DEFAULT_HORIZON
    assert defaults["scale"].default == _core.DEFAULT_PROGRESS_SCALE
    assert defaults["c_r"].default == _core.DEFAULT_C_R
