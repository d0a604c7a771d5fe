"""N environments in one call. :func:`make`, :class:`ChannelVectorEnv` and
:class:`PointMassVectorEnv`: the bundled worlds as Gymnasium ``VectorEnv`` s whose N envs step
in one core call (:class:`WorldBatch`, as EnvPool does for Atari and MuJoCo).
:class:`ShieldedVectorEnv`: any FSA-augmented vector env shielded in one ``filter_batch``
call, with ``info["shield"]`` as a dict of arrays and the layout of FSA-augmented
observations. The Stable-Baselines3 twins, :class:`tlshield.sb3.WorldVecEnv` and
:class:`tlshield.sb3.ShieldedVecEnv`, live apart so that SB3 and torch load only when they are
used."""

from __future__ import annotations

import numbers
from collections.abc import Callable
from typing import Any, ClassVar, cast

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from tlshield._core import FilterBatch, Shield, WorldsStep, step_worlds
from tlshield.codes import Solver, Status
from tlshield.copying import IndependentCopies
from tlshield.envs.params import FULL

#: Maps the policy's actions ``(N, m)`` to the RL actions in the shield's units.
ActionFn = Callable[[NDArray[np.float64]], NDArray[np.float64]]


def batch_infos(out: FilterBatch, a_rl: NDArray[np.float64]) -> list[dict[str, Any]]:
    """Per-env ``info["shield"]`` of a batch (lists of floats: cheaper than array rows): the
    single-env entry's fields but the goal and the barriers, which a batch does not return."""
    columns = zip(
        a_rl.tolist(),
        out.a_cbf.tolist(),
        out.a_clf.tolist(),
        out.delta.tolist(),
        out.status.tolist(),
        out.slack.tolist(),
        out.solver.tolist(),
        strict=True,
    )
    # The enum members by value: a dict lookup, where calling the enum per row cost about a
    # third of this function (as in WorldBatch.infos).
    status_of, solver_of = _MEMBERS[Status], _MEMBERS[Solver]
    return [
        {
            "a_rl": a,
            "a_cbf": cbf,
            "a_clf": clf,
            "delta": delta,
            "status": status_of[status],
            "slack": slack,
            "solver": solver_of[solver],
        }
        for a, cbf, clf, delta, status, slack, solver in columns
    ]


def shield_arrays(out: FilterBatch, a_rl: NDArray[np.float64]) -> dict[str, NDArray[Any]]:
    """A batch's ``info["shield"]`` the Gymnasium vector way, a dict of arrays with one row per
    sub-env: ``a_rl``, ``a_cbf``, ``a_clf`` ``(N, m)``, ``delta``, ``slack`` and the
    ``status`` and ``solver`` codes ``(N,)`` (``tlshield.Status(code)`` names one)."""
    return {
        "a_rl": a_rl,
        "a_cbf": out.a_cbf,
        "a_clf": out.a_clf,
        "delta": out.delta,
        "status": out.status,
        "slack": out.slack,
        "solver": out.solver,
    }


def rl_actions(actions: Any, action_fn: ActionFn | None) -> NDArray[np.float64]:
    """The batch's RL actions in the shield's units, as one C-ordered float64 array."""
    a = np.asarray(actions, dtype=np.float64)
    return np.ascontiguousarray(a if action_fn is None else action_fn(a), dtype=np.float64)


def split_states(obs: NDArray[np.float64], k: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """States and FSA states from a batch of FSA-augmented observations."""
    return np.ascontiguousarray(obs[:, :-k]), np.argmax(obs[:, -k:], axis=1)


class ShieldedVectorEnv(IndependentCopies, gym.vector.VectorWrapper):
    """Shields every sub-environment of a Gymnasium vector env in one ``filter_batch`` call.

    The sub-environments are FSA-augmented envs without their own shield whose observation is
    the state vector followed by the one-hot FSA state, and whose ``step`` takes the applied
    action (as ``tlshield/Channel-v0`` with ``shield_in_env=False``). ``action_fn`` maps the
    policy's actions ``(N, m)`` to the RL actions in the shield's units (default: as they
    are). ``infos["shield"]`` is a dict of arrays, one row per sub-env, as Gymnasium's vector
    infos are (:func:`shield_arrays`).
    """

    def __init__(
        self, env: gym.vector.VectorEnv, shield: Shield, action_fn: ActionFn | None = None
    ) -> None:
        super().__init__(env)
        self.shield = shield
        self.action_fn = action_fn
        self._k = shield.automaton.num_states
        self._obs: NDArray[np.float64] | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._obs = np.asarray(obs, dtype=np.float64)
        return obs, info

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        a_rl = rl_actions(actions, self.action_fn)
        states, qs = split_states(self._obs, self._k)
        out = self.shield.filter_batch(states, qs, a_rl)
        obs, rewards, terminated, truncated, infos = self.env.step(out.action)
        self._obs = np.asarray(obs, dtype=np.float64)
        infos = {**infos, "shield": shield_arrays(out, a_rl)}
        return obs, rewards, terminated, truncated, infos


#: Each result enum's members by value.
_MEMBERS: dict[type, dict[int, Any]] = {e: {m.value: m for m in e} for e in (Status, Solver)}


class WorldBatch(IndependentCopies):
    """N bundled environments of one kind (``tlshield/Channel-v0`` or ``tlshield/PointMass-v0``)
    whose steps run in one core call (``tlshield._core.step_worlds``: plant, shield, monitor,
    reward and observation of every env, in parallel past 32 envs, GIL released). Each env is a
    real single environment: it draws its own episodes (its resets run in Python, one env at a
    time), so a batch row follows exactly the trajectory the single env follows for the same
    seed and actions. All envs share one configuration, and so one shield."""

    def __init__(self, envs: list[Any]) -> None:
        if not envs:
            raise ValueError("a batch needs at least one environment")
        self.envs = envs
        first = envs[0]
        self.observation_space = first.observation_space
        self.action_space = first.action_space
        self.obs = np.zeros((len(envs), *first.observation_space.shape))

    def reset_env(self, i: int, **kwargs: Any) -> tuple[NDArray[np.float64], dict[str, Any]]:
        """Resets env ``i`` (its own draws); its observation becomes row ``i``."""
        obs, info = self.envs[i].reset(**kwargs)
        self.obs[i] = obs
        return obs, info

    def step(self, actions: Any, active: NDArray[np.bool_] | None = None) -> WorldsStep:
        """Steps every env (or the ``active`` ones) on its row of ``actions`` in one call."""
        first = self.envs[0]
        in_env = getattr(first, "shield_in_env", True)
        out = step_worlds(
            [e._world for e in self.envs],
            [e.tracker.monitor for e in self.envs],
            np.asarray(actions, dtype=np.float64),
            self.obs,
            None if active is None else [bool(a) for a in active],
            first.shield if in_env else None,
            in_env,
        )
        self.obs = out.observation
        for env, slack in zip(self.envs, out.slack.tolist(), strict=True):
            env.last_slack = slack
        return out

    def infos(self, out: WorldsStep) -> list[dict[str, Any]]:
        """Each env's ``info`` as its own ``step`` gives it (a batch does not return the CLF
        goal and the barrier list: None and empty), built in the core call
        ``WorldsStep.infos``."""
        first = self.envs[0]
        # info["shield"] is there when a shield filtered the step (tlshield.step_info).
        shielded = first.shield is not None and getattr(first, "shield_in_env", True)
        status_of, solver_of = (_MEMBERS[Status], _MEMBERS[Solver]) if shielded else ({}, {})
        return out.infos(first.CONSTRAINTS, shielded, status_of, solver_of)


class ChannelBatch(WorldBatch):
    """``num_envs`` :class:`tlshield.envs.ChannelEnv` stepped in one core call (see
    :class:`WorldBatch`)."""

    def __init__(self, num_envs: int, config: str = FULL, **kwargs: Any) -> None:
        from tlshield.envs.channel import ChannelEnv

        _check_count(num_envs)
        super().__init__([ChannelEnv(config=config, **kwargs) for _ in range(num_envs)])


class PointMassBatch(WorldBatch):
    """``num_envs`` :class:`tlshield.envs.point_mass.PointMassEnv` stepped in one core call
    (see :class:`WorldBatch`)."""

    def __init__(self, num_envs: int, config: str = FULL, **kwargs: Any) -> None:
        from tlshield.envs.point_mass import PointMassEnv

        _check_count(num_envs)
        super().__init__([PointMassEnv(config, **kwargs) for _ in range(num_envs)])


#: The most environments one batch holds. Each is a Python env with its own shield (about
#: 0.1 MB), so a count past memory would not raise: the operating system would kill the
#: process. Checked before any env is built.
MAX_ENVS = 65_536


def _check_count(num_envs: Any) -> None:
    if isinstance(num_envs, bool) or not isinstance(num_envs, numbers.Integral):
        raise TypeError(f"num_envs = {num_envs!r}: expected an integer")
    if num_envs < 1:
        raise ValueError(f"num_envs = {num_envs}: a vector env needs at least one environment")
    if num_envs > MAX_ENVS:
        raise ValueError(
            f"num_envs = {num_envs}: at most {MAX_ENVS} environments per vector env "
            "(tlshield.vector.MAX_ENVS); run several vector envs, or several processes"
        )


class WorldVectorEnv(IndependentCopies, gym.vector.VectorEnv):
    """A :class:`WorldBatch` as a Gymnasium ``VectorEnv``, stepped in one core call; an env
    whose episode ended is reset on the next step (``AutoresetMode.NEXT_STEP``, Gymnasium's
    default). ``infos`` holds arrays: ``fsa_state``, ``success``, ``trap``, ``tl_reward``,
    ``constraints`` (N, 2), ``min_obstacle_distance``, ``collision``, ``violation``, and the
    shield's ``a_cbf``, ``a_clf``, ``status``."""

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}

    #: The core batch of a bundled env's vector class, built from ``(num_envs, config,
    #: **kwargs)`` (set by each subclass; :func:`tlshield.sb3.make_vec_env` steps the same).
    BATCH: ClassVar[Callable[..., WorldBatch]]

    def __init__(self, batch: WorldBatch) -> None:
        self.batch = batch
        num_envs = len(batch.envs)
        self.num_envs = num_envs
        self.single_observation_space = self.batch.observation_space
        self.single_action_space = self.batch.action_space
        self.observation_space = gym.vector.utils.batch_space(
            self.single_observation_space, num_envs
        )
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        self._autoreset = np.zeros(num_envs, dtype=bool)

    @property
    def envs(self) -> list[Any]:
        """The single environments."""
        return self.batch.envs

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float64], dict[str, Any]]:
        n = self.num_envs
        seeds = [seed + i for i in range(n)] if isinstance(seed, int) else seed or [None] * n
        if len(seeds) != n:
            raise ValueError(f"seed: expected {n} seeds (one per env), got {len(seeds)}")
        for i in range(n):
            self.batch.reset_env(i, seed=seeds[i], options=options)
        self._autoreset[:] = False
        return self.batch.obs.copy(), {}

    def step(
        self, actions: Any
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], Any, Any, dict[str, Any]]:
        resetting = self._autoreset.copy()
        out = self.batch.step(actions, active=~resetting)
        rewards = out.reward.copy()
        terminated, truncated = out.terminated.copy(), out.truncated.copy()
        for i in np.flatnonzero(resetting):
            self.batch.reset_env(int(i))
        rewards[resetting] = 0.0
        terminated[resetting] = truncated[resetting] = False
        self._autoreset = terminated | truncated
        infos = {
            "fsa_state": out.q,
            "success": out.accepted,
            "trap": out.trapped,
            "tl_reward": out.tl_reward,
            "constraints": out.constraints,
            "min_obstacle_distance": out.min_obstacle_distance,
            "collision": out.collision,
            "violation": out.violation,
            "a_cbf": out.a_cbf,
            "a_clf": out.a_clf,
            "status": out.status,
        }
        return self.batch.obs.copy(), rewards, terminated, truncated, infos


class ChannelVectorEnv(WorldVectorEnv):
    """``tlshield/Channel-v0`` as a Gymnasium ``VectorEnv`` stepped in one core call (see
    :class:`WorldVectorEnv`)."""

    #: The core batch it steps (:func:`tlshield.sb3.make_vec_env` steps the same).
    BATCH = ChannelBatch

    def __init__(self, num_envs: int, config: str = FULL, **kwargs: Any) -> None:
        super().__init__(self.BATCH(num_envs, config, **kwargs))


class PointMassVectorEnv(WorldVectorEnv):
    """``tlshield/PointMass-v0`` as a Gymnasium ``VectorEnv`` stepped in one core call (see
    :class:`WorldVectorEnv`)."""

    #: The core batch it steps (:func:`tlshield.sb3.make_vec_env` steps the same).
    BATCH = PointMassBatch

    def __init__(self, num_envs: int, config: str = FULL, **kwargs: Any) -> None:
        super().__init__(self.BATCH(num_envs, config, **kwargs))


def _sync(env_id: str, num_envs: int, **kwargs: Any) -> gym.vector.SyncVectorEnv:
    """``num_envs`` copies of ``env_id`` side by side in Gymnasium's ``SyncVectorEnv``."""
    _check_count(num_envs)
    return gym.vector.SyncVectorEnv([lambda: gym.make(env_id, **kwargs)] * num_envs)


def flatworld_vector_env(num_envs: int, **kwargs: Any) -> gym.vector.SyncVectorEnv:
    """``tlshield/FlatWorld-v0``'s vector entry point (``gymnasium.make_vec``): its envs side
    by side in a ``SyncVectorEnv`` (written in Python as a user's env would be, it has no core
    world)."""
    from tlshield.envs import FLATWORLD_ID

    return _sync(FLATWORLD_ID, num_envs, **kwargs)


def safety_goal_vector_env(num_envs: int, task: str, **kwargs: Any) -> gym.vector.SyncVectorEnv:
    """The Safety-Gymnasium envs' vector entry point (``gymnasium.make_vec``): ``num_envs``
    copies of ``tlshield/<task>`` side by side in a ``SyncVectorEnv``."""
    return _sync(f"tlshield/{task}", num_envs, **kwargs)


def world_vector_class(env_id: str) -> type[WorldVectorEnv] | None:
    """The core-stepped vector env class ``env_id`` is registered with as its
    ``vector_entry_point``, or None (an env written in Python, or none registered)."""
    import tlshield.envs  # noqa: F401  (registers the bundled envs)

    try:
        entry = gym.spec(env_id).vector_entry_point
    except gym.error.Error:  # not registered under this name (e.g. "module:Env-v0")
        return None
    creator = gym.envs.registration.load_env_creator(entry) if isinstance(entry, str) else entry
    is_world = isinstance(creator, type) and issubclass(creator, WorldVectorEnv)
    return cast(type[WorldVectorEnv], creator) if is_world else None


def make(env_id: str, num_envs: int, config: str = FULL, **kwargs: Any) -> Any:
    """A Gymnasium vector env of ``num_envs`` copies of ``env_id`` stepped in one core call:
    an env whose registered ``vector_entry_point`` is a core world (``tlshield/Channel-v0``,
    ``tlshield/PointMass-v0``). Other envs, FlatWorld-v0 among them (written in Python as a
    user's env would be), are refused: ``gymnasium.make_vec`` gives them a ``SyncVectorEnv``.
    For Stable-Baselines3 use :func:`tlshield.sb3.make_vec_env`."""
    kind = world_vector_class(env_id)
    if kind is None:
        raise ValueError(
            f"env {env_id!r}: tlshield.vector.make steps the envs the core steps (registered "
            "with a WorldVectorEnv as their vector_entry_point); for other envs use "
            "gymnasium.make_vec (a SyncVectorEnv)"
        )
    # Each bundled class is built from (num_envs, config, **kwargs).
    return cast(Callable[..., WorldVectorEnv], kind)(num_envs, config, **kwargs)
