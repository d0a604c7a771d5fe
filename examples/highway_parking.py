"""Shielding a third-party environment: highway-env's ``parking-v0`` (not ours; installs from
the package registry, no downloaded assets) with a temporal-logic task and the shield.

The task: ``(w1 & w2 & w3 & w4) U g``: stay inside the lot's walls until the ego car is within
1 m of its goal spot. The parked cars are user barriers: each car is two discs (at +-1.5 m
along its heading, radius ``CAR_RADIUS``) that the ego's reference point must stay out of.

highway-env integrates a kinematic bicycle about the car's centre (velocity along heading +
slip angle ``beta = atan(tan(delta) / 2)``, turn rate ``v sin(beta) / (L / 2)``) at 15 Hz under
a 5 Hz policy. Its **rear axle**, ``L / 2`` behind the centre, moves exactly as
``tlshield.KinematicBicycle(L)`` with speed ``v cos(beta)`` and inputs (acceleration,
``tan(delta)``), so ``--model bicycle`` shields the rear axle with the exact
model: the steering limit is the box ``|tan delta| <= 1``, and the turn rate the car can make
shrinks with its speed as it does in the simulator. ``--model unicycle`` (the default) is an
approximation: ``tlshield.AccelerationUnicycle`` on the centre, whose turn rate is bounded by a
constant box whatever the speed, its output mapped to a steering angle by inverting the
relation above (saturated at the steering limit). The exact model shields the wrong point for
this lot: the car's body reaches 5 m ahead of its rear axle, which discs around the rear axle
do not see (docs/guides/highway-parking.md has the measurements). ``--model body`` keeps the
exact model on the rear axle and protects the whole body: three discs along the car
(:data:`BODY`), each a ``tlshield.Ball`` on a body point (``heading``, ``offset``), kept out of
every parked car's two discs, and walls kept as far from the rear axle as the body reaches.
Positions are constraints of relative degree 2 under these models, so the shield uses
higher-order barriers (``alpha2``); a body point's heading is one integration from the steering
(mixed relative degree, which the shield holds with one row more).

Entering a spot between parked cars needs a line-up (in front of the spot, on its axis, then
straight in). ``--line-up`` (with ``--model body --clf``) writes it into the task as a sequence:
first a waypoint of the rear axle in the aisle, on the spot's axis (:data:`LINE_UP`), then the
spot. The routed CLF leads the car there, turning it on the way, and then into the spot, with
a box on its correction wide enough to overrule the policy's steering
(:data:`LINE_UP_CLF_BOUND`).

``python examples/highway_parking.py [--steps N] [--seed S] [--model M] [--clf] [--line-up]``
drives a naive policy (steer and accelerate towards the goal, 30% random actions) for N
environment steps with and without the shield and prints crashes (highway-env's own collision
check, rectangles), successes (the centre within ``GOAL_RADIUS`` of the spot's, or
highway-env's own test, which ends the episode) and the shield's relaxed/failed counts. Needs
``pip install highway-env``.
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

import gymnasium as gym
import highway_env  # noqa: F401  (registers parking-v0)
import numpy as np

import tlshield

#: The lot's walls (highway-env parking: 70 m x 42 m, walls 1 m thick) and the margin the ego
#: car's centre keeps from their centre lines: half a wall, half the car's length (2.5 m) and
#: 1 m for the model's error.
HALF_X, HALF_Y, WALL_MARGIN = 35.0, 21.0, 4.0
#: Radius of each of a parked car's two discs (its 5 m x 2 m body plus the ego's half-width).
CAR_RADIUS = 3.0
#: Within this distance of the goal spot's centre the task is done (m).
GOAL_RADIUS = 1.0
#: highway-env's limits: acceleration (m/s^2), steering (rad); the car's length (m).
MAX_ACCEL, MAX_STEER, LENGTH = 5.0, math.pi / 4, 5.0
#: ``--model body``: the ego's 5 m x 2 m body as three discs at these distances ahead of the
#: rear axle (which highway-env puts at the back of the body), each of radius
#: ``BODY_RADIUS`` (a sixth of the length and half the width: its corners are inside). A parked
#: car's two discs (at +-1.5 m along it) then need ``PARKED_RADIUS`` to cover its body.
BODY = (LENGTH / 6, LENGTH / 2, 5 * LENGTH / 6)
BODY_RADIUS = math.hypot(LENGTH / 6, 1.0)
PARKED_RADIUS = math.hypot(LENGTH / 2 - 1.5, 1.0)
#: The walls' margin from the rear axle under ``--model body``: half a wall, the body's reach
#: ahead of the rear axle (its far corner), and 0.5 m for the model's error.
BODY_WALL_MARGIN = 0.5 + math.hypot(LENGTH, 1.0) + 0.5
#: ``--line-up``: the line-up waypoint of the rear axle on the spot's axis, ``(distance back
#: from its parked place, radius)`` (m): 6 m out, the body's front disc (4.17 m ahead, radius
#: 1.30) ends short of the spot's mouth, clear of the cars beside the spot, so the car can line
#: up there and go straight in. One waypoint did better than two (a wide one farther out, then
#: this one) and than smaller discs: docs/guides/highway-parking.md has the measurements.
LINE_UP = (6.0, 1.5)
#: ``--line-up``'s box on the CLF's correction (acceleration in m/s^2, ``tan delta``): 2, so that
#: the CLF can turn the wheel full the other way against the policy's full lock (``|tan delta|
#: <= 1``); the default box (0.5) cannot overrule a policy that steers at the spot.
LINE_UP_CLF_BOUND = 2.0


def state_of(env: gym.Env) -> np.ndarray:
    """``[x, y, theta, v]`` of the ego car (the shield's state)."""
    car = env.unwrapped.vehicle
    return np.array([car.position[0], car.position[1], car.heading, car.speed])


def rear_state_of(env: gym.Env) -> np.ndarray:
    """``[x, y, theta, v]`` of the rear axle: its position, the heading and its speed
    ``v cos(beta)`` (the exact bicycle's state)."""
    car = env.unwrapped.vehicle
    heading = np.array([math.cos(car.heading), math.sin(car.heading)])
    rear = car.position - LENGTH / 2 * heading
    beta = math.atan(math.tan(car.action["steering"]) / 2)
    return np.array([*rear, car.heading, car.speed * math.cos(beta)])


def parked(env: gym.Env) -> bool:
    """The task's goal, whatever the shield's model: the centre within ``GOAL_RADIUS``."""
    car = env.unwrapped.vehicle
    return bool(np.linalg.norm(car.position - car.goal.position) <= GOAL_RADIUS)


def make_spec(env: gym.Env, model: str = "unicycle", line_up: bool = False) -> tlshield.Spec:
    """The task of the episode just reset (the goal spot moves per episode), on the shielded
    point: the centre (unicycle) or the rear axle, whose goal disc is larger by the half length
    that separates the two (success is still judged on the centre: :func:`parked`).

    ``line_up`` (``model="body"``) writes the way into the spot as a sequence, ``walls U (pre
    & (walls U g))``: a waypoint of the rear axle in the aisle, on the spot's axis
    (:data:`LINE_UP`), so that the CLF brings the car in front of the spot, heading into it,
    before it aims into the spot."""
    goal = env.unwrapped.vehicle.goal.position
    margin = BODY_WALL_MARGIN if model == "body" else WALL_MARGIN
    walls = {
        "w1": tlshield.Halfspace([-1.0, 0.0, 0.0, 0.0], HALF_X - margin),
        "w2": tlshield.Halfspace([1.0, 0.0, 0.0, 0.0], HALF_X - margin),
        "w3": tlshield.Halfspace([0.0, -1.0, 0.0, 0.0], HALF_Y - margin),
        "w4": tlshield.Halfspace([0.0, 1.0, 0.0, 0.0], HALF_Y - margin),
    }
    radius = GOAL_RADIUS + (LENGTH / 2 if model == "bicycle" else 0.0)
    spot = env.unwrapped.vehicle.goal.heading
    axis = np.array([math.cos(spot), math.sin(spot)])
    if model == "body":  # where the rear axle is when the car is parked in the spot
        goal = goal - LENGTH / 2 * axis
    preds: dict[str, Any] = {
        **walls,
        "g": tlshield.Ball(pos=[0, 1], radius=radius, center=list(goal)),
    }
    w = "(w1 & w2 & w3 & w4)"
    if not line_up:
        return tlshield.Spec(f"{w} U g", preds)
    if model != "body":
        raise ValueError("line_up needs model='body' (a rear-axle goal on the spot's axis)")
    back, r = LINE_UP
    preds["pre"] = tlshield.Ball(pos=[0, 1], radius=r, center=list(goal - back * axis))
    return tlshield.Spec(f"{w} U (pre & ({w} U g))", preds)


def make_shield(
    env: gym.Env,
    spec: tlshield.Spec,
    car_radius: float = CAR_RADIUS,
    alpha: float = 1.0,
    model: str = "unicycle",
    clf: bool = False,
    clf_bound: float = 0.5,
) -> tlshield.Shield:
    """The shield of the episode just reset: the task's walls, the parked cars as barriers (for
    ``model="body"``, every pair of a body disc and a parked car's disc, ``car_radius`` apart,
    and the walls again as barriers, so that they hold after the task is done). ``clf_bound``
    is the box on the CLF's correction, per input."""
    u = env.unwrapped
    cars: dict[str, tlshield.Avoid | tlshield.Inside] = {}
    if model == "body":
        cars.update({w: tlshield.Inside(spec.predicates[w]) for w in ("w1", "w2", "w3", "w4")})
    points = BODY if model == "body" else (None,)
    for k, car in enumerate(u.road.vehicles[1:]):
        along = 1.5 * np.array([math.cos(car.heading), math.sin(car.heading)])
        for end, sign in (("f", 1.0), ("r", -1.0)):
            centre = list(car.position + sign * along)
            for i, ahead in enumerate(points):
                body = {} if ahead is None else {"heading": 2, "offset": (ahead, 0.0)}
                name = f"!car{k}{end}" + ("" if ahead is None else f"b{i}")
                disc = tlshield.Ball(pos=[0, 1], radius=car_radius, center=centre, **body)
                cars[name] = tlshield.Avoid(disc)
    if model != "unicycle":
        dynamics: Any = tlshield.KinematicBicycle(LENGTH, x=0, y=1, theta=2, v=3)
        limits = ((-MAX_ACCEL, -math.tan(MAX_STEER)), (MAX_ACCEL, math.tan(MAX_STEER)))
    else:
        dynamics = tlshield.AccelerationUnicycle(x=0, y=1, theta=2, v=3)
        limits = ((-MAX_ACCEL, -2.0), (MAX_ACCEL, 2.0))
    return tlshield.Shield(
        spec,
        dynamics,
        alpha=alpha,
        alpha2=alpha,
        c3=1.0,
        k=1e4,
        cbf_bounds=(-20.0, 20.0),
        clf_bounds=(-clf_bound, clf_bound),
        action_bounds=limits,
        use_clf=clf,
        margin=0.05,
        barriers=cars,
    )


def to_env_action(accel: float, turn_rate: float, speed: float) -> np.ndarray:
    """The shield's ``(a, omega)`` as highway-env's normalised ``(acceleration, steering)``:
    invert ``omega = v sin(beta) / (L / 2)``, ``beta = atan(tan(delta) / 2)``."""
    if abs(speed) < 1e-3:
        steer = 0.0
    else:
        sin_beta = max(-1.0, min(1.0, turn_rate * (LENGTH / 2) / speed))
        steer = math.atan(2.0 * math.tan(math.asin(sin_beta)))
    steer = max(-MAX_STEER, min(MAX_STEER, steer))
    return np.array([accel / MAX_ACCEL, steer / MAX_STEER], dtype=np.float32)


def bicycle_to_env_action(accel: float, tan_steer: float) -> np.ndarray:
    """The exact bicycle's ``(a, tan delta)`` as highway-env's normalised action: the steering
    angle ``atan(tan delta)``, and the centre's acceleration ``a / cos(beta)`` that gives the
    rear axle ``a``."""
    steer = max(-MAX_STEER, min(MAX_STEER, math.atan(tan_steer)))
    beta = math.atan(math.tan(steer) / 2)
    return np.array([accel / math.cos(beta) / MAX_ACCEL, steer / MAX_STEER], dtype=np.float32)


def naive(env: gym.Env, rng: np.random.Generator, turn: float = 2.0) -> tuple[float, float]:
    """A user's unsafe controller: turn towards the goal, hold 3 m/s; 30% random actions.
    Returns the acceleration and a turn command within ``+-turn`` in physical units: the turn
    rate (unicycle, limit 2 rad/s) or ``tan delta`` (bicycle, limit 1)."""
    if rng.random() < 0.3:
        return rng.uniform(-MAX_ACCEL, MAX_ACCEL), rng.uniform(-turn, turn)
    x, y, theta, v = state_of(env)
    gx, gy = env.unwrapped.vehicle.goal.position
    error = (math.atan2(gy - y, gx - x) - theta + math.pi) % (2 * math.pi) - math.pi
    return 2.0 * (3.0 - v), max(-turn, min(turn, 2.0 * error))


def run(
    steps: int,
    shielded: bool,
    seed: int,
    car_radius: float = CAR_RADIUS,
    alpha: float = 1.0,
    model: str = "unicycle",
    clf: bool = False,
    line_up: bool = False,
) -> dict[str, Any]:
    """``steps`` environment steps of the naive policy, shielded or not (``line_up``: the task
    written with the line-up waypoints and the CLF's wider box, see :func:`make_spec`)."""
    bicycle = model != "unicycle"
    observe = rear_state_of if bicycle else state_of
    turn_limit = 1.0 if bicycle else 2.0  # tan(MAX_STEER) = tan(pi / 4) = 1
    env = gym.make("parking-v0", config={"vehicles_count": 10, "duration": 60})
    rng = np.random.default_rng(seed)
    counts = {"steps": 0, "episodes": 0, "crashes": 0, "wall_crashes": 0, "successes": 0}
    counts.update({"env_successes": 0, "relaxed": 0, "failed": 0})
    clf_bound = LINE_UP_CLF_BOUND if line_up else 0.5
    episode = 0
    while counts["steps"] < steps:
        env.reset(seed=seed * 10_000 + episode)
        episode += 1
        spec = make_spec(env, model, line_up)
        shield = None
        if shielded:
            shield = make_shield(env, spec, car_radius, alpha, model, clf, clf_bound)
        aut = spec.automaton()
        q = aut.step(observe(env), aut.initial)
        while counts["steps"] < steps:
            accel, turn = naive(env, rng, turn_limit)
            s = observe(env)
            if shield is not None:
                out = shield.filter(s, q, [accel, turn])
                accel, turn = float(out.action[0]), float(out.action[1])
                counts["relaxed"] += out.status == tlshield.Status.RELAXED
                counts["failed"] += out.status == tlshield.Status.FAILED
            if bicycle:
                action = bicycle_to_env_action(accel, turn)
            else:
                action = to_env_action(accel, turn, s[3])
            _, _, terminated, truncated, info = env.step(action)
            counts["steps"] += 1
            q = aut.step(observe(env), q)
            if info["crashed"]:
                counts["crashes"] += 1
                x, y = observe(env)[:2]
                margin = BODY_WALL_MARGIN if model == "body" else WALL_MARGIN
                near_wall = abs(x) > HALF_X - margin or abs(y) > HALF_Y - margin
                counts["wall_crashes"] += bool(near_wall)
                break
            if parked(env):
                counts["successes"] += 1
                break
            if terminated or truncated:
                # highway-env ends the episode when its own test (position and heading, less
                # strict across the spot than along it) says the car is parked: a success too.
                if info["is_success"]:
                    counts["successes"] += 1
                    counts["env_successes"] += 1
                break
        counts["episodes"] += 1
    env.close()
    return counts


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--car-radius",
        type=float,
        nargs="+",
        default=[CAR_RADIUS],
        help="radius of each parked car's two discs (m); several values: one shielded row each",
    )
    parser.add_argument("--alpha", type=float, default=1.0, help="alpha = alpha2 of the HOCBF")
    parser.add_argument(
        "--model",
        choices=("unicycle", "bicycle", "body"),
        default="unicycle",
        help="the shield's model: the centre as an acceleration unicycle (an approximation), "
        "the rear axle as the exact kinematic bicycle, or the exact bicycle with barriers on "
        "three discs of the body (body: --car-radius defaults to the two discs' radii summed)",
    )
    parser.add_argument(
        "--clf",
        action="store_true",
        help="also drive to the goal with the shield's CLF, routed around the parked cars",
    )
    parser.add_argument(
        "--line-up",
        action="store_true",
        help="(with --model body --clf) write the task with a waypoint in front of the spot, "
        "on its axis, so that the CLF lines the car up before it goes in; the CLF's box is "
        f"{LINE_UP_CLF_BOUND:g} instead of 0.5",
    )
    args = parser.parse_args()
    if args.line_up and not (args.model == "body" and args.clf):
        parser.error("--line-up needs --model body --clf")
    if args.model == "body" and args.car_radius == [CAR_RADIUS]:
        args.car_radius = [PARKED_RADIUS + BODY_RADIUS]
    print(
        f"highway-env parking-v0, 10 parked cars, naive policy, {args.steps} steps each, "
        f"model {args.model}, alpha = alpha2 = {args.alpha:g}, CLF {'on' if args.clf else 'off'}"
        f"{', line-up' if args.line_up else ''}:"
    )
    print(
        "| shield | car disc radius | episodes | crashes (at a wall) | successes (by highway-env's "
        "test only) | relaxed | "
        "failed | time |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    settings = [(False, math.nan)] + [(True, r) for r in args.car_radius]
    for shielded, radius in settings:
        start = time.perf_counter()
        c = run(
            args.steps, shielded, args.seed, radius, args.alpha, args.model, args.clf, args.line_up
        )
        print(
            f"| {'on' if shielded else 'off'} | {radius:g} | {c['episodes']} | "
            f"{c['crashes']} ({c['wall_crashes']}) | "
            f"{c['successes']} ({c['env_successes']}) | {c['relaxed']} | {c['failed']} | "
            f"{time.perf_counter() - start:.0f} s |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
