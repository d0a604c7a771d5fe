"""Scripted scenarios for the shield's guidance: a robot on one side of obstacles, its goal on
the other (docs/concepts/deadlock.md). They measure whether the shield routes around what it
keeps the robot out of, or parks in front of it (the CLF-CBF deadlock).

Four layouts (a disc on the line, a disc 5 cm off it, a concave U of three discs, eight random
discs), six robots (single integrator, the paper's unicycle reference point, a double
integrator; the acceleration unicycle and ThrustTurn, which turn at acceleration level; the
kinematic bicycle, a car that turns only while moving), two encodings (the obstacles in the
formula, ``(!o1 & ...) U goal``, or as the shield's barriers with ``F goal``) and two drivers
(the shield alone, a zero RL action; a greedy seeker pushing straight at the goal through
CBF+CLF). Every episode is seeded: the start and the goal are jittered, and the random layout is
drawn, from ``numpy.random.default_rng(seed)``.

How the drivers and boxes are set: every robot's inputs are bounded by its limits (``SPEED`` for
a velocity or an acceleration, ``TURN`` for the unicycle's turn rate, ``SPEED`` for the turn of
the robots that turn at acceleration level). The CLF's box is ``CLF_SHARE`` of the limits (half,
the guides' recommendation), the CBF's three times the limits, and k is the rule's,
``clf_bound / (d gain)`` (``TURN_GAIN`` for the turn of the robots that turn at acceleration
level). The seeker pushes at half the speed limit (times the cosine of its
heading error, for the robots that turn) and turns at the full rate: twice its heading error,
clipped to the turn limit.

``python -m tlshield.lab.routing --episodes 50`` prints the tables, with routing on and off.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tlshield import (
    AccelerationUnicycle,
    Avoid,
    Ball,
    DoubleIntegrator,
    KinematicBicycle,
    Monitor,
    Shield,
    SingleIntegrator,
    Spec,
    Status,
    ThrustTurn,
    Unicycle,
)

LAYOUTS = ("line", "off_line", "u_shape", "random8")
ROBOTS = ("single", "unicycle", "double")
#: Robots that must turn at acceleration level, measured beside ROBOTS.
TURNING = ("accel_unicycle", "thrust_turn")
#: Robots that turn only while moving: the kinematic bicycle (a car).
CARS = ("bicycle",)
#: Every robot the lab drives.
ALL_ROBOTS = ROBOTS + TURNING + CARS
ENCODINGS = ("formula", "barriers")
DRIVERS = ("shield", "seeker")

#: Where the robot starts and where its goal is (before the per-episode jitter).
START = np.array([-2.0, 0.0])
GOAL = np.array([2.0, 0.0])
#: The goal region's radius (reached when the reference point is inside it).
GOAL_RADIUS = 0.2
DT = 0.05
#: Steps per episode: 40 s, several times what the straight line takes.
HORIZON = 800
#: The speed bound of every robot (m/s) and the unicycle's turn rate bound (rad/s).
SPEED = 1.0
TURN = 3.0
#: The CLF gain by the rule k = clf_bound / d with d = 0.5 m (docs/concepts/shield.md).
CLF_DISTANCE = 0.5
#: The CLF's box as a share of the limits: half, as docs/guides/own-robot.md recommends
#: (``--clf-share`` measures others).
CLF_SHARE = 0.5


def layout(name: str, rng: np.random.Generator) -> list[tuple[np.ndarray, float]]:
    """The obstacles (centre, radius) of a layout; the random one is drawn from ``rng``."""
    if name == "line":
        return [(np.array([0.0, 0.0]), 0.5)]
    if name == "off_line":
        return [(np.array([0.0, 0.05]), 0.5)]
    if name == "u_shape":
        # A cup open towards the robot: the goal's direction points into its bottom.
        return [
            (np.array([0.0, 0.75]), 0.45),
            (np.array([0.55, 0.0]), 0.45),
            (np.array([0.0, -0.75]), 0.45),
        ]
    if name == "random8":
        discs: list[tuple[np.ndarray, float]] = []
        while len(discs) < 8:
            c = rng.uniform([-1.2, -1.2], [1.2, 1.2])
            r = float(rng.uniform(0.2, 0.35))
            if all(np.linalg.norm(c - o) > r + ro + 0.05 for o, ro in discs):
                discs.append((c, r))
        return discs
    raise ValueError(f"layout: expected one of {LAYOUTS}, got {name!r}")


@dataclass(frozen=True)
class Robot:
    """A robot: its model (the plant and the shield's model), start state, the shield's
    keywords and a greedy seeker's action."""

    model: object
    start: Callable[[np.ndarray], np.ndarray]
    shield_kwargs: dict
    seeker: Callable[[np.ndarray, np.ndarray], np.ndarray]


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else np.zeros_like(v)


def _wrap(a: float) -> float:
    return (a + np.pi) % (2 * np.pi) - np.pi


#: The bicycle's wheelbase (m), and the speed its seeker asks for at most and at least (m/s,
#: the creep that keeps it turning: a car turns only while moving).
WHEELBASE = 0.5
CAR_SPEED = 0.5 * SPEED
CAR_CREEP = 0.1

#: Overrides every robot's k when set (``--k``), to measure other gains.
K_OVERRIDE: float | None = None


def robot(name: str) -> Robot:
    """One of ``ROBOTS``, with the gains the guides recommend (k = clf_bound / (d gain))."""
    r = _robot(name)
    if K_OVERRIDE is not None:
        r.shield_kwargs["k"] = K_OVERRIDE
    return r


def _heading_error(s: np.ndarray, g: np.ndarray) -> float:
    """The angle from the heading ``s[2]`` to the goal ``g``, in ``[-pi, pi)``."""
    return _wrap(float(np.arctan2(g[1] - s[1], g[0] - s[0]) - s[2]))


#: The gain the rule reads for the turn of a robot that turns at acceleration level, whose turn
#: reaches the position only through the heading (no gain of its own): the unicycle's eps. At
#: the recommended box, the rule's k without it (``clf_bound / d`` = 1) leaves the acceleration
#: unicycle's shield alone parked in front of a single disc.
TURN_GAIN = 0.1
#: ThrustTurn's drag (1/s), which bounds its alpha.
DRAG = 1.0


def _second_order(b: float, turn_gain: float = 1.0) -> dict:
    """The gains of an acceleration-level robot with inputs bounded by ``b`` (``turn_gain``:
    the gain the rule reads for its turn)."""
    c = CLF_SHARE * b
    return dict(
        alpha=2.0,
        alpha2=2.0,
        c3=1.0,
        k=c / (CLF_DISTANCE * turn_gain),
        clf_gain=1.0,
        cbf_bounds=(-3 * b, 3 * b),
        clf_bounds=(-c, c),
    )


def _robot(name: str) -> Robot:
    if name == "single":
        b = SPEED
        c = CLF_SHARE * b
        return Robot(
            SingleIntegrator([0, 1]),
            lambda p: p.copy(),
            dict(
                alpha=2.0,
                c3=1.0,
                k=c / CLF_DISTANCE,
                cbf_bounds=(-3 * b, 3 * b),
                clf_bounds=(-c, c),
            ),
            lambda s, g: 0.5 * SPEED * _unit(g - s[:2]),
        )
    if name == "unicycle":
        lo, hi = (-SPEED, -TURN), (SPEED, TURN)

        def seek(s: np.ndarray, g: np.ndarray) -> np.ndarray:
            err = _heading_error(s, g)
            return np.array([0.5 * SPEED * max(np.cos(err), 0.0), np.clip(2.0 * err, -TURN, TURN)])

        return Robot(
            Unicycle(eps=0.1),
            lambda p: np.array([p[0], p[1], 0.0]),
            dict(
                alpha=2.0,
                c3=1.0,
                # The rule per input, k = bound / (d * gain): the turn rate moves the point
                # eps = 0.1 ahead at eps * omega, so k = CLF_SHARE * TURN / (CLF_DISTANCE * 0.1).
                k=CLF_SHARE * TURN / (CLF_DISTANCE * 0.1),
                cbf_bounds=(tuple(3 * x for x in lo), tuple(3 * x for x in hi)),
                clf_bounds=(
                    tuple(CLF_SHARE * x for x in lo),
                    tuple(CLF_SHARE * x for x in hi),
                ),
            ),
            seek,
        )
    if name == "double":
        b = SPEED

        def seek_double(s: np.ndarray, g: np.ndarray) -> np.ndarray:
            return np.clip(1.0 * _unit(g - s[:2]) * 0.5 - 1.0 * s[2:], -0.5 * b, 0.5 * b)

        return Robot(
            DoubleIntegrator([0, 1], [2, 3]),
            lambda p: np.array([p[0], p[1], 0.0, 0.0]),
            _second_order(b),
            seek_double,
        )
    if name in TURNING:
        # x, y, theta, then v (the acceleration unicycle) or vx, vy (ThrustTurn: a body pushed
        # along its heading, with drag, like Safety-Gymnasium's Point).
        model = AccelerationUnicycle() if name == "accel_unicycle" else ThrustTurn(2.0, 3.0, DRAG)

        def seek_turning(s: np.ndarray, g: np.ndarray) -> np.ndarray:
            err = _heading_error(s, g)
            return np.array(
                [0.5 * SPEED * max(np.cos(err), 0.0), float(np.clip(2.0 * err, -SPEED, SPEED))]
            )

        gains = _second_order(SPEED, TURN_GAIN)
        if name == "thrust_turn":
            # A body that slides keeps alpha <= drag <= alpha + alpha2 (own-robot.md, "alpha,
            # alpha2"): the drag alone then keeps the second-order row among still discs, so
            # the QP has a solution whatever the heading. At alpha = 2 the thrust, across the
            # barrier, had no hold on it and the shield gave way into a shelf.
            gains["alpha"] = gains["alpha2"] = DRAG
        return Robot(
            model,
            lambda p: np.concatenate([p, np.zeros(2 if name == "accel_unicycle" else 3)]),
            gains,
            seek_turning,
        )
    if name in CARS:
        # x, y, theta, v; inputs (acceleration, tan(steer)), each bounded by SPEED (1), with
        # the acceleration-level gains.
        def seek_car(s: np.ndarray, g: np.ndarray) -> np.ndarray:
            err = _heading_error(s, g)
            speed = max(CAR_SPEED * np.cos(err), CAR_CREEP)
            accel = np.clip(2.0 * (speed - s[3]), -SPEED, SPEED)
            return np.array([accel, np.clip(2.0 * err, -SPEED, SPEED)])

        return Robot(
            KinematicBicycle(WHEELBASE),
            lambda p: np.array([p[0], p[1], 0.0, 0.0]),
            _second_order(SPEED, TURN_GAIN),
            seek_car,
        )
    raise ValueError(f"robot: expected one of {ALL_ROBOTS}, got {name!r}")


def shield_for(
    robot_name: str,
    obstacles: list[tuple[np.ndarray, float]],
    goal: np.ndarray,
    encoding: str,
    route: bool,
) -> Shield:
    """The shield of one episode: obstacles in the formula or as barriers."""
    r = robot(robot_name)
    balls = {
        f"o{i + 1}": Ball(pos=[0, 1], radius=rad, center=list(c))
        for i, (c, rad) in enumerate(obstacles)
    }
    goal_ball = Ball(pos=[0, 1], radius=GOAL_RADIUS, center=list(goal))
    if encoding == "formula":
        avoid = " & ".join(f"!{name}" for name in balls)
        spec = Spec(f"({avoid}) U goal", {**balls, "goal": goal_ball})
        barriers = None
    elif encoding == "barriers":
        spec = Spec("F goal", {"goal": goal_ball})
        barriers = {f"!{name}": Avoid(ball) for name, ball in balls.items()}
    else:
        raise ValueError(f"encoding: expected one of {ENCODINGS}, got {encoding!r}")
    return Shield(spec, r.model, barriers=barriers, route=route, dt=DT, **r.shield_kwargs)


@dataclass(frozen=True)
class Episode:
    """What one episode gave: ``success`` is the goal reached without ever entering an
    obstacle (an episode that touched one is never a success, in either encoding)."""

    success: bool
    entries: int
    steps: int
    relaxed: int


def episode(
    layout_name: str, robot_name: str, encoding: str, driver: str, seed: int, route: bool = True
) -> Episode:
    """One seeded episode (see the module docs)."""
    rng = np.random.default_rng(seed)
    start = START + rng.uniform(-0.1, 0.1, 2)
    goal = GOAL + rng.uniform(-0.1, 0.1, 2)
    obstacles = layout(layout_name, rng)
    r = robot(robot_name)
    shield = shield_for(robot_name, obstacles, goal, encoding, route)
    monitor = Monitor(shield.automaton)
    s = r.start(start)
    monitor.reset(s)
    m = 2
    entries = relaxed = 0
    for t in range(HORIZON):
        a_rl = np.zeros(m) if driver == "shield" else r.seeker(s, goal)
        out = shield.filter_monitor(monitor, a_rl)
        relaxed += out.status != Status.SOLVED
        s = r.model.step(s, out.action, DT)
        p = s[:2]
        entries += any(np.linalg.norm(p - c) < rad for c, rad in obstacles)
        monitor.advance(s)
        if np.linalg.norm(p - goal) < GOAL_RADIUS:
            return Episode(entries == 0, entries, t + 1, relaxed)
    return Episode(False, entries, HORIZON, relaxed)


def cell(
    layout_name: str, robot_name: str, encoding: str, driver: str, episodes: int, route: bool = True
) -> dict:
    """Success rate, obstacle entries and relaxed steps over seeds ``0..episodes-1``."""
    runs = [
        episode(layout_name, robot_name, encoding, driver, seed, route) for seed in range(episodes)
    ]
    return {
        "success": sum(e.success for e in runs) / episodes,
        "entries": sum(e.entries for e in runs),
        "relaxed": sum(e.relaxed for e in runs),
    }


def table(episodes: int, route: bool) -> str:
    """The markdown table: one row per robot and driver, one column per layout; each cell
    ``success formula / barriers`` (entries are counted and reported below the table)."""
    lines = [
        "| robot | driver | " + " | ".join(LAYOUTS) + " |",
        "|---|---|" + "---|" * len(LAYOUTS),
    ]
    entries = relaxed = 0
    for robot_name in ALL_ROBOTS:
        for driver in DRIVERS:
            cells = []
            for layout_name in LAYOUTS:
                parts = []
                for encoding in ENCODINGS:
                    c = cell(layout_name, robot_name, encoding, driver, episodes, route)
                    entries += c["entries"]
                    relaxed += c["relaxed"]
                    parts.append(f"{c['success']:.2f}")
                cells.append(" / ".join(parts))
            lines.append(f"| {robot_name} | {driver} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(f"Obstacle entries: {entries}; relaxed or failed QPs: {relaxed}.")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Prints the tables (``--help``)."""
    global K_OVERRIDE, CLF_SHARE
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--route", choices=("on", "off", "both"), default="both")
    parser.add_argument("--k", type=float, default=None, help="every robot's k (default: the rule)")
    parser.add_argument(
        "--clf-share",
        type=float,
        default=CLF_SHARE,
        help="the CLF's box as a share of the limits (default: half, the recommended box)",
    )
    args = parser.parse_args(argv)
    K_OVERRIDE = args.k
    CLF_SHARE = args.clf_share
    for route in {"on": [True], "off": [False], "both": [False, True]}[args.route]:
        k = "the rule" if args.k is None else f"{args.k:g}"
        where = "on" if route else "off"
        box = f"CLF box {CLF_SHARE:g} x the limits"
        print(f"routing {where}, k = {k}, {box} ({args.episodes} episodes per cell)")
        print("each cell: success with the obstacles in the formula / as barriers")
        print(table(args.episodes, route))
        print()


if __name__ == "__main__":
    main()
