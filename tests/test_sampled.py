"""``Shield(dt=...)``: barrier rows that hold the sampled states of an Euler plant (issue 57,
item 3; the core's tests/sampled.rs holds the property over models, k and routing). Here: the
setting is checked where it is given, survives a copy, and the bundled envs whose plant is the
model's Euler step pass their step."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

import tlshield
from tlshield.envs.channel_task import ChannelParams, channel_shield
from tlshield.envs.flatworld import FlatWorldParams, flatworld_shield
from tlshield.envs.point_mass import PointMassParams, point_mass_shield

GOAL = tlshield.Ball([0, 1], 0.2, center=[2.0, 0.0])
DISC = {"!o": tlshield.Avoid(tlshield.Ball([0, 1], 0.5, center=[0.0, 0.01]))}


def shield(**kw: object) -> tlshield.Shield:
    settings: dict = dict(
        alpha=2.0,
        alpha2=2.0,
        c3=1.0,
        k=1e4,
        clf_gain=1.0,
        cbf_bounds=(-3.0, 3.0),
        clf_bounds=(-1.0, 1.0),
        barriers=DISC,
        route=False,
    )
    return tlshield.Shield(
        tlshield.Spec("F goal", {"goal": GOAL}),
        tlshield.DoubleIntegrator([0, 1], [2, 3]),
        **{**settings, **kw},
    )


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"dt": 0.6}, r"alpha = 2 with dt = 0.6: alpha \* dt = 1.2 > 1.*alpha <= 1 / dt"),
        ({"dt": 0.1, "alpha2": 20.0}, r"alpha2 = 20 with dt = 0.1.*alpha2 <= 1 / dt"),
        ({"dt": 0.0}, "dt = 0"),
        ({"dt": float("nan")}, "dt = NaN"),
    ],
)
def test_a_step_the_gains_cannot_hold_is_refused_where_it_is_given(kw: dict, match: str) -> None:
    with pytest.raises(tlshield.ShieldError, match=match):
        shield(**kw)


def settings(sh: tlshield.Shield) -> dict:
    """The keywords a shield is rebuilt from (its pickle)."""
    return sh.__reduce__()[1][3]


def rebuilt(sh: tlshield.Shield, **changes: object) -> tlshield.Shield:
    """The same shield with some keywords changed."""
    spec, model = sh.__reduce__()[1][2]
    return tlshield.Shield(spec, model, **{**settings(sh), **changes})


def min_h(sh: tlshield.Shield, dt: float) -> float:
    """The double integrator parked on the disc's rim by the CLF at k = 1e4, routing off."""
    model = tlshield.DoubleIntegrator([0, 1], [2, 3])
    s, low = np.array([-2.0, 0.0, 0.0, 0.0]), np.inf
    for _ in range(800):
        s = model.step(s, sh.filter(s, 0, np.zeros(2)).action, dt)
        low = min(low, float(np.hypot(s[0], s[1] - 0.01)) - 0.5)
    return low


def test_the_sampled_rows_keep_the_rim_where_the_continuous_rows_enter_and_survive_a_copy() -> None:
    assert min_h(shield(), 0.05) < 0.0  # the continuous-time rows: inside by ~6e-4 m
    sampled = shield(dt=0.05)
    assert min_h(sampled, 0.05) >= 0.0
    for twin in (copy.deepcopy(sampled), pickle.loads(pickle.dumps(sampled))):
        assert settings(twin)["dt"] == 0.05
        assert min_h(twin, 0.05) == min_h(sampled, 0.05)


def test_the_envs_stepped_by_the_model_pass_their_step() -> None:
    """Channel-v0, FlatWorld-v0 and PointMass-v0 integrate the shield's model with an Euler
    step, so their shields hold the sampled states (Safety-Gymnasium's plant is MuJoCo: its
    shield keeps the continuous-time rows and the disturbance bounds)."""
    cases = [
        (channel_shield(ChannelParams(), "rl_cbf_clf"), ChannelParams().agent.dt),
        (
            flatworld_shield(FlatWorldParams(), "rl_cbf_clf", tlshield.Spec("F g", {"g": GOAL})),
            FlatWorldParams().step_size,
        ),
        (
            point_mass_shield(PointMassParams(), "rl_cbf_clf", tlshield.Spec("F g", {"g": GOAL})),
            PointMassParams().dt,
        ),
    ]
    for sh, dt in cases:
        assert sh is not None
        assert settings(sh)["dt"] == dt


def test_where_the_step_moves_nothing_a_barrier_reads_the_rows_are_the_continuous_ones() -> None:
    """A driftless model (the single integrator, the unicycle's reference point) and no moving
    obstacle: the predicted sample of a = 0 is the state itself, so the sampled rows are the
    continuous-time rows bit for bit (FlatWorld-v0's and Channel-v0's shields with static
    obstacles act as before); with the obstacles' drift they differ."""
    rng = np.random.default_rng(4)
    goal = tlshield.Spec("F g", {"g": GOAL})
    flat = FlatWorldParams()
    with_dt = flatworld_shield(flat, "rl_cbf_clf", goal)
    assert with_dt is not None
    without = rebuilt(with_dt, dt=None)
    states = rng.uniform(-flat.size, flat.size, (400, 2))
    a = rng.uniform(-1.0, 1.0, (400, 2))
    qs = np.zeros(400, int)
    np.testing.assert_array_equal(
        with_dt.filter_batch(states, qs, a).action, without.filter_batch(states, qs, a).action
    )
    channel = ChannelParams()
    sh = channel_shield(channel, "rl_cbf_clf")
    assert sh is not None
    plain = rebuilt(sh, dt=None)
    s = rng.uniform(-1.0, 1.0, (400, 13)) * [4, 1.4, 3.1, 4, 4, 4, 4, 4, 4, 4, 4, 4, 4]
    s[:, 9:] = s[:, :2].repeat(2, axis=0).reshape(400, 4) + rng.uniform(-0.8, 0.8, (400, 4))
    q = sh.automaton.step_batch(s, np.full(400, sh.automaton.initial))
    a = rng.uniform(*channel.agent.rl_bounds, (400, 2))
    np.testing.assert_array_equal(
        sh.filter_batch(s, q, a).action, plain.filter_batch(s, q, a).action
    )
    drift = np.zeros_like(s)
    drift[:, 9:] = rng.normal(scale=0.5, size=(400, 4))
    moved = sh.filter_batch(s, q, a, drift).action != plain.filter_batch(s, q, a, drift).action
    assert moved.any()
