"""The parallel batch calls keep working in a child of ``os.fork()`` (issue 20, point 3): a
process that used them before forking used to leave its child waiting forever for thread-pool
workers that do not exist there."""

from __future__ import annotations

import os
import sys
import time

import gymnasium as gym
import numpy as np
import pytest

import tlshield
from tlshield.envs import ENV_ID
from tlshield.envs.channel import ChannelParams, channel_shield, channel_task_spec

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="os.fork is POSIX-only")

ROWS = 4096


def _batch_inputs(rows: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    states = np.zeros((rows, 13))
    states[:, 0] = rng.uniform(-0.5, 0.5, rows)
    states[:, 1] = states[:, 0] + rng.uniform(-0.5, 0.5, rows)
    states[:, 2] = rng.uniform(-np.pi, np.pi, rows)
    states[:, 3:9] = [3.0, 3.0, 5.0, 5.0, 8.0, 8.0]
    states[:, 9:13] = [4.0, 4.5, 6.0, 5.5]
    a_rl = rng.uniform(-1, 1, (rows, 2)) * [1.0, 2.0]
    return states, np.zeros(rows, dtype=np.int64), a_rl


def _everything(shield: tlshield.Shield, spec: tlshield.Spec) -> list[np.ndarray]:
    """Every parallel batch call of the native API on ROWS rows."""
    states, _, a_rl = _batch_inputs(ROWS)
    aut = spec.automaton()
    qs = aut.step_batch(states, np.full(ROWS, aut.initial))
    out = shield.filter_batch(states, qs, a_rl)
    trajs = states[: ROWS // 8 * 8].reshape(-1, 8, 13)
    return [qs, out.action, out.status, spec.robustness_batch(trajs)]


def test_batch_calls_finish_in_a_forked_child() -> None:
    spec = channel_task_spec()
    shield = channel_shield(ChannelParams(), "rl_cbf_clf", spec)
    assert shield is not None
    want = _everything(shield, spec)  # the parent's pool is running now
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: the same calls must finish and agree
        code = 1
        try:
            got = _everything(shield, spec)
            code = 0 if all(np.array_equal(a, b) for a, b in zip(got, want, strict=True)) else 3
        finally:
            os.write(write, bytes([code]))
            os._exit(code)
    os.close(write)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        time.sleep(0.05)
    else:
        os.kill(pid, 9)
        os.waitpid(pid, 0)
        pytest.fail("the forked child's batch calls did not finish within 60 s")
    os.close(read)
    assert os.waitstatus_to_exitcode(status) == 0, "the child's batch results differ"
    # And the parent still works after its child.
    assert all(np.array_equal(a, b) for a, b in zip(_everything(shield, spec), want, strict=True))


class BatchProbe(gym.Wrapper):
    """Each step also shields a 64-row batch (above the parallel threshold) in the worker."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.probe = channel_shield(ChannelParams(), "rl_cbf_clf")

    def step(self, action):  # type: ignore[no-untyped-def]
        states, qs, a_rl = _batch_inputs(64, seed=1)
        out = self.probe.filter_batch(states, qs, a_rl)
        assert np.isfinite(out.action).all()
        return super().step(action)


def test_async_vector_env_with_fork_over_shielded_envs() -> None:
    spec = channel_task_spec()
    shield = channel_shield(ChannelParams(), "rl_cbf_clf", spec)
    _everything(shield, spec)  # start the parent's pool before the workers fork

    def make() -> gym.Env:
        return BatchProbe(gym.make(ENV_ID, config="rl_cbf_clf"))

    envs = gym.vector.AsyncVectorEnv([make, make], context="fork")
    try:
        envs.reset_async(seed=0)
        envs.reset_wait(timeout=60)
        rng = np.random.default_rng(0)
        for _ in range(20):
            envs.step_async(rng.uniform(-1, 1, (2, 2)))
            _, reward, _, _, info = envs.step_wait(timeout=60)
            assert np.isfinite(reward).all()
            assert not np.any(info["violation"])
    finally:
        envs.close(terminate=True)
    print(f"fork ok on {sys.platform}")
