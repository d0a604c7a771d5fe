"""Warehouse scenarios for the shield's guidance (docs/concepts/deadlock.md, "Warehouse"): a
robot in an aisle picks up at P, then drops off at D inside an alcove of shelves, while a
forklift crosses the aisle between the two. The task is ``F (p & F d)``; the shelves and the
forklift are the shield's ``Avoid`` barriers (discs: only discs are routed around).

The floor, in metres. The aisle runs along x. North of it (y = 1) runs a row of shelves, each
a chain of overlapping discs; a cross aisle (x about -0.2) breaks the row, and further east the
row opens into an alcove, three walls of shelves around ``D`` with its mouth on the aisle. The
robot starts near ``(-3, 0.2)`` and ``P`` is near ``(-1.5, -1)``, so the straight line from
``P`` to ``D`` crosses the alcove's west wall: the way in goes round its corner. The forklift
(a disc whose centre is read from the state, ``Ball(..., center_dims=...)``) comes up from the
south at constant speed, crosses the aisle at x = -0.2 and stops in the cross aisle, clear of
the aisle; the scenario moves its centre each step and passes its velocity as the shield's
``drift``.

Three variants:

- ``alcove``: the above.
- ``covered``: a pallet (a larger shelf disc) inside the alcove covers ``D``'s centre; the part
  of ``D`` beyond the pallet, towards the alcove's back wall, is free and reachable by either
  side of the pallet. Parking at the pallet's rim nearest the aisle does not reach ``D``.
- ``enclosed``: shelves close the alcove's mouth. ``D`` cannot be reached; the measure is
  whether ``FilterResult.goal_unreachable`` says so at every step whose goal is ``D``.

The robots are ``tlshield.lab.routing``'s (the same models, gains, recommended CLF box
``CLF_SHARE`` of the limits and greedy seekers), and the kinematic bicycle of
``scripts/robot_reach.py`` (wheelbase 0.5 m; inputs acceleration and ``tan(steer)``, each
bounded by 1; the acceleration-level robots' gains). The drivers are the shield alone (a zero
RL action) and a greedy seeker pushing straight at the task's current goal (``Monitor.goal``:
``P``'s centre, then ``D``'s), never at the routed target. The bicycle's seeker accelerates
towards a speed that falls with its heading error (never below a creep, since a car turns only
while it moves) and steers at the goal.

Every episode is seeded: the robot's start, ``P`` and the forklift's start are jittered from
``numpy.random.default_rng(seed)``; the shelves and ``D`` are fixed.

``python -m tlshield.lab.warehouse --episodes 30`` prints a table per variant.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np

from tlshield import Avoid, Ball, Monitor, Shield, Spec, Status
from tlshield.lab import routing

VARIANTS = ("alcove", "covered", "enclosed")
ROBOTS = routing.ALL_ROBOTS
DRIVERS = routing.DRIVERS

#: A shelf is a chain of discs this big (m), centres this far apart: they overlap, so the
#: chain has no gap a point could pass.
SHELF_RADIUS = 0.25
SHELF_PITCH = 0.4
#: The aisle's north row of shelves (y) and the alcove's walls: its west and east walls' x and
#: its back wall's y. The alcove's inside is 1.5 m wide and about 1.35 m deep.
ROW_Y = 1.0
ALCOVE_WEST, ALCOVE_EAST, ALCOVE_BACK = 1.4, 3.4, 2.6
#: The cross aisle the forklift leaves through: the row breaks between these x (disc centres).
CROSS_AISLE = (-1.0, 0.6)

START = np.array([-3.0, 0.2])
P = np.array([-1.5, -1.0])
#: The goals' radius, and D's centre and radius inside the alcove (the covered variant's D is
#: larger: its free part beyond the pallet must hold a robot's point with room to spare).
GOAL_RADIUS = 0.2
D = np.array([2.4, 1.85])
COVERED_D_RADIUS = 0.4
#: The covered variant's pallet: it holds D's centre and reaches 0.25 m past D's rim towards
#: the aisle, leaving the 0.15 m of D nearest the back wall free (and a 0.25 m lane between
#: the pallet and the back wall, 0.3 m on either side of it).
PALLET = (np.array([2.4, 1.65]), 0.45)

#: The forklift: its disc's radius (m), the x of its crossing, its speed northward (m/s, a
#: third of the robots' speed limit), the range its start's y is drawn from, so that it meets
#: the robot at different points of the robot's way from P to D, and where it stops. It stops
#: because a disc that drives on for ever ends far from the rest: about 16 m from the robot, the
#: enclosed variant's search for a way to D stops at its work bound, which reports D reachable.
FORKLIFT_RADIUS = 0.4
FORKLIFT_X = -0.2
FORKLIFT_SPEED = 0.35
FORKLIFT_START_Y = (-5.0, -2.0)
FORKLIFT_STOP_Y = 2.5

DT = routing.DT
#: Steps per episode: 60 s, about three times the way's length at the CLF's speed.
HORIZON = 1200


def _chain(a: np.ndarray, b: np.ndarray) -> list[tuple[np.ndarray, float]]:
    """A shelf from ``a`` to ``b``: discs at most ``SHELF_PITCH`` apart, both ends included."""
    n = int(np.ceil(np.linalg.norm(b - a) / SHELF_PITCH - 1e-9))
    return [(a + (b - a) * i / n, SHELF_RADIUS) for i in range(n + 1)]


def shelves(variant: str) -> list[tuple[np.ndarray, float]]:
    """The still obstacles (centre, radius) of a variant: the aisle's row, the alcove, and the
    covered variant's pallet or the enclosed variant's shelf across the alcove's mouth."""
    if variant not in VARIANTS:
        raise ValueError(f"variant: expected one of {VARIANTS}, got {variant!r}")
    west, east = CROSS_AISLE
    pt = np.array
    discs = (
        _chain(pt([-4.2, ROW_Y]), pt([west, ROW_Y]))
        + _chain(pt([east, ROW_Y]), pt([ALCOVE_WEST - SHELF_PITCH, ROW_Y]))
        + _chain(pt([ALCOVE_WEST, ROW_Y]), pt([ALCOVE_WEST, ALCOVE_BACK]))
        + _chain(pt([ALCOVE_WEST + SHELF_PITCH, ALCOVE_BACK]), pt([ALCOVE_EAST, ALCOVE_BACK]))
        + _chain(pt([ALCOVE_EAST, ALCOVE_BACK - SHELF_PITCH]), pt([ALCOVE_EAST, ROW_Y]))
        + _chain(pt([ALCOVE_EAST + SHELF_PITCH, ROW_Y]), pt([4.6, ROW_Y]))
    )
    if variant == "covered":
        discs.append(PALLET)
    if variant == "enclosed":
        mouth = _chain(pt([ALCOVE_WEST, ROW_Y]), pt([ALCOVE_EAST, ROW_Y]))
        discs += mouth[1:-1]
    return discs


def d_radius(variant: str) -> float:
    """D's radius in a variant."""
    return COVERED_D_RADIUS if variant == "covered" else GOAL_RADIUS


def shield_for(robot_name: str, variant: str, goal_p: np.ndarray, n: int) -> Shield:
    """The shield of one episode over states ``(robot's state, forklift's x, y)``, the
    forklift's centre at dimensions ``n, n + 1``."""
    r = routing.robot(robot_name)
    spec = Spec(
        "F (p & F d)",
        {
            "p": Ball([0, 1], GOAL_RADIUS, center=list(goal_p)),
            "d": Ball([0, 1], d_radius(variant), center=list(D)),
        },
    )
    barriers = {
        f"shelf{i}": Avoid(Ball([0, 1], rad, center=list(c)))
        for i, (c, rad) in enumerate(shelves(variant))
    }
    barriers["forklift"] = Avoid(Ball([0, 1], FORKLIFT_RADIUS, center_dims=[n, n + 1]))
    return Shield(spec, r.model, barriers=barriers, dt=DT, **r.shield_kwargs)


@dataclass(frozen=True)
class Episode:
    """What one episode gave: ``success`` is the task done (P, then D) without ever entering a
    shelf or the forklift; ``d_steps`` counts the steps whose goal was D, ``unreachable`` those
    of them with ``goal_unreachable`` set, ``p_unreachable`` the steps whose goal was P with it
    set; ``end`` is where the robot's point was last, and ``forklift_gap`` how close it came to
    the forklift's rim (m)."""

    success: bool
    entries: int
    steps: int
    relaxed: int
    d_steps: int
    unreachable: int
    p_unreachable: int
    end: tuple[float, float]
    forklift_gap: float


def episode(variant: str, robot_name: str, driver: str, seed: int) -> Episode:
    """One seeded episode (see the module docs)."""
    rng = np.random.default_rng(seed)
    start = START + rng.uniform(-0.1, 0.1, 2)
    goal_p = P + rng.uniform(-0.1, 0.1, 2)
    fork = np.array([FORKLIFT_X, rng.uniform(*FORKLIFT_START_Y)])
    r = routing.robot(robot_name)
    robot_state = r.start(start)
    n = len(robot_state)
    shield = shield_for(robot_name, variant, goal_p, n)
    still = shelves(variant)
    centres = np.array([c for c, _ in still])
    radii = np.array([rad for _, rad in still])
    drift = np.zeros(n + 2)
    monitor = Monitor(shield.automaton)
    initial = shield.automaton.initial
    s = np.concatenate([robot_state, fork])
    task = monitor.reset(s)
    entries = relaxed = d_steps = unreachable = p_unreachable = 0
    gap = np.inf
    for t in range(HORIZON):
        # The forklift's velocity over the coming step, which the barrier's row reads.
        drift[n + 1] = min(FORKLIFT_SPEED, (FORKLIFT_STOP_Y - s[n + 1]) / DT)
        if driver == "shield":
            a_rl = np.zeros(2)
        else:
            a_rl = r.seeker(s[:n], monitor.goal)
        out = shield.filter_monitor(monitor, a_rl, drift=drift)
        relaxed += out.status != Status.SOLVED
        if task.q == initial:
            p_unreachable += out.goal_unreachable
        else:
            d_steps += 1
            unreachable += out.goal_unreachable
        s = r.model.step(s, out.action, DT)
        s[n + 1] += drift[n + 1] * DT
        p = s[:2]
        inside = np.any(np.linalg.norm(centres - p, axis=1) < radii)
        to_forklift = float(np.linalg.norm(p - s[n : n + 2])) - FORKLIFT_RADIUS
        gap = min(gap, to_forklift)
        entries += bool(inside or to_forklift < 0.0)
        task = monitor.advance(s)
        if task.accepted:
            end = (float(p[0]), float(p[1]))
            return Episode(entries == 0, entries, t + 1, relaxed, d_steps, unreachable, 0, end, gap)
    end = (float(s[0]), float(s[1]))
    return Episode(False, entries, HORIZON, relaxed, d_steps, unreachable, p_unreachable, end, gap)


def cell(variant: str, robot_name: str, driver: str, episodes: int) -> dict:
    """Over seeds ``0..episodes-1``: the success rate, obstacle entries, relaxed QPs,
    ``d_steps``, the steps whose goal was D, ``flagged``, how many of them had
    ``goal_unreachable`` set, ``flagged_p``, the steps whose goal was P with it set, and
    ``forklift_gap``, how close any episode came to the forklift's rim (m)."""
    runs = [episode(variant, robot_name, driver, seed) for seed in range(episodes)]
    return {
        "success": sum(e.success for e in runs) / episodes,
        "entries": sum(e.entries for e in runs),
        "relaxed": sum(e.relaxed for e in runs),
        "d_steps": sum(e.d_steps for e in runs),
        "flagged": sum(e.unreachable for e in runs),
        "flagged_p": sum(e.p_unreachable for e in runs),
        "forklift_gap": min(e.forklift_gap for e in runs),
    }


def table(variant: str, episodes: int) -> str:
    """The markdown table of one variant: one row per robot and driver. The steps flagged
    unreachable are counted over the steps whose goal was D (after P)."""
    lines = [
        "| robot | driver | success | entries | relaxed QPs | D-steps flagged unreachable "
        "| closest to the forklift (m) |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for robot_name in ROBOTS:
        for driver in DRIVERS:
            c = cell(variant, robot_name, driver, episodes)
            # Counts, not a share: "every step" must not hide behind a rounded 1.00.
            flagged = "all" if c["flagged"] == c["d_steps"] else str(c["flagged"])
            flagged += f" of {c['d_steps']}"
            if c["flagged_p"]:
                flagged += f" (P-steps: {c['flagged_p']})"
            lines.append(
                f"| {robot_name} | {driver} | {c['success']:.2f} | {c['entries']} "
                f"| {c['relaxed']} | {flagged} | {c['forklift_gap']:.2f} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Prints the tables (``--help``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--variant", choices=(*VARIANTS, "all"), default="all")
    args = parser.parse_args(argv)
    variants = VARIANTS if args.variant == "all" else (args.variant,)
    box = f"CLF box {routing.CLF_SHARE:g} x the limits"
    for variant in variants:
        print(f"**{variant}**, k = the rule, {box} ({args.episodes} episodes per cell)")
        print()
        print(table(variant, args.episodes))
        print()


if __name__ == "__main__":
    main()
