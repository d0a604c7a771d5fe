"""Your own robot, end to end (docs/guides/own-robot.md walks through this file).

A kinematic bicycle car (state x, y, heading, speed; inputs acceleration and steering) in a
10 m x 10 m room visits goal A, then goal B, avoiding three discs. The car is a plain
Gymnasium env that knows nothing of tlshield; the factory ``make_room`` adds the task
(``FsaAugmented``) and the shield (``Shielded``), and registers as ``BicycleRoom-v0`` when this
module is imported, so the command line can train it:

    cd examples && tlshield train --env bicycle_room:BicycleRoom-v0 --updates 100 --out run
    cd examples && tlshield evaluate run

``python examples/bicycle_room.py`` checks the shield alone before any training: an attacker
(full throttle and steering at the nearest obstacle or wall) and a random policy, with the
shield on and off, and prints the violating steps of each.
"""

from __future__ import annotations

import argparse
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

import tlshield
from tlshield.envs import EnvProfile, register
from tlshield.wrappers import FsaAugmented, Shielded

#: The car: wheelbase (m), steering limit (rad), acceleration limit (m/s^2), top speed (m/s).
WHEELBASE, MAX_STEER, MAX_ACCEL, TOP_SPEED = 0.5, 0.5, 2.0, 2.0
#: The room's side (m), the control period (s) and the episode length (steps).
ROOM, DT, HORIZON = 10.0, 0.2, 200
GOALS = {"a": (2.0, 8.0), "b": (8.0, 2.0)}
GOAL_RADIUS = 0.6
OBSTACLES = {"!o1": ((5.4, 5.4), 1.0), "!o2": ((3.3, 5.0), 0.7), "!o3": ((7.5, 7.5), 0.7)}
#: The walls are kept this far away (m): the car is a point at its rear axle.
WALL = 0.3

#: The plant and the shield's model are one code: the env steps with the model's Euler step.
MODEL = tlshield.KinematicBicycle(WHEELBASE)  # state (x, y, theta, v); inputs (a, tan delta)
TAN_MAX = float(np.tan(MAX_STEER))
#: The configurations the trainer knows: no shield, the CBF alone, the CBF and the CLF.
CONFIGS = ("rl", "rl_cbf", "rl_cbf_clf")


class BicycleRoom(gym.Env):
    """The car in the room. Observation ``(x, y, cos theta, sin theta, v)`` (more than the
    state's four values: ``state_of`` reads the state back); action in ``[-1, 1]^2`` scaled to
    (acceleration, tan steering). Terminated when the car leaves the room."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self) -> None:
        # Bounds that hold whatever the policy: one step past a wall, and the speed that full
        # throttle reaches in an episode.
        speed = MAX_ACCEL * HORIZON * DT
        reach = ROOM + speed * DT
        low = np.array([-reach, -reach, -1.0, -1.0, -speed])
        high = np.array([reach, reach, 1.0, 1.0, speed])
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)
        self.state = np.zeros(4)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        x, y = self.np_random.uniform(1.0, 2.5, size=2)  # the lower-left corner
        self.state = np.array([x, y, self.np_random.uniform(-np.pi, np.pi), 0.0])
        return self._observe(), {}

    def _observe(self) -> np.ndarray:
        x, y, theta, v = self.state
        return np.array([x, y, np.cos(theta), np.sin(theta), v])

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = physical(np.clip(action, -1.0, 1.0))
        self.state = MODEL.step(self.state, a, DT)
        left = not (0.0 <= self.state[0] <= ROOM and 0.0 <= self.state[1] <= ROOM)
        return self._observe(), 0.0, left, False, {}


def state_of(obs: np.ndarray) -> np.ndarray:
    """The state ``(x, y, theta, v)`` the spec and the shield read, from the observation (its
    first five values: ``Shielded`` sees the one-hot FSA state appended after them)."""
    x, y, c, s, v = np.asarray(obs, dtype=np.float64)[:5]
    return np.array([x, y, np.arctan2(s, c), v])


def physical(action: np.ndarray) -> np.ndarray:
    """The policy's ``[-1, 1]^2`` as the model's inputs (acceleration, tan steering)."""
    return np.asarray(action, dtype=np.float64) * [MAX_ACCEL, TAN_MAX]


def room_spec() -> tlshield.Spec:
    """The task: goal a, then goal b. Obstacles and walls are barriers, not atoms (see the
    guide)."""
    goals = {name: tlshield.Ball([0, 1], GOAL_RADIUS, center=c) for name, c in GOALS.items()}
    return tlshield.Spec("F (a & F b)", goals)


def barriers() -> dict[str, tlshield.Avoid | tlshield.Inside]:
    """Keep out of each disc, inside the room, and below the top speed."""
    walls = {
        "west": tlshield.Halfspace([1.0, 0.0, 0.0, 0.0], -WALL),
        "east": tlshield.Halfspace([-1.0, 0.0, 0.0, 0.0], ROOM - WALL),
        "south": tlshield.Halfspace([0.0, 1.0, 0.0, 0.0], -WALL),
        "north": tlshield.Halfspace([0.0, -1.0, 0.0, 0.0], ROOM - WALL),
        "speed": tlshield.Halfspace([0.0, 0.0, 0.0, -1.0], TOP_SPEED),
        "reverse": tlshield.Halfspace([0.0, 0.0, 0.0, 1.0], 0.5),
    }
    discs = {
        name: tlshield.Avoid(tlshield.Ball([0, 1], r, center=c))
        for name, (c, r) in OBSTACLES.items()
    }
    walls_in = {name: tlshield.Inside(h) for name, h in walls.items()}
    return {**discs, **walls_in}


def room_shield(config: str = "rl_cbf_clf") -> tlshield.Shield:
    """The shield: gains from the guide's rule (alpha + alpha2 <= a_max / v_max, so that no
    barrier asks for more braking than the car has at top speed)."""
    alpha = alpha2 = MAX_ACCEL / (2.0 * TOP_SPEED)
    return tlshield.Shield(
        room_spec(),
        MODEL,
        alpha=alpha,
        alpha2=alpha2,
        c3=1.0,
        k=1e4,
        clf_gain=0.5,
        barriers=barriers(),
        # The env holds the action for DT and takes the model's Euler step: with dt the
        # barrier rows hold the sampled states, not only the state at the sample.
        dt=DT,
        # What the correction may add, what the applied action may be (the car's limits),
        # and the RL action's range (the shield checks the box can cancel it).
        cbf_bounds=([-2 * MAX_ACCEL, -2 * TAN_MAX], [2 * MAX_ACCEL, 2 * TAN_MAX]),
        clf_bounds=([-0.5 * MAX_ACCEL, -0.5 * TAN_MAX], [0.5 * MAX_ACCEL, 0.5 * TAN_MAX]),
        action_bounds=([-MAX_ACCEL, -TAN_MAX], [MAX_ACCEL, TAN_MAX]),
        rl_bounds=([-MAX_ACCEL, -TAN_MAX], [MAX_ACCEL, TAN_MAX]),
        use_clf=config == "rl_cbf_clf",
    )


def to_unit(action: np.ndarray) -> np.ndarray:
    """The shielded physical action back in the env's ``[-1, 1]^2``."""
    return np.asarray(action, dtype=np.float64) / [MAX_ACCEL, TAN_MAX]


def make_room(
    config: str = "rl_cbf_clf",
    evaluation: bool = False,
    gamma: float = 0.999,
    horizon: int = HORIZON,
) -> gym.Env:
    """The trainer's factory: ``config`` picks the shield, ``evaluation`` turns the CBF on in
    every configuration (the paper's evaluation rule), ``gamma`` is the trainer's discount
    (the trainer passes its own, since this factory names it), ``horizon`` the episode
    length."""
    if config not in CONFIGS:
        raise ValueError(f"config = {config!r}: expected one of {CONFIGS}")
    env: gym.Env = gym.wrappers.TimeLimit(BicycleRoom(), max_episode_steps=horizon)
    # Leaving the room ends the episode as a failure, never as a way out.
    env = FsaAugmented(
        env,
        room_spec(),
        state_fn=state_of,
        gamma=gamma,
        horizon=horizon,
        failure_on_termination=True,
    )
    if config == "rl" and not evaluation:
        return env
    shield = room_shield("rl_cbf" if config == "rl" else config)
    # The shield works in physical units: action_fn scales the policy's action up, and the
    # env gets the shielded action back in its own units.
    shielded = Shielded(_PhysicalActions(env), shield, state_fn=state_of, action_fn=physical)
    return _UnitActions(shielded)


class _PhysicalActions(gym.ActionWrapper):
    """The env below, taking physical actions (what ``Shielded`` hands down)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        high = np.array([MAX_ACCEL, TAN_MAX])
        self.action_space = gym.spaces.Box(-high, high, dtype=np.float64)

    def action(self, action: np.ndarray) -> np.ndarray:
        return to_unit(action)


class _UnitActions(gym.ActionWrapper):
    """The policy's side: actions in ``[-1, 1]^2`` (``Shielded``'s ``action_fn`` scales)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)

    def action(self, action: np.ndarray) -> np.ndarray:
        return np.asarray(action, dtype=np.float64)


# The lab reads what kind of task this is from the registration: scored by its success.
register("BicycleRoom-v0", make_room, profile=EnvProfile(scored_by_return=False))


def attacker(state: np.ndarray) -> np.ndarray:
    """Full throttle, steering at the nearest obstacle's centre or wall point."""
    x, y, theta, _ = state
    targets = [np.array(c) for c, _ in OBSTACLES.values()]
    targets += [np.array(p) for p in ((0.0, y), (ROOM, y), (x, 0.0), (x, ROOM))]
    target = min(targets, key=lambda t: float(np.linalg.norm(t - state[:2])))
    heading = np.arctan2(target[1] - y, target[0] - x)
    turn = (heading - theta + np.pi) % (2 * np.pi) - np.pi
    return np.array([1.0, np.clip(3.0 * turn, -1.0, 1.0)])


def attack(config: str, policy: str, episodes: int, seed: int = 0) -> dict[str, int]:
    """Violating steps (measured by tlshield from the barriers' values), trap entries and
    successes of ``episodes`` episodes of the attacker or a random policy."""
    from tlshield.lab.measures import step_violation

    env = make_room(config, evaluation=config != "rl")
    measure = room_shield()  # without a shield, the barriers are measured as it would
    rng = np.random.default_rng(seed)
    out = {"violating steps": 0, "episodes with one": 0, "successes": 0}
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        trapped = violated = False
        for _ in range(HORIZON):
            state = state_of(obs)
            a = attacker(state) if policy == "attacker" else rng.uniform(-1.0, 1.0, 2)
            obs, _, terminated, truncated, info = env.step(a)
            h = info.get("barriers") or measure.barrier_values(state_of(obs))
            bad = step_violation({**info, "barriers": h}, trapped)
            trapped = bool(info["trap"])
            out["violating steps"] += int(bool(bad))
            violated |= bool(bad)
            if terminated or truncated:
                out["successes"] += int(info["success"])
                break
        out["episodes with one"] += int(violated)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args()
    print("| policy | shield | episodes | violating steps | episodes with one | successes |")
    print("|---|---|---:|---:|---:|---:|")
    for policy in ("attacker", "random"):
        for config in ("rl", "rl_cbf", "rl_cbf_clf"):
            got = attack(config, policy, args.episodes)
            shield = {"rl": "off", "rl_cbf": "CBF", "rl_cbf_clf": "CBF + CLF"}[config]
            print(
                f"| {policy} | {shield} | {args.episodes} | {got['violating steps']} "
                f"| {got['episodes with one']} | {got['successes']} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
