"""``info`` declared once (:mod:`tlshield.step_info`): every key a bundled env, a wrapper or a
vector env writes is a key of :class:`StepInfo` (Safety-Gymnasium's own ``cost_*`` pass
through), ``info["shield"]`` holds :class:`ShieldInfo`'s keys and is there exactly when a shield
filtered the step."""

from __future__ import annotations

from typing import Any, get_type_hints

import gymnasium as gym
import numpy as np
import pytest

import tlshield
from tlshield.step_info import ShieldedStep, ShieldInfo, StepInfo

STEP_KEYS = set(get_type_hints(StepInfo))
SHIELD_KEYS = set(get_type_hints(ShieldInfo))
ENVS = ("tlshield/Channel-v0", "tlshield/PointMass-v0", "tlshield/FlatWorld-v0")


def _check(info: dict[str, Any], shielded: bool, where: str) -> None:
    extra = {k for k in info if k not in STEP_KEYS and not k.startswith("cost_")}
    assert not extra, f"{where}: undeclared info keys {sorted(extra)}"
    assert ("shield" in info) == shielded, f"{where}: shield entry present = {'shield' in info}"
    if shielded:
        assert set(info["shield"]) <= SHIELD_KEYS, f"{where}: {sorted(info['shield'])}"


@pytest.mark.parametrize("env_id", ENVS)
@pytest.mark.parametrize("config", ["rl", "rl_cbf", "rl_cbf_clf"])
def test_every_info_key_is_declared(env_id: str, config: str) -> None:
    env = gym.make(env_id, config=config)
    rng = np.random.default_rng(0)
    _, info = env.reset(seed=3)
    _check(info, False, f"{env_id} {config} reset")
    for t in range(40):
        *_, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape))
        _check(info, config != "rl", f"{env_id} {config} step {t}")
        if terminated or truncated:
            env.reset(seed=t)


@pytest.mark.parametrize("env_id", ENVS[:2])
def test_the_core_batch_declares_the_same_keys(env_id: str) -> None:
    for config in ("rl", "rl_cbf_clf"):
        venv = tlshield.vector.make(env_id, 3, config=config)
        venv.reset(seed=1)
        batch = venv.batch
        for _ in range(5):
            out = batch.step(np.zeros((3, 2)))
            for info in batch.infos(out):
                _check(info, config != "rl", f"{env_id} {config} batch")


def test_a_safety_gym_step_is_declared_and_goes_through_shielded_step() -> None:
    for config in ("rl", "rl_cbf_clf"):
        env = gym.make("tlshield/SafetyPointGoal1-v0", config=config)
        env.reset(seed=0)
        assert isinstance(env.unwrapped._step, ShieldedStep)
        for _ in range(5):
            info = env.step(np.zeros(2))[4]
            _check(info, config != "rl", f"SafetyPointGoal1-v0 {config}")


def test_shielded_step_filters_advances_and_reports() -> None:
    spec = tlshield.Spec("F g", {"g": tlshield.Ball([0, 1], 0.3, center=[2.0, 0.0])})
    automaton = spec.automaton()
    monitor = tlshield.Monitor(automaton)
    gains = {
        "alpha": 1.0,
        "c3": 1.0,
        "k": 1e4,
        "cbf_bounds": (-1.0, 1.0),
        "clf_bounds": (-1.0, 1.0),
    }
    shield = tlshield.Shield(spec, tlshield.SingleIntegrator([0, 1]), **gains)
    step = ShieldedStep(monitor)
    monitor.reset(np.zeros(2))
    action, result = step.filter(shield, np.zeros(2))
    assert result is not None and np.allclose(action, result.action)
    assert np.linalg.norm(action) > 0  # the CLF drives towards g
    task = step.advance(np.array([2.0, 0.0]))
    info = step.info({"raw": 1, "success": False}, success=bool(monitor.q in automaton.accepting))
    assert info["success"] and info["raw"] == 1 and info["shield"]["a_rl"].tolist() == [0, 0]
    assert not task.trapped
    same, none = step.filter(None, np.ones(2))
    assert none is None and same.tolist() == [1.0, 1.0] and "shield" not in step.info()
