"""How routing's cost grows with the number of discs: shield steps of a single integrator
among N random discs (N = 1 to 256), routed against ``route=False`` on the same states, and
Channel-v0's states, routed against unrouted.

Cases, each measured in one run (the ratios are of numbers from the same process):
- ``static``: the robot driven through the field step by step, as an env steps it (the
  routed shield's action, a greedy policy towards the goal under it), discs that stay put;
- ``moving``: the same with every disc drifting on a small circle (its centre is a state
  dimension the shield reads, ``center_dims``), so every step's discs are new;
- ``states``: independent random states left of the static field, each unrelated to the
  last (the worst case: nothing carries from one step to the next);
- ``batch``: ``filter_batch`` over those independent states, the time per row;
- ``channel``: the states a Channel-v0 episode visits under random actions.

Each case reports the median step, its p99 and its max (per state the median over the passes,
then the percentiles over the states), routed and unrouted, and the ratios. With
``--before DIR`` the same measurement is first made in a subprocess importing ``tlshield`` from
``DIR`` (a copy of the package with an older build of its core), and both are printed side by
side.

Run: ``.venv/bin/python benches/route_scaling.py [--quick] [--before DIR] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_shield import step_percentiles

#: Discs per field.
COUNTS = (1, 16, 32, 64, 128, 256)
#: Independent states per field, trajectories per field and their longest length (steps).
STATES = 400
TRAJECTORIES = 3
HORIZON = 400
#: Channel-v0 episodes (random actions) whose states are timed.
CHANNEL_EPISODES = 4
#: How far (m) and how fast (rad/s) each moving disc drifts about its place.
DRIFT, SPIN = 0.3, 0.5
#: Batch rows timed per call.
BATCH = 256


def field(n: int, rng: np.random.Generator) -> tuple[list[tuple[np.ndarray, float]], float]:
    """``n`` non-overlapping discs (radius 0.2 to 0.5) in a square that grows with ``n`` (about
    one disc per 6 m^2), and the square's half side."""
    side = max(1.0, 1.2 * np.sqrt(n))
    discs: list[tuple[np.ndarray, float]] = []
    while len(discs) < n:
        c = rng.uniform(-side, side, 2) if n > 1 else np.zeros(2)
        r = float(rng.uniform(0.2, 0.5))
        if all(np.linalg.norm(c - o) > r + ro for o, ro in discs):
            discs.append((c, r))
    return discs, side


def shield(discs: list[tuple[np.ndarray, float]], goal: np.ndarray, moving: bool, route: bool):
    """The single integrator's shield among ``discs`` (as the routing lab's, barriers): with
    ``moving``, each disc's centre is read from the state, after the robot's position."""
    from tlshield import Avoid, Ball, Shield, Spec
    from tlshield.lab import routing

    r = routing.robot("single")
    spec = Spec("F goal", {"goal": Ball(pos=[0, 1], radius=routing.GOAL_RADIUS, center=list(goal))})
    barriers = {
        f"!o{i + 1}": Avoid(
            Ball(pos=[0, 1], radius=rad, center_dims=[2 + 2 * i, 3 + 2 * i])
            if moving
            else Ball(pos=[0, 1], radius=rad, center=list(c))
        )
        for i, (c, rad) in enumerate(discs)
    }
    return Shield(spec, r.model, barriers=barriers, route=route, dt=routing.DT, **r.shield_kwargs)


def free(p: np.ndarray, discs: list[tuple[np.ndarray, float]]) -> bool:
    return all(np.linalg.norm(p - c) > r * 1.05 for c, r in discs)


def start(side: float, discs, rng: np.random.Generator) -> np.ndarray:
    """A free point left of the field."""
    while True:
        p = np.array([rng.uniform(-side - 1.0, -side + 0.5), rng.uniform(-side, side)])
        if free(p, discs):
            return p


def trajectories(n: int, rng: np.random.Generator, moving: bool) -> tuple[list, object, object]:
    """States along ``TRAJECTORIES`` drives through a field of ``n`` discs (the routed shield's
    action under a greedy policy towards the goal), and the two shields (unrouted, routed)."""
    from tlshield.lab import routing

    discs, side = field(n, rng)
    goal = np.array([side + 1.0, rng.uniform(-0.5, 0.5) * side])
    shields = [shield(discs, goal, moving, on) for on in (False, True)]
    q = shields[1].automaton.initial
    centres = np.concatenate([c for c, _ in discs]) if moving else np.empty(0)
    phase = rng.uniform(0, 2 * np.pi, len(discs))
    steps = []
    for _ in range(TRAJECTORIES):
        s = np.concatenate([start(side, discs, rng), centres])
        for t in range(HORIZON):
            if moving:
                angle = phase + SPIN * t * routing.DT
                offset = DRIFT * np.stack([np.cos(angle), np.sin(angle)], axis=1).ravel()
                s[2:] = centres + offset
            a = 0.5 * routing.SPEED * routing._unit(goal - s[:2])
            steps.append((s.copy(), a))
            s[:2] += routing.DT * shields[1].filter(s, q, a).action
            if np.linalg.norm(s[:2] - goal) < routing.GOAL_RADIUS:
                break
    return steps, q, shields


def timed(shields, q, steps, passes: int) -> dict:
    """Per-step percentiles of both shields on ``steps`` (in order, as an env steps them)."""
    out = {}
    for on, sh in zip(("unrouted", "routed"), shields, strict=True):
        t = step_percentiles(lambda item, sh=sh: sh.filter(item[0], q, item[1]), steps, passes)
        out[on] = {k: t[k] for k in ("p50", "p99", "max")}
    return out


def field_cases(n: int, rng: np.random.Generator, passes: int) -> dict:
    """Every case of one field size."""
    out = {}
    for name, moving in (("static", False), ("moving", True)):
        steps, q, shields = trajectories(n, rng, moving)
        out[name] = timed(shields, q, steps, passes) | {"steps": len(steps)}
    # Independent states left of a static field (and the same rows as one batch).
    discs, side = field(n, rng)
    goal = np.array([side + 1.0, rng.uniform(-0.5, 0.5) * side])
    shields = [shield(discs, goal, False, on) for on in (False, True)]
    q = shields[1].automaton.initial
    states = [(start(side, discs, rng), rng.uniform(-0.5, 0.5, 2)) for _ in range(STATES)]
    out["states"] = timed(shields, q, states, passes)
    out["states"]["planned"] = int(
        sum(not np.array_equal(shields[1].filter(s, q, a).goal, goal) for s, a in states)
    )
    rows = np.array([s for s, _ in states[:BATCH]])
    acts = np.array([a for _, a in states[:BATCH]])
    qs = np.full(len(rows), q)
    batch = {}
    for on, sh in zip(("unrouted", "routed"), shields, strict=True):
        best = np.inf
        for _ in range(passes):
            t0 = time.perf_counter()
            sh.filter_batch(rows, qs, acts)
            best = min(best, time.perf_counter() - t0)
        batch[on] = best / len(rows)
    out["batch"] = batch
    return out


def channel_case(rng: np.random.Generator, passes: int) -> dict:
    """The states Channel-v0 visits under random actions, routed against unrouted (the
    paper's task shield with the reference parameters)."""
    import gymnasium as gym
    from compare_shield import make_shield

    import tlshield  # noqa: F401  (registers the environments)

    env = gym.make("tlshield/Channel-v0")
    monitor = env.unwrapped.tracker.monitor
    steps = []
    for episode in range(CHANNEL_EPISODES):
        env.reset(seed=episode)
        done = False
        while not done:
            steps.append((monitor.state.copy(), monitor.q, rng.uniform([-4.0, -6.0], [4.0, 6.0])))
            _, _, term, trunc, _ = env.step(env.action_space.sample())
            done = term or trunc
    out = {}
    for on in (False, True):
        sh = make_shield(route=on)
        t = step_percentiles(lambda item, sh=sh: sh.filter(*item), steps, passes)
        out["routed" if on else "unrouted"] = {k: t[k] for k in ("p50", "p99", "max")}
    out["steps"] = len(steps)
    return out


def measure(passes: int, counts: tuple[int, ...]) -> dict:
    """Every case, from one seed."""
    rng = np.random.default_rng(0)
    cases = {f"N={n}": field_cases(n, rng, passes) for n in counts}
    cases["channel"] = channel_case(rng, passes)
    return cases


def us(v: float) -> str:
    return f"{v * 1e6:.1f}"


def rows(cases: dict) -> list[str]:
    """Markdown rows: per case, unrouted and routed median / p99 / max (us) and the ratios
    routed median / unrouted median and routed p99 / routed median."""
    out = []
    for name, case in cases.items():
        parts = {"channel": case} if name == "channel" else case
        for kind, c in parts.items():
            if kind == "batch":
                u, r = c["unrouted"], c["routed"]
                out.append(f"| {name} | batch row | {us(u)} | {us(r)} | {r / u:.2f}x | |")
                continue
            u, r = c["unrouted"], c["routed"]
            out.append(
                f"| {name} | {kind} | {us(u['p50'])} / {us(u['p99'])} / {us(u['max'])} "
                f"| {us(r['p50'])} / {us(r['p99'])} / {us(r['max'])} "
                f"| {r['p50'] / u['p50']:.2f}x | {r['p99'] / r['p50']:.2f}x |"
            )
    return out


HEADER = [
    "| discs | case | unrouted median / p99 / max (us) | routed median / p99 / max (us) "
    "| routed / unrouted median | routed p99 / median |",
    "|---|---|---|---|---|---|",
]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer passes and fields (smoke)")
    parser.add_argument("--before", help="a tlshield package directory to measure first")
    parser.add_argument("--json", action="store_true", help="print the measurement as JSON")
    args = parser.parse_args(argv)
    passes = 3 if args.quick else 7
    counts = (1, 16, 64) if args.quick else COUNTS
    before = None
    if args.before:
        env = {**os.environ, "PYTHONPATH": args.before}
        cmd = [sys.executable, __file__, "--json"] + (["--quick"] if args.quick else [])
        before = json.loads(subprocess.run(cmd, env=env, check=True, capture_output=True).stdout)
    import tlshield

    after = measure(passes, counts)
    if args.json:
        print(json.dumps(after))
        return 0
    print(f"tlshield from {Path(tlshield.__file__).parent}, {passes} passes")
    if before is not None:
        print("before:", *HEADER, *rows(before), "", "after:", sep="\n")
    print(*HEADER, *rows(after), sep="\n")
    cases = [(name, c) for name, c in after.items() if name != "channel"]
    for name, case in cases:
        planned = case["states"]["planned"]
        print(f"{name}: {planned} of {STATES} independent states routed (target is not the goal)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
