"""tlshield/PointMass-v0: Gymnasium API, the task wiring, and the higher-order shield keeping
a double integrator out of the obstacles against a policy that drives straight through them."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tlshield
from tlshield.envs import POINT_MASS_ID
from tlshield.envs.point_mass import CONFIGS, PointMassParams, make_point_mass

CFG = PointMassParams()


# The whole stack is checked on purpose (a user's env is the wrapped one), so the checker's
# "different from the unwrapped version" notice is expected.
@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")
@pytest.mark.parametrize("config", sorted(CONFIGS))
def test_check_env_passes(config: str) -> None:
    check_env(make_point_mass(config), skip_render_check=True)
    env = gym.make(POINT_MASS_ID, config=config)
    obs, info = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape and info["fsa_state"] == 0


def before_a(env: gym.Env) -> bool:
    """Whether the task is still at its start (a not yet visited)."""
    tracker = env.get_wrapper_attr("tracker")
    return bool(tracker.q == tracker.automaton.initial)


def straight(env: gym.Env, obs: np.ndarray) -> np.ndarray:
    """Full acceleration straight at the current goal (a, then b), braking near it: the
    straight lines cross o1 and o2."""
    p, v = obs[:2], obs[2:4]
    goal = np.array(CFG.goal_a if before_a(env) else CFG.goal_b)
    return np.clip(2.0 * (goal - p) - 2.0 * v, -1.0, 1.0)


def run(config: str, policy: object, seed: int) -> tuple[int, bool, float]:
    env = make_point_mass(config)
    obs, _ = env.reset(seed=seed)
    entries, min_h = 0, math.inf
    for _ in range(CFG.horizon):
        obs, _, terminated, truncated, info = env.step(policy(env, obs))  # type: ignore[operator]
        entries += info["collision"]
        min_h = min(min_h, info["min_obstacle_distance"])
        if terminated or truncated:
            return entries, bool(info["success"]), min_h
    return entries, False, min_h


def test_the_hocbf_keeps_a_straight_driver_out_of_the_obstacles() -> None:
    for seed in range(3):
        unshielded, _, _ = run("rl", straight, seed)
        assert unshielded > 0  # the attack is real
        entries, _, min_h = run("rl_cbf", straight, seed)
        assert entries == 0 and min_h > 0.0, (seed, min_h)


def waypoints(env: gym.Env, obs: np.ndarray) -> np.ndarray:
    """Past o1 on its right, to a; then over o2, to b."""
    p, v = obs[:2], obs[2:4]
    if before_a(env):
        target = (3.2, 6.0) if p[1] < 5.5 else CFG.goal_a
    else:
        target = (5.0, 9.8) if p[0] < 4.9 else CFG.goal_b
    return np.clip(1.5 * (np.array(target) - p) - 2.0 * v, -1.0, 1.0)


def test_the_task_is_doable_and_finishing_ends_the_episode() -> None:
    for seed in range(3):
        entries, success, _ = run("rl", waypoints, seed)
        assert success and entries == 0, seed


def test_bad_settings_are_rejected_at_make() -> None:
    with pytest.raises(ValueError, match="overlap"):
        gym.make(POINT_MASS_ID, obstacle_radius=4.0)
    with pytest.raises(ValueError, match="config"):
        gym.make(POINT_MASS_ID, config="cbf")
    with pytest.raises(TypeError, match="unknown PointMass-v0 parameter"):
        gym.make(POINT_MASS_ID, alhpa=1.0)
    with pytest.raises(ValueError, match="alpha2"):
        gym.make(POINT_MASS_ID, alpha2=0.0)
    env = make_point_mass()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.array([math.nan, 0.0]))
    assert isinstance(tlshield.DoubleIntegrator([0, 1], [2, 3]), tlshield.DoubleIntegrator)


def discounted_return(policy: object, seed: int, gamma: float = CFG.gamma) -> float:
    """The training reward of PointMass-v0 (config rl: no shield), discounted."""
    env = make_point_mass("rl")
    obs, _ = env.reset(seed=seed)
    total, discount = 0.0, 1.0
    for _ in range(CFG.horizon):
        obs, reward, terminated, truncated, _ = env.step(policy(env, obs))  # type: ignore[operator]
        total += discount * float(reward)
        discount *= gamma
        if terminated or truncated:
            break
    return total


def park_before_b(env: gym.Env, obs: np.ndarray) -> np.ndarray:
    """Visits a like the waypoint driver, then parks 1.2 m short of b and stays."""
    if before_a(env):
        return waypoints(env, obs)
    p, v = obs[:2], obs[2:4]
    target = (5.0, 9.8) if p[0] < 4.9 else (CFG.goal_b[0] - 1.2, CFG.goal_b[1])
    return np.clip(1.5 * (np.array(target) - p) - 2.0 * v, -1.0, 1.0)


def test_the_reward_pays_finishing_and_never_pays_barging() -> None:
    # Finishing out-earns dawdling just short of the last goal, and going around the obstacles
    # out-earns driving straight through them, on every seed (no shield: the reward alone).
    for seed in range(5):
        finish = discounted_return(waypoints, seed)
        assert finish > discounted_return(park_before_b, seed), seed
        assert finish > discounted_return(straight, seed), seed


def test_every_core_step_is_the_shields_model_and_the_walls() -> None:
    """The core steps PointMass-v0: each step equals ``s + dt (f + g a)`` of the public
    ``DoubleIntegrator`` for the applied action (the shield's answer clipped to the box), held
    at the walls with the velocity into a wall zeroed, and pays the task reward minus the
    collision penalty (a reference written here, independent of the core's step)."""
    env = make_point_mass("rl_cbf_clf")
    model = tlshield.DoubleIntegrator([0, 1], [2, 3])
    rng = np.random.default_rng(4)
    lo, hi = CFG.room
    walls = 0
    for episode in range(3):
        obs, _ = env.reset(seed=episode)
        for _ in range(CFG.horizon):
            s = obs[:4].copy()
            a_rl = rng.uniform(-1, 1, size=2) if episode else np.array([-1.0, -1.0])
            obs, reward, terminated, truncated, info = env.step(a_rl)
            applied = info["action"]
            wanted = a_rl + info["shield"]["a_cbf"] + info["shield"]["a_clf"]
            np.testing.assert_allclose(applied, np.clip(wanted, -1.0, 1.0), atol=1e-12)
            want = np.asarray(model.step(s, applied, CFG.dt))
            for p, v in ((0, 2), (1, 3)):
                if not lo <= want[p] <= hi:
                    want[p], want[v] = min(max(want[p], lo), hi), 0.0
                    walls += 1
            np.testing.assert_array_equal(obs[:4], want)
            assert reward == info["tl_reward"] - CFG.collision_penalty * info["collision"]
            if terminated or truncated:
                break
    assert walls > 0  # the first episode drives into the corner
