"""Safety that survives a slip (issue 33, point 4): no state of the task turns the shield off.
The trap keeps a recovery safe set, the clauses every way into it kept, so a state that
slipped into a region to avoid (a start inside a hazard, model error, a relaxed step) is driven
back out and kept out, with the hazards in the formula as with user barriers."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tlshield
from tlshield.envs.layout import X, Y

HAZARDS = {"h1": ((2.0, 0.0), 0.8), "h2": ((2.0, 2.5), 0.6)}


def hazard_task() -> tlshield.Spec:
    preds = {n: tlshield.Ball([0, 1], r, center=c) for n, (c, r) in HAZARDS.items()}
    preds["g"] = tlshield.Ball([0, 1], 0.4, center=[5.0, 0.0])
    return tlshield.Spec("(!h1 & !h2) U g", preds)


def test_the_trap_keeps_what_every_way_into_it_kept() -> None:
    aut = hazard_task().automaton()
    assert aut.trap is not None
    assert sorted(map(sorted, aut.recovery_cnf)) == [["!h1", "g"], ["!h2", "g"]]
    # The paper's channel task: stay in the channel unless in g3.
    channel = tlshield.envs.channel_task_spec().automaton()
    assert sorted(map(sorted, channel.recovery_cnf)) == [["c1", "g3"], ["c2", "g3"]]
    # A formula without a trap has no recovery set.
    assert (
        tlshield.Spec("F g", {"g": tlshield.Halfspace([1.0], 0.0)}).automaton().recovery_cnf == []
    )


@pytest.mark.parametrize("policy", ["attacker", "random"])
def test_a_start_inside_a_hazard_of_the_formula_is_driven_out_and_kept_out(policy: str) -> None:
    """A double integrator starts inside h1 (so the automaton starts in its trap); the shield
    drives it out, and it never re-enters a hazard, under an attacker pushing at h1's centre
    and under random actions."""
    model = tlshield.DoubleIntegrator([0, 1], [2, 3])
    shield = tlshield.Shield(
        hazard_task(),
        model,
        alpha=2.0,
        alpha2=2.0,
        c3=1.0,
        k=1e4,
        cbf_bounds=(-8.0, 8.0),
        clf_bounds=(-0.5, 0.5),
        action_bounds=(-4.0, 4.0),
        use_clf=False,
        # h rises towards the margin as m - (m - h0) exp(-alpha t): it crosses 0 after
        # ln((m - h0) / m) / alpha, 1.4 s from 0.7 deep with m = 0.05 (6.7 s with 1e-6).
        margin=0.05,
    )
    monitor = tlshield.Monitor(shield.automaton)
    rng = np.random.default_rng(0)
    for episode in range(10):
        s = np.array([2.0 + rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), 0.0, 0.0])
        task = monitor.reset(s)
        assert task.trapped  # inside h1 from the start
        out_at, reentries = None, 0
        for t in range(1000):
            if policy == "attacker":
                a_rl = 4.0 * (np.array(HAZARDS["h1"][0]) - s[:2])
                a_rl = np.clip(a_rl, -4.0, 4.0)
            else:
                a_rl = rng.uniform(-4.0, 4.0, 2)
            s = model.step(s, shield.filter_monitor(monitor, a_rl).action, 0.01)
            monitor.advance(s)
            inside = any(np.linalg.norm(s[:2] - c) <= r for c, r in HAZARDS.values())
            if not inside and out_at is None:
                out_at = t
            reentries += int(inside and out_at is not None)
        assert out_at is not None and out_at < 300, f"episode {episode}: never got out"
        assert reentries == 0, f"episode {episode}: re-entered {reentries} steps"


def test_channel_starts_outside_the_channel_return_and_stay() -> None:
    """Channel-v0 with starts spread 4 m: under random actions, every episode that starts
    outside the channel comes back in and stays (before: once in the trap nothing pushed
    back). Episodes go on in the trap (``end_on_trap=False``; by default a training episode
    ends there, with nothing left to do)."""
    starts_outside = returned = outside_after = 0
    for episode in range(30):
        env = gym.make("tlshield/Channel-v0", config="rl_cbf", start_spread=4.0, end_on_trap=False)
        env.reset(seed=episode)
        u = env.unwrapped
        width = u.params.task.half_width

        def out() -> bool:
            return bool(abs(u.state[X] - u.state[Y]) >= width)  # noqa: B023

        if not out():
            continue
        starts_outside += 1
        rng = np.random.default_rng(episode)
        back = False
        for _ in range(u.params.horizon):
            _, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, 2))
            if not out():
                back = True
            elif back:
                outside_after += 1
            if terminated or truncated:
                break
        returned += back
    assert starts_outside >= 10  # the test exercises what it claims
    assert returned == starts_outside
    assert outside_after == 0
