"""Copy and pickle, as data (issue 31): every core object and every bundled environment
supports ``copy.copy``, ``copy.deepcopy`` and ``pickle``; a copy continues exactly like the
original, bit for bit, through the same random stream; a pickle from another tlshield version
is refused; Gymnasium's ``AsyncVectorEnv`` works with ``context="spawn"``."""

from __future__ import annotations

import copy
import pickle
from collections.abc import Callable
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import tlshield
import tlshield.sb3
import tlshield.vector
from tests.fixtures import task_shield
from tlshield.envs.channel import ChannelEnv, channel_task_spec
from tlshield.envs.flatworld import make_flatworld
from tlshield.envs.point_mass import make_point_mass
from tlshield.envs.safety_gym import SafetyGoalEnv, load_builder

COPIES: dict[str, Callable[[Any], Any]] = {
    "copy": copy.copy,
    "deepcopy": copy.deepcopy,
    "pickle": lambda x: pickle.loads(pickle.dumps(x)),
}


def _same(a: Any, b: Any) -> bool:
    """Bit-for-bit equality of nested results (arrays, dicts, tuples, enums, floats)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple):
        return type(a) is type(b) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, float):
        return isinstance(b, float) and np.float64(a).tobytes() == np.float64(b).tobytes()
    return type(a) is type(b) and a == b


def _task_step(t: Any) -> tuple:
    return (t.q, t.reward, t.accepted, t.trapped, t.goal, t.atom_robustness)


def _filtered(out: Any) -> tuple:
    return (out.action, out.a_cbf, out.a_clf, out.delta, out.slack, out.goal, out.barriers)


def _states(seed: int, steps: int) -> np.ndarray:
    """A walk along the channel (the task's FSA states occur) with jittered goal positions."""
    rng = np.random.default_rng(seed)
    s = np.zeros((steps, 13))
    along = np.linspace(0.0, 10.0, steps)
    off = rng.uniform(-0.5, 0.5, steps)
    s[:, 0], s[:, 1] = along + off / 2, along - off / 2
    s[:, 2] = rng.uniform(-np.pi, np.pi, steps)
    s[:, 3:9] = [4.0, 4.0, 4.5, 6.5, 9.0, 9.0]
    s[:, 9:13] = [20.0, 20.0, 20.0, -20.0]
    return s


# --- the core objects ----------------------------------------------------------------------


@pytest.mark.parametrize("how", COPIES)
def test_predicates_specs_automata_and_models_copy_as_equals(how: str) -> None:
    spec = channel_task_spec()
    traj = _states(0, 40)
    clone = COPIES[how](spec)
    assert str(clone) == str(spec) and clone.atoms == spec.atoms
    assert _same(clone.robustness(traj), spec.robustness(traj))
    for name, p in spec.predicates.items():
        q = COPIES[how](p)
        assert repr(q) == repr(p), name
        assert _same(q.robustness(traj[5]), p.robustness(traj[5]))
        assert _same(q.gradient(traj[5]), p.gradient(traj[5]))
    aut = spec.automaton()
    twin = COPIES[how](aut)
    assert twin.edges() == aut.edges() and twin.trap == aut.trap
    assert twin.step_batch(traj, np.zeros(40, dtype=int)).tolist() == (
        aut.step_batch(traj, np.zeros(40, dtype=int)).tolist()
    )
    alone = tlshield.Automaton.from_formula("F a & (!a U b)")
    assert COPIES[how](alone).to_dot() == alone.to_dot()
    for model in (
        tlshield.Unicycle(0.1, x=0, y=1, theta=2),
        tlshield.SingleIntegrator([0, 1]),
        tlshield.DoubleIntegrator([0, 1], [2, 3]),
        tlshield.AccelerationUnicycle(0, 1, 2, 3),
    ):
        other = COPIES[how](model)
        assert repr(other) == repr(model)
        s = np.array([0.3, -0.2, 0.7, 1.1])
        assert all(map(_same, other.eval(s), model.eval(s)))


@pytest.mark.parametrize("how", COPIES)
def test_a_copied_progress_reward_pays_the_same(how: str) -> None:
    aut = channel_task_spec().automaton()
    reward = aut.progress_reward(
        gamma=0.97, horizon=150, scale=0.5, c_r=2.0, exclusive=[["g1", "g2", "g3"]]
    )
    twin = COPIES[how](reward)
    assert repr(twin) == repr(reward)
    for s in _states(1, 30):
        for q in range(aut.num_states):
            assert _same(twin.potential(s, q), reward.potential(s, q))


@pytest.mark.parametrize("reward", ["progress", "paper"])
@pytest.mark.parametrize("how", COPIES)
def test_a_monitor_copied_mid_episode_continues_bit_for_bit(how: str, reward: str) -> None:
    shield = task_shield()
    aut = shield.automaton
    progress = aut.progress_reward(exclusive=[["g1", "g2", "g3"]]) if reward == "progress" else None
    monitor = tlshield.Monitor(aut, progress, c_r=1.5, trap_penalty=-7.0)
    assert COPIES[how](monitor).started is False  # before any episode too
    traj = _states(2, 60)
    monitor.reset(traj[0])
    for s in traj[1:20]:
        monitor.advance(s)
    twin = COPIES[how](monitor)
    assert (twin.q, twin.phi, twin.started) == (monitor.q, monitor.phi, True)
    rng = np.random.default_rng(0)
    for s in traj[20:]:
        a_rl = rng.normal(0.0, 0.5, size=2)
        # The shield reads a copied monitor as it reads the original (one automaton).
        assert all(
            map(
                _same,
                _filtered(shield.filter_monitor(twin, a_rl)),
                _filtered(shield.filter_monitor(monitor, a_rl)),
            )
        )
        assert all(map(_same, _task_step(twin.advance(s)), _task_step(monitor.advance(s))))


@pytest.mark.parametrize("how", COPIES)
def test_a_monitor_batch_copied_mid_episode_continues_bit_for_bit(how: str) -> None:
    shield = task_shield()
    batch = tlshield.MonitorBatch(shield.automaton, 3, c_r=1.5, trap_penalty=-7.0)
    trajs = np.stack([_states(seed, 40) for seed in range(3)], axis=1)  # (T, 3, 13)
    batch.reset(trajs[0])
    for states in trajs[1:15]:
        batch.advance(states)
    twin = COPIES[how](batch)
    assert len(twin) == 3 and twin.q.tolist() == batch.q.tolist()
    for states in trajs[15:]:
        a_rl = np.full((3, 2), 0.3)
        x, y = shield.filter_monitors(twin, a_rl), shield.filter_monitors(batch, a_rl)
        assert _same(x.action, y.action) and _same(x.status, y.status)
        u, v = twin.advance(states), batch.advance(states)
        assert all(
            _same(getattr(u, k), getattr(v, k)) for k in ("q", "reward", "accepted", "trapped")
        )
    empty = COPIES[how](tlshield.MonitorBatch(shield.automaton, 0))
    assert len(empty) == 0 and empty.advance(np.zeros((0, 13))).q.shape == (0,)


@pytest.mark.parametrize("how", COPIES)
def test_a_copied_shield_gives_the_same_actions(how: str) -> None:
    spec = channel_task_spec()
    barriers = {
        "wall": tlshield.Inside(tlshield.Halfspace(np.eye(13)[0], 11.0)),
        "!pole": (tlshield.Avoid(tlshield.Ball([0, 1], 0.4, center=[5.0, 5.5])), 0.5),
    }
    shields = [
        task_shield(barriers=barriers, action_bounds=(-3.0, 3.0), solver="clarabel", alpha2=None),
        task_shield(rl_bounds=([-1.0, -2.0], [1.0, 2.0]), use_clf=False, margin=1e-4),
        tlshield.Shield(spec, None, alpha=1.0, c3=1.0, k=1e4, cbf_bounds=([-5.0] * 2, [5.0] * 2),
                        clf_bounds=(-0.5, 0.5)),
    ]  # fmt: skip
    rng = np.random.default_rng(3)
    traj = _states(3, 30)
    qs = spec.automaton().step_batch(traj, np.zeros(30, dtype=int))
    for shield in shields:
        twin = COPIES[how](shield)
        assert repr(twin) == repr(shield)
        a_rl = rng.uniform(-0.9, 0.9, size=(30, 2))
        for s, q, a in zip(traj, qs, a_rl, strict=True):
            f, g = tlshield.Unicycle(0.1).eval(s)
            kwargs = {"f": f, "g": g} if shield is shields[2] else {}
            out, ref = twin.filter(s, int(q), a, **kwargs), shield.filter(s, int(q), a, **kwargs)
            assert all(map(_same, _filtered(out), _filtered(ref)))


# --- the worlds and the environments ------------------------------------------------------


def _rollout(env: Any, actions: np.ndarray) -> list[Any]:
    """Every output of a fixed action sequence, resetting (without a seed: the env's own
    random stream) whenever an episode ends."""
    out = []
    for a in actions:
        step = env.step(a)
        out.append(step)
        if step[2] or step[3]:
            out.append(env.reset())
    return out


#: Envs as users make them. gym.make's outer wrappers are Gymnasium's, which copy.copy copies
#: shallowly (sharing the env below): those are copied with deepcopy and pickle; tlshield's
#: own envs and wrappers copy in full with copy.copy too.
MADE: dict[str, Callable[[], Any]] = {
    "Channel-v0": lambda: gym.make("tlshield/Channel-v0"),
    "Channel-v0 rl paper": lambda: gym.make(
        "tlshield/Channel-v0", config="rl", observation="paper"
    ),
    "PointMass-v0": lambda: gym.make("tlshield/PointMass-v0"),
    "FlatWorld-v0": lambda: gym.make("tlshield/FlatWorld-v0"),
    "SafetyPointGoal1-v0": lambda: gym.make("tlshield/SafetyPointGoal1-v0"),
    "SafetyCarGoal1-v0 native": lambda: gym.make("tlshield/SafetyCarGoal1-v0", actions="native"),
}
OWN: dict[str, Callable[[], Any]] = {
    "ChannelEnv": lambda: ChannelEnv(config="rl_cbf"),
    "make_point_mass": lambda: make_point_mass("rl_cbf_clf"),
    "make_flatworld": lambda: make_flatworld(config="rl_cbf"),
    "SafetyGoalEnv Goal2": lambda: SafetyGoalEnv("SafetyPointGoal2-v0", "rl_cbf", alpha=3.0),
}
CASES = [(name, how) for name in MADE for how in ("deepcopy", "pickle")] + [
    (name, how) for name in OWN for how in COPIES
]


@pytest.mark.parametrize(("name", "how"), CASES)
def test_a_copied_env_continues_exactly_like_the_original(name: str, how: str) -> None:
    if "Safety" in name:
        load_builder()  # make test installs Safety-Gymnasium; without it, the error says so
    env = {**MADE, **OWN}[name]()
    env.reset(seed=11)
    rng = np.random.default_rng(5)
    shape = env.action_space.shape
    for a in rng.uniform(-1, 1, size=(30, *shape)):  # mid-episode
        env.step(a)
    twin = COPIES[how](env)
    actions = rng.uniform(-1, 1, size=(260, *shape))  # past an episode's end: a reset draws
    assert _same(_rollout(twin, actions), _rollout(env, actions))


def test_a_shallow_copy_of_a_gym_make_env_still_copies_the_env_below() -> None:
    """``copy.copy`` of gym.make's outer wrapper is Gymnasium's (shallow); the env under it
    copies in full, so a copy of ``env.unwrapped`` never shares the world."""
    env = gym.make("tlshield/Channel-v0")
    env.reset(seed=0)
    inner = copy.copy(env.unwrapped)
    assert inner is not env.unwrapped and inner._world is not env.unwrapped._world
    assert inner.tracker.monitor is not env.unwrapped.tracker.monitor


def _shielded(kind: str) -> Any:
    """A vector env of Channel-v0s without their own shield, shielded by the batch wrapper."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from tlshield.envs.channel_task import ChannelParams, channel_shield

    make = partial(ChannelEnv, shield_in_env=False, observation="paper")
    shield = channel_shield(ChannelParams(), "rl_cbf_clf")
    action_fn = make().rl_action
    if kind == "sb3":
        return tlshield.sb3.ShieldedVecEnv(DummyVecEnv([make] * 3), shield, action_fn)
    return tlshield.vector.ShieldedVectorEnv(
        gym.vector.SyncVectorEnv([make] * 3), shield, action_fn
    )


VECTORS: dict[str, Callable[[], Any]] = {
    "vector Channel-v0": lambda: tlshield.vector.make("tlshield/Channel-v0", 3),
    "vector PointMass-v0": lambda: tlshield.vector.make("tlshield/PointMass-v0", 3),
    "sb3 Channel-v0": lambda: tlshield.sb3.make_vec_env("tlshield/Channel-v0", 3),
    "sb3 PointMass-v0": lambda: tlshield.sb3.make_vec_env("tlshield/PointMass-v0", 3),
    "sb3 ShieldedVecEnv": lambda: _shielded("sb3"),
    "ShieldedVectorEnv": lambda: _shielded("gym"),
}


@pytest.mark.parametrize("name", VECTORS)
@pytest.mark.parametrize("how", COPIES)
def test_a_copied_vector_env_continues_exactly_like_the_original(name: str, how: str) -> None:
    venv = VECTORS[name]()
    sb3 = name.startswith("sb3")
    if sb3:
        venv.seed(4)
        venv.reset()
    else:
        venv.reset(seed=4)
    rng = np.random.default_rng(6)
    actions = rng.uniform(-1, 1, size=(250, 3, 2))

    def run(v: Any, acts: np.ndarray) -> list[Any]:
        return [v.step(a) for a in acts]

    run(venv, actions[:20])
    twin = COPIES[how](venv)
    assert _same(run(twin, actions[20:]), run(venv, actions[20:]))


# --- versions, Ray and spawned processes ------------------------------------------------------


def test_a_pickle_from_another_version_is_refused_with_a_clear_error() -> None:
    version = tlshield._core.__version__.encode()
    other = b"9.9.9"[: len(version)].ljust(len(version), b"9")
    assert other != version
    for obj in (
        task_shield(),
        channel_task_spec(),
        tlshield.Monitor(task_shield().automaton),
        gym.make("tlshield/Channel-v0"),
    ):
        data = pickle.dumps(obj)
        assert version in data
        with pytest.raises(ValueError, match=f"written by tlshield {other.decode()}"):
            pickle.loads(data.replace(version, other))


def test_a_restored_state_is_checked() -> None:
    monitor = tlshield.Monitor(task_shield().automaton)
    with pytest.raises(ValueError, match="state 99 does not exist"):
        monitor.__setstate__((99, 0.0, True, [0.0] * 13))
    with pytest.raises(ValueError, match="s length"):
        monitor.__setstate__((0, 0.0, True, [0.0] * 3))
    with pytest.raises(ValueError, match="phi"):
        monitor.__setstate__((0, float("nan"), True, [0.0] * 13))
    with pytest.raises(TypeError, match=r"\(q, phi, started, s\)"):
        monitor.__setstate__("garbage")
    env = ChannelEnv()
    with pytest.raises(ValueError, match="horizon"):
        env._world.__setstate__(([0.0] * 13, [0.0] * 13, [[0.0] * 4] * 2, 10**6))
    with pytest.raises(ValueError, match="obstacles"):
        env._world.__setstate__(([0.0] * 13, [0.0] * 13, [[0.0] * 4] * 3, 0))


def _make_channel() -> gym.Env:
    import tlshield  # noqa: F401  (registers the ids in the spawned process)

    return gym.make("tlshield/Channel-v0")


def test_async_vector_env_with_spawn_steps_like_the_sync_one() -> None:
    actions = np.random.default_rng(7).uniform(-1, 1, size=(15, 2, 2))
    outs = []
    for venv in (
        gym.vector.AsyncVectorEnv([_make_channel] * 2, context="spawn"),
        gym.vector.SyncVectorEnv([_make_channel] * 2),
    ):
        venv.reset(seed=9)
        outs.append([venv.step(a)[:4] for a in actions])
        venv.close()
    assert _same(outs[0], outs[1])
