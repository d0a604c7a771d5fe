"""tlshield/Channel-v0 and the wrappers: Gymnasium API, determinism, the shield's effect on
violations, goal sampling, vectorised shielding, and bad input."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tlshield
from tests.fixtures import progress_step
from tlshield.envs import CONFIGS, ENV_ID, ChannelEnv, channel_shield
from tlshield.envs.channel import GOAL_DIMS, RELATIVE_DIM, STATE_DIM, ChannelParams
from tlshield.wrappers import FsaAugmented, Shielded, ShieldedVecEnv, ShieldedVectorEnv

INFO_KEYS = {
    "fsa_state",
    "constraints",
    "min_obstacle_distance",
    "success",
    "collision",
    "violation",
    "shield",
    "trap",
    "tl_reward",
}


#: The vector shield wrappers read the state from the observation (state + one-hot FSA state)
#: and pass no drift: the paper's observation, without the moving-obstacle barrier.
STATE_OBS = {"observation": "paper", "obstacle_barrier": False}


@pytest.mark.parametrize("config", sorted(CONFIGS))
# check_env also renders in "human" mode; without a display the renderer says so once.
@pytest.mark.filterwarnings("ignore:ChannelRenderer.show")
def test_check_env_passes(config: str) -> None:
    env = gym.make(ENV_ID, config=config, render_mode="rgb_array")
    check_env(env.unwrapped)
    env.close()


def test_evaluation_env_passes_check_env_and_forces_the_cbf() -> None:
    env = gym.make(ENV_ID, config="rl", evaluation=True)
    check_env(env.unwrapped, skip_render_check=True)
    shield = env.unwrapped.shield
    assert shield is not None and "use_cbf=true" in repr(shield)


def rollout(env: gym.Env, seed: int, actions: np.ndarray) -> list[np.ndarray]:
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, _, term, trunc, _ = env.step(a)
        out.append(obs)
        if term or trunc:
            break
    return out


def test_same_seed_same_episode() -> None:
    actions = np.random.default_rng(0).uniform(-1, 1, size=(200, 2))
    first = rollout(gym.make(ENV_ID), 42, actions)
    second = rollout(gym.make(ENV_ID), 42, actions)
    assert len(first) == len(second)
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))
    other = rollout(gym.make(ENV_ID), 43, actions)
    assert not np.array_equal(first[0], other[0])


@pytest.mark.parametrize("observation", ["paper", "relative"])
def test_observation_layout_and_info(observation: str) -> None:
    env = gym.make(ENV_ID, observation=observation)
    obs, info = env.reset(seed=0)
    aut = env.unwrapped.spec_tl.automaton()
    dim = STATE_DIM if observation == "paper" else RELATIVE_DIM
    assert obs.shape == (dim + aut.num_states,)
    assert obs[dim:].sum() == 1 and obs[dim + info["fsa_state"]] == 1
    obs, reward, _, _, info = env.step(np.zeros(2))
    assert INFO_KEYS <= set(info)
    assert set(info["constraints"]) == {"c1", "c2"}
    s = env.unwrapped.state
    assert info["constraints"]["c1"] == pytest.approx(s[0] - s[1] + 1.5)
    if observation == "paper":
        np.testing.assert_array_equal(obs[:STATE_DIM], s)
    else:
        assert obs[0] == pytest.approx(math.cos(s[2])) and obs[1] == pytest.approx(math.sin(s[2]))
        assert obs[2] == pytest.approx(info["constraints"]["c1"])
        # In the agent's frame: x ahead, y to the left.
        c, si = math.cos(s[2]), math.sin(s[2])
        frame = np.array([[c, si], [-si, c]])
        np.testing.assert_allclose(obs[4:6], frame @ (s[3:5] - s[:2]))  # g1
        np.testing.assert_allclose(obs[10:12], frame @ (s[9:11] - s[:2]))  # o1
        np.testing.assert_allclose(obs[14:16], frame @ env.unwrapped.drift[9:11])
        goal = env.unwrapped.tracker.automaton.goal(s, info["fsa_state"])
        np.testing.assert_allclose(obs[18:20], frame @ (goal - s[:2]))
        ahead = s[:2] + 2.0 * np.array([c, si])  # a point 2 m straight ahead reads (2, 0)
        np.testing.assert_allclose(frame @ (ahead - s[:2]), [2.0, 0.0], atol=1e-12)
    assert set(info["shield"]) == {
        "a_rl",
        "a_cbf",
        "a_clf",
        "delta",
        "status",
        "slack",
        "gave_way",
        "solver",
        "goal",
        "goal_unreachable",
        "barriers",
    }
    assert isinstance(reward, float) and math.isfinite(reward)


def adversarial(env: ChannelEnv, obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Full speed towards the nearer wall (turning towards it), half of the time."""
    if rng.random() < 0.5:
        return rng.uniform(-1, 1, size=2)
    x, y, theta = env.state[:3]
    # Outward normal of the nearer wall: c1 (x - y + w) is nearer when x < y.
    wall = 3 * math.pi / 4 if x - y < 0 else -math.pi / 4
    heading_error = (wall - theta + math.pi) % (2 * math.pi) - math.pi
    return np.array([1.0, np.clip(2.0 * heading_error, -1, 1)])


def violations(config: str, policy: str, episodes: int = 200) -> tuple[int, float]:
    env = ChannelEnv(config=config)
    rng = np.random.default_rng(7)
    count, min_h = 0, math.inf
    for episode in range(episodes):
        obs, _ = env.reset(seed=episode)
        for _ in range(200):
            if policy == "random":
                action = rng.uniform(-1, 1, size=2)
            else:
                action = adversarial(env, obs, rng)
            obs, _, term, trunc, info = env.step(action)
            count += info["violation"]
            min_h = min(min_h, *info["constraints"].values())
            if term or trunc:
                break
    return count, min_h


@pytest.mark.parametrize("config", ["rl_cbf", "rl_cbf_clf"])
@pytest.mark.parametrize("policy", ["random", "adversarial"])
def test_cbf_prevents_every_channel_violation(config: str, policy: str) -> None:
    """200 episodes of 200 steps: with the CBF on, no state leaves the channel."""
    count, min_h = violations(config, policy)
    print(f"{config} {policy}: {count} violations, min h over visited states {min_h:.3e}")
    assert count == 0 and min_h >= 0.0


def test_without_the_cbf_violations_happen() -> None:
    count, min_h = violations("rl", "adversarial", episodes=50)
    print(f"rl adversarial: {count} violations, min h {min_h:.3e}")
    assert count > 0 and min_h < 0


def test_goal_draws() -> None:
    """Every episode is solvable (g3 and one of g1/g2 inside the channel), goals outside the
    channel occur, and the CLF never prefers one (its cube with the channel cannot hold, so the
    rank-aware goal passes it over; before issue 22 it did in some episodes)."""
    env = ChannelEnv()
    w = env.params.task.half_width
    n, outside, clf_outside = 500, 0, 0
    for seed in range(n):
        _, info = env.reset(seed=seed)
        centres = [env.state[a : b + 1] for a, b in GOAL_DIMS]
        inside = [
            abs(c[0] - c[1]) < w - env.params.task.goal_radius * math.sqrt(2) for c in centres
        ]
        assert inside[2] and (inside[0] or inside[1])
        outside += info["goal_outside_channel"]
        clf_outside += info["clf_goal_outside"]
    print(
        f"goal outside the channel: {outside / n:.1%}; CLF-preferred goal outside: "
        f"{clf_outside / n:.1%}"
    )
    assert 0.35 < outside / n < 0.65
    assert clf_outside == 0


def test_no_step_aims_at_a_goal_outside_the_channel() -> None:
    """With a goal drawn outside the channel in every episode, no shielded step's CLF goal
    (the task monitor's, which the shield reads) lies outside it: that goal cannot be reached
    while another can, and the rank-aware choice, restricted to goals that can be reached,
    passes it over. (``info["shield"]["goal"]`` is the routed target, which may lie anywhere
    along the way's direction.)"""
    env = gym.make(ENV_ID, config="rl_cbf_clf", outside_goal_probability=1.0).unwrapped
    w = env.params.task.half_width
    rng = np.random.default_rng(0)
    steps = 0
    for seed in range(20):
        env.reset(seed=seed)
        for _ in range(100):
            _, _, term, trunc, _ = env.step(rng.uniform(-1.0, 1.0, 2))
            goal = env.tracker.goal
            assert goal is not None and abs(goal[1] - goal[0]) <= w, (seed, goal)
            steps += 1
            if term or trunc:
                break
    assert steps > 1000


def test_overrides_and_bad_input() -> None:
    env = gym.make(ENV_ID, config="rl_clf", k=1e3, dt=0.05, horizon=10, c_r=2.0)
    assert env.unwrapped.params.task.horizon == 10 and env.unwrapped.params.shield.k == 1e3
    env.reset(seed=0)
    steps = 0
    while True:
        steps += 1
        _, _, term, trunc, _ = env.step(np.zeros(2))
        if term or trunc:
            break
    assert steps <= 10
    with pytest.raises(ValueError, match="config"):
        ChannelEnv(config="cbf")
    with pytest.raises(TypeError, match="unknown Channel-v0 parameter"):
        ChannelEnv(alhpa=1.0)
    with pytest.raises(ValueError, match="alpha \\* dt"):
        ChannelEnv(alpha=20.0)
    with pytest.raises(ValueError, match="dt"):
        ChannelEnv(dt=-0.1)
    with pytest.raises(ValueError, match="render_mode"):
        ChannelEnv(render_mode="ascii")
    env = ChannelEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action\[0\] is NaN"):
        env.step(np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match=r"action: expected 2 values"):
        env.step(np.zeros(3))


def test_a_goal_range_too_short_for_two_goals_is_rejected_at_make() -> None:
    """g1 and g2 are drawn until apart: a range where they cannot be would draw forever."""
    with pytest.raises(ValueError, match="near_goal_u"):
        gym.make(ENV_ID, near_goal_u=(0.8, 1.2))
    env = gym.make(ENV_ID, near_goal_u=(1.0, 2.0))
    for seed in range(20):
        env.reset(seed=seed)  # short, but wide enough: every draw ends


def test_a_channel_too_narrow_for_the_goals_is_rejected_at_make() -> None:
    # w / sqrt(2) = 0.42 < goal_radius 0.5: no goal disc fits inside the channel. Before the
    # check, make() accepted it and reset() failed inside numpy (high - low < 0).
    with pytest.raises(ValueError, match="goal disc must fit inside the channel"):
        gym.make(ENV_ID, half_width=0.6)
    # Wider channel, same outside-goal band: an "outside" goal would overlap the channel.
    with pytest.raises(ValueError, match="outside_goal_v"):
        gym.make(ENV_ID, half_width=2.0)
    env = gym.make(ENV_ID, half_width=2.0, outside_goal_v=(2.0, 2.5))
    env.reset(seed=0)


def test_reset_reports_a_start_in_the_trap() -> None:
    # A start spread wider than the channel puts some s_0 outside it: the automaton is in the
    # trap from the first state, and reset's info must say so.
    env = ChannelEnv(start_spread=3.0)
    trap = env.tracker.automaton.trap
    seen = set()
    for seed in range(40):
        _, info = env.reset(seed=seed)
        assert info["trap"] == (info["fsa_state"] == trap)
        assert info["trap"] == (info["constraints"]["c1"] < 0 or info["constraints"]["c2"] < 0)
        seen.add(info["trap"])
    assert seen == {True, False}


def test_rgb_render() -> None:
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.zeros(2))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3


# --- the wrappers on someone else's environment ---------------------------------------------


class PointEnv(gym.Env):
    """A 2-D single integrator: reach the disc at (3, 0) while staying in y < 1."""

    observation_space = gym.spaces.Box(-10, 10, shape=(2,), dtype=np.float64)
    action_space = gym.spaces.Box(-1, 1, shape=(2,), dtype=np.float64)

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        self.p = np.array([0.0, 0.5])
        return self.p.copy(), {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        self.p = self.p + 0.1 * np.asarray(action)
        return self.p.copy(), -1.0, False, False, {}


def point_spec() -> tlshield.Spec:
    return tlshield.Spec(
        "(below U goal)",
        {
            "goal": tlshield.Ball([0, 1], 0.3, center=[3.0, 0.0]),
            "below": tlshield.Halfspace([0.0, -1.0], 1.0),
        },
    )


def test_fsa_augmented_and_shielded_on_a_user_env() -> None:
    spec = point_spec()
    env = FsaAugmented(PointEnv(), spec, c_r=1.0, w=0.5, trap_penalty=-50.0, reward="paper")
    aut = spec.automaton()
    obs, info = env.reset(seed=0)
    assert obs.shape == (2 + aut.num_states,) and info["fsa_state"] == env.fsa_state
    q = env.fsa_state
    obs, reward, _, _, info = env.step(np.array([1.0, 0.0]))
    expected = aut.reward(obs[:2], q, 1.0) + 0.5 * -1.0
    assert reward == pytest.approx(expected)
    shield = tlshield.Shield(
        spec,
        tlshield.SingleIntegrator([0, 1]),
        alpha=5.0,
        c3=1.0,
        k=1e4,
        cbf_bounds=(-3, 3),
        clf_bounds=(-0.5, 0.5),
    )
    shielded = Shielded(env, shield)
    obs, _ = shielded.reset(seed=0)
    for _ in range(100):
        obs, _, term, _, info = shielded.step(np.array([0.0, 1.0]))  # straight at the wall
        assert obs[1] < 1.0 + 1e-9
        assert info["shield"]["status"] == tlshield.Status.SOLVED
        if term:
            break
    with pytest.raises(TypeError, match="FsaAugmented"):
        Shielded(PointEnv(), shield)
    # action_fn maps the policy's action to the shield's units, as the vector wrappers' does:
    # the shield sees (and info reports) the mapped action, the env gets the shielded one.
    scaled = Shielded(env, shield, action_fn=lambda a: 0.5 * np.asarray(a))
    obs, _ = scaled.reset(seed=0)
    q = env.fsa_state
    _, _, _, _, info = scaled.step(np.array([0.4, -0.2]))
    ref = shield.filter(obs[:2], q, np.array([0.2, -0.1]))
    assert info["shield"]["a_rl"].tolist() == [0.2, -0.1]
    assert info["shield"]["a_cbf"].tolist() == ref.a_cbf.tolist()
    applied = info["shield"]["a_rl"] + info["shield"]["a_cbf"] + info["shield"]["a_clf"]
    assert applied.tolist() == ref.action.tolist()


def test_shielded_routes_the_trackers_goal_term_when_it_can() -> None:
    """A routing shield of the tracker's own automaton routes the goal term; one of another
    task's automaton cannot, and says so instead of failing."""
    spec = point_spec()
    barriers = {"!o": tlshield.Avoid(tlshield.Ball([0, 1], 0.5, center=[1.5, 0.0]))}
    settings = dict(alpha=5.0, c3=1.0, k=1e4, cbf_bounds=(-3, 3), clf_bounds=(-0.5, 0.5))
    model = tlshield.SingleIntegrator([0, 1])
    env = FsaAugmented(PointEnv(), spec)
    Shielded(env, tlshield.Shield(spec, model, barriers=barriers, **settings))
    monitor = env.tracker.monitor
    assert monitor.routed_by is not None
    env.reset(seed=0)
    assert monitor.goal_distance > np.hypot(3.0, 0.5) + 1e-3  # the way round the disc
    elsewhere = {"goal": tlshield.Ball([0, 1], 0.3, center=[2.5, 0.0])}
    other = FsaAugmented(PointEnv(), tlshield.Spec("F goal", elsewhere))
    with pytest.warns(UserWarning, match="straight distance"):
        Shielded(other, tlshield.Shield(spec, model, barriers=barriers, **settings))
    assert other.tracker.monitor.routed_by is None


def test_fsa_augmented_reset_reports_a_start_in_the_trap() -> None:
    # The wrapped env starts above the y < 1 line: the automaton is in the trap from s_0.
    class AboveEnv(PointEnv):
        def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[Any, dict]:
            super().reset(seed=seed)
            self.p = np.array([0.0, 2.0])
            return self.p.copy(), {}

    spec = point_spec()
    _, info = FsaAugmented(AboveEnv(), spec).reset(seed=0)
    assert info["trap"] and info["fsa_state"] == spec.automaton().trap
    _, info = FsaAugmented(PointEnv(), spec).reset(seed=0)
    assert not info["trap"]


def test_fsa_augmented_pays_the_progress_reward_by_default() -> None:
    spec = point_spec()
    env = FsaAugmented(PointEnv(), spec, gamma=0.9, scale=2.0)
    aut = spec.automaton()
    progress = aut.progress_reward(gamma=0.9, scale=2.0)
    obs, _ = env.reset(seed=0)
    q, phi = env.fsa_state, 0.0
    for _ in range(5):
        obs, reward, _, _, info = env.step(np.array([1.0, 0.0]))
        q, expected, phi = progress_step(aut, progress, q, phi, obs[:2])
        assert reward == pytest.approx(expected) and info["tl_reward"] == pytest.approx(expected)
    with pytest.raises(ValueError, match="reward"):
        FsaAugmented(PointEnv(), spec, reward="eq5a1")


def test_gymnasium_vector_shield_equals_per_env_shield() -> None:
    n, seeds = 4, [10, 11, 12, 13]
    vec = gym.vector.SyncVectorEnv(
        [lambda: ChannelEnv(shield_in_env=False, **STATE_OBS) for _ in range(n)]
    )
    cfg = ChannelParams.from_flat(STATE_OBS)
    singles = [ChannelEnv(**STATE_OBS) for _ in range(n)]
    shielded = ShieldedVectorEnv(
        vec, channel_shield(cfg, "rl_cbf_clf"), action_fn=singles[0].rl_action
    )
    obs, _ = shielded.reset(seed=seeds)
    single_obs = [env.reset(seed=s)[0] for env, s in zip(singles, seeds, strict=True)]
    np.testing.assert_array_equal(obs, np.stack(single_obs))
    rng = np.random.default_rng(0)
    for _ in range(30):
        actions = rng.uniform(-1, 1, size=(n, 2))
        obs, _, _, _, infos = shielded.step(actions)
        steps = [env.step(a) for env, a in zip(singles, actions, strict=True)]
        np.testing.assert_allclose(obs, np.stack([st[0] for st in steps]), atol=1e-12)
        # Gymnasium's vector infos: a dict of arrays, one row per sub-env, each row the
        # single env's correction.
        shield = infos["shield"]
        assert {k: v.shape[0] for k, v in shield.items()} == dict.fromkeys(shield, n)
        for key in ("a_rl", "a_cbf", "a_clf"):
            want = np.stack([st[4]["shield"][key] for st in steps])
            np.testing.assert_allclose(shield[key], want, atol=1e-12)
        assert shield["status"].tolist() == [st[4]["shield"]["status"].value for st in steps]


def test_sb3_vecenv_shield_equals_per_env_shield() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    n = 3
    venv = DummyVecEnv([lambda: ChannelEnv(shield_in_env=False, **STATE_OBS) for _ in range(n)])
    venv.seed(5)
    singles = [ChannelEnv(config="rl_cbf", **STATE_OBS) for _ in range(n)]
    shielded = ShieldedVecEnv(
        venv,
        channel_shield(ChannelParams.from_flat(STATE_OBS), "rl_cbf"),
        action_fn=singles[0].rl_action,
    )
    obs = shielded.reset()
    expected = np.stack([env.reset(seed=5 + i)[0] for i, env in enumerate(singles)])
    np.testing.assert_array_equal(obs, expected)
    rng = np.random.default_rng(1)
    for _ in range(20):
        actions = rng.uniform(-1, 1, size=(n, 2))
        obs, _, _, infos = shielded.step(actions)
        want = np.stack([env.step(a)[0] for env, a in zip(singles, actions, strict=True)])
        np.testing.assert_allclose(obs, want, atol=1e-12)
        assert all("shield" in info for info in infos)


def test_obstacles_in_the_task_option() -> None:
    """Beyond the paper: with the obstacles in the formula, the CBF safe set keeps the agent
    out of them as well as in the channel."""
    env = ChannelEnv(obstacles_in_task=True)
    check_env(env, skip_render_check=True)
    env.reset(seed=0)
    assert {"o1", "o2"} <= set(env.spec_tl.atoms)
    out = env.shield.filter(env.state, env.tracker.q, np.zeros(2))
    names = [name for name, _ in out.barriers]
    assert {"c1", "c2", "!o1", "!o2"} <= set(names)
    assert ChannelEnv().spec_tl.atoms == ["g1", "g2", "g3", "c1", "c2"]


def test_obstacle_velocity_is_measured_and_passed_to_the_shield() -> None:
    env = ChannelEnv(config="rl_cbf")
    env.reset(seed=3)
    before = env.state[9:13].copy()
    env.step(np.zeros(2))
    np.testing.assert_allclose(env.drift[9:13], (env.state[9:13] - before) / env.params.agent.dt)
    assert env.drift[:9].tolist() == [0.0] * 9
    out = env.shield.filter(env.state, env.tracker.q, np.zeros(2), drift=env.drift)
    assert {"!o1", "!o2"} <= {name for name, _ in out.barriers}
    off = ChannelEnv(config="rl_cbf", obstacle_barrier=False)
    off.reset(seed=3)
    names = {n for n, _ in off.shield.filter(off.state, off.tracker.q, np.zeros(2)).barriers}
    assert not names & {"!o1", "!o2"}


def test_the_moving_obstacle_barrier_prevents_most_collisions() -> None:
    """20k adversarial steps (benches/moving_obstacles.py runs 100k): the measured drift cuts
    collisions against the barrier that treats the obstacles as standing still."""
    from benches.moving_obstacles import attack

    moving = attack(20_000, 1, "rl_cbf")
    static = attack(20_000, 1, "rl_cbf", obstacle_drift=False)
    print(f"moving: {moving}\nstatic: {static}")
    assert moving["violations"] == 0 and moving["failed"] == 0
    assert moving["collisions"] * 10 < static["collisions"]
    assert moving["min_distance"] > static["min_distance"]


@pytest.mark.parametrize("config", ["rl", "rl_cbf_clf"])
def test_the_core_world_steps_as_the_numpy_reference(config: str) -> None:
    """Plant, obstacles, drift, observation and reward terms of the world the core steps,
    against an independent numpy version (tests/channel_reference.py), over seeded episodes
    that drive into walls (the shield acts) and through the task."""
    from tests import channel_reference as ref

    env = ChannelEnv(config=config)
    cfg = env.params
    rng = np.random.default_rng(2)
    steps = 0
    for episode in range(6):
        env.reset(seed=100 + episode)
        paths = env._obstacles.copy()
        s = env.state
        for t in range(1, cfg.task.horizon + 1):
            action = rng.uniform(-1, 1, 2)
            if episode % 2:  # full speed ahead, turning slowly: into a wall
                action = np.array([1.0, 0.2])
            obs, reward, terminated, truncated, info = env.step(action)
            want = ref.next_state(cfg, s, info["action"], paths, t)
            np.testing.assert_allclose(env.state, want, rtol=0, atol=1e-12)
            drift = np.zeros(13)
            drift[9:13] = (want[9:13] - s[9:13]) / cfg.agent.dt
            np.testing.assert_allclose(env.drift, drift, rtol=0, atol=1e-12)
            one_hot = np.eye(env.tracker.automaton.num_states)[info["fsa_state"]]
            expected = ref.observation(cfg, want, drift, env.tracker.goal, one_hot)
            np.testing.assert_allclose(obs, expected, rtol=0, atol=1e-12)
            rho = env.spec_tl.atom_robustness(want)
            c1, c2 = env.spec_tl.atoms.index("c1"), env.spec_tl.atoms.index("c2")
            assert info["constraints"] == {"c1": rho[c1], "c2": rho[c2]}
            d = min(float(np.hypot(*(want[:2] - want[a : b + 1]))) for a, b in ref.OBSTACLE_DIMS)
            assert info["min_obstacle_distance"] == d
            collision = d < cfg.obstacles.obstacle_radius
            terms = (
                cfg.obstacles.w * min(d - cfg.obstacles.safe_distance, 0.0)
                - cfg.obstacles.collision_penalty * collision
            )
            # end_on_trap (the default): the step entering the trap ends the episode and pays
            # the trap's reward for every step left.
            ends_in_trap = cfg.task.end_on_trap and info["trap"]
            lump = info["tl_reward"] * (cfg.task.horizon - t) if ends_in_trap else 0.0
            assert reward == pytest.approx(info["tl_reward"] + terms + lump, abs=1e-9)
            assert terminated == (info["success"] or ends_in_trap)
            s = want
            steps += 1
            if terminated or truncated:
                break
    assert steps > 300


def test_end_on_trap_ends_a_training_episode_where_it_leaves_the_channel() -> None:
    """``end_on_trap``: the step entering the trap terminates and also pays the trap penalty of
    every step left to the horizon; without it the episode goes on in the trap, paying it
    every step. The same states and rewards up to there, and a shielded configuration (which
    never enters the trap) runs unchanged."""
    runs = {}
    for end in (False, True):
        env = ChannelEnv(config="rl", end_on_trap=end)
        env.reset(seed=3)
        rewards, states = [], []
        for _ in range(200):
            _, reward, terminated, truncated, info = env.step(np.array([1.0, -0.3]))
            rewards.append(reward)
            states.append(env.state.copy())
            if terminated or truncated or len(rewards) > 40:
                break
        runs[end] = (rewards, states, terminated, info["trap"])
    (kept, kept_states, kept_term, kept_trap), (ended, ended_states, term, trap) = (
        runs[False],
        runs[True],
    )
    assert trap and term and kept_trap and not kept_term
    k = len(ended)
    assert k < len(kept) and kept[: k - 1] == ended[:-1]
    np.testing.assert_array_equal(np.array(kept_states[:k]), np.array(ended_states))
    penalty = env.tracker.trap_penalty
    assert all(r <= penalty for r in kept[k - 1 :])
    horizon = env.params.task.horizon
    assert ended[-1] == pytest.approx(kept[k - 1] + penalty * (horizon - k))
    # With the CBF the trap is never entered: the option changes nothing.
    shielded = {}
    for end in (False, True):
        env = ChannelEnv(config="rl_cbf", end_on_trap=end)
        env.reset(seed=3)
        shielded[end] = [env.step(np.array([1.0, -0.3]))[1] for _ in range(60)]
    assert shielded[False] == shielded[True]


def test_the_core_world_is_built_from_one_params_object() -> None:
    """ChannelWorld reads every setting from the env's ChannelParams (one spelling of each
    constant); an object that is not one is a TypeError naming the missing field."""
    from tlshield._core import ChannelWorld

    env = ChannelEnv(config="rl_cbf_clf", end_on_trap=False)
    ChannelWorld(env.model, env.params, evaluation=True, channel_atoms=(0, 1))
    with pytest.raises(
        TypeError, match=r"params: expected a ChannelParams \(no agent\.rl_bounds\)"
    ):
        ChannelWorld(env.model, object(), evaluation=True, channel_atoms=(0, 1))
