"""The Python boundary of the core: typed errors, checks where a setting is given, and the one
model of the dynamics that both the shield and the environment's plant step through."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import tlshield
from tests.fixtures import task_shield
from tlshield.envs.channel import STATE_DIM, THETA, X, Y, channel_task_spec


def shield(model: object, **overrides: object) -> tlshield.Shield:
    return task_shield(model, **overrides)


def test_errors_are_typed_value_errors() -> None:
    for cls in (tlshield.SpecError, tlshield.AutomatonError, tlshield.ShieldError):
        assert issubclass(cls, ValueError)
    aut = channel_task_spec().automaton()
    with pytest.raises(tlshield.AutomatonError, match="state 99 does not exist"):
        aut.step(np.zeros(STATE_DIM), 99)
    with pytest.raises(tlshield.ShieldError, match="alpha"):
        shield(tlshield.Unicycle(0.1), alpha=-1.0)
    # Malformed numbers stay plain ValueErrors, wherever they are passed.
    with pytest.raises(ValueError, match="finite") as info:
        aut.step(np.full(STATE_DIM, np.nan), 0)
    assert not isinstance(info.value, tlshield.AutomatonError)


def test_shield_rejects_indices_past_the_state_at_construction() -> None:
    # The task's channel halfspaces fix the state length at 13.
    with pytest.raises(tlshield.ShieldError, match=r"pos = \[0, 99\].*13"):
        shield(tlshield.Unicycle(0.1), pos=(0, 99))
    with pytest.raises(tlshield.ShieldError, match="reads 21 state values"):
        shield(tlshield.Unicycle(0.1, 0, 1, 20))


@pytest.mark.parametrize(
    "model", [tlshield.Unicycle(0.1, 0, 1, 2), tlshield.SingleIntegrator([1, 3])]
)
def test_model_step_is_euler_of_eval(model: tlshield.Unicycle | tlshield.SingleIntegrator) -> None:
    rng = np.random.default_rng(0)
    for _ in range(200):
        s = rng.uniform(-3, 3, size=5)
        f, g = model.eval(s)
        a = rng.uniform(-2, 2, size=g.shape[1])
        np.testing.assert_allclose(model.step(s, a, 0.1), s + 0.1 * (f + g @ a), atol=1e-12)
    with pytest.raises(ValueError, match="dt"):
        model.step(np.zeros(5), np.zeros(g.shape[1]), 0.0)
    with pytest.raises(ValueError, match="a: expected"):
        model.step(np.zeros(5), np.zeros(7), 0.1)


def test_channel_plant_is_the_shields_model() -> None:
    """Every environment step equals s + dt (f + g a) of the shield's own model, up to the arena
    clamp and the angle wrap (the obstacles move on their own)."""
    env = gym.make("tlshield/Channel-v0", config="rl_cbf_clf").unwrapped
    model = env.model
    cfg = env.params
    rng = np.random.default_rng(1)
    checked = 0
    for episode in range(5):
        env.reset(seed=episode)
        for _ in range(cfg.task.horizon):
            s = env.state.copy()
            _, _, term, trunc, info = env.step(rng.uniform(-1, 1, size=2))
            f, g = model.eval(s)
            want = s + cfg.agent.dt * (f + g @ info["action"])
            lo, hi = cfg.agent.arena
            want[X], want[Y] = np.clip(want[[X, Y]], lo, hi)
            want[THETA] = (want[THETA] + math.pi) % (2 * math.pi) - math.pi
            np.testing.assert_allclose(env.state[: THETA + 1], want[: THETA + 1], atol=1e-12)
            checked += 1
            if term or trunc:
                break
    assert checked > 100
