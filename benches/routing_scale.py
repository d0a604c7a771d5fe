"""How routing's cost grows with the number of discs: one shield step of a single integrator
among N random discs (N = 1, 16, 64, 128; the goal behind them), routed against
``route=False`` on the same states, and the paper's channel task on random states (goals and
obstacles anywhere), routed against unrouted.

Each case reports the median step and its p99 (per state the median over the passes, then the
percentiles over the states) and the routed / unrouted ratios, measured in one run. With
``--before DIR`` the same measurement is first made in a subprocess importing ``tlshield`` from
``DIR`` (a copy of the package with an older build of its core), and both are printed side by
side: the before and after columns of one session.

Run: ``.venv/bin/python benches/routing_scale.py [--quick] [--before DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_shield import make_shield, make_steps, step_percentiles

#: Discs per field.
COUNTS = (1, 16, 64, 128)
#: States per field, and random channel states.
STATES = 500
CHANNEL_STATES = 3000


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


def field_case(n: int, rng: np.random.Generator, passes: int) -> dict:
    """One step of a single integrator among ``n`` discs, routed and not: the robot left of the
    field, the goal right of it (so that the straight line usually crosses discs)."""
    from tlshield.lab import routing

    discs, side = field(n, rng)
    goal = np.array([side + 1.0, rng.uniform(-0.5, 0.5) * side])
    shields = {
        on: routing.shield_for("single", discs, goal, "barriers", route=on) for on in (False, True)
    }
    q = shields[True].automaton.initial
    states = []
    while len(states) < STATES:
        p = np.array([rng.uniform(-side - 1.0, -side + 0.5), rng.uniform(-side, side)])
        if all(np.linalg.norm(p - c) > r * 1.05 for c, r in discs):
            states.append((p, rng.uniform(-0.5, 0.5, 2)))
    routed = sum(not np.array_equal(shields[True].filter(s, q, a).goal, goal) for s, a in states)
    out: dict = {"planned": int(routed)}
    for on, sh in shields.items():
        t = step_percentiles(lambda item, sh=sh: sh.filter(item[0], q, item[1]), states, passes)
        out["routed" if on else "unrouted"] = {"p50": t["p50"], "p99": t["p99"]}
    return out


def channel_case(rng: np.random.Generator, passes: int) -> dict:
    """``Shield.filter`` on random states of the channel task: goals and the moving
    obstacles anywhere around the channel."""
    steps = make_steps(rng, CHANNEL_STATES)
    for s, _ in steps:
        s[9:13] = rng.uniform(-1.0, 10.0, size=4)
    out: dict = {}
    for on in (False, True):
        shield = make_shield(route=on)
        q = shield.automaton.initial
        t = step_percentiles(
            lambda item, sh=shield, q=q: sh.filter(item[0], q, item[1]), steps, passes
        )
        out["routed" if on else "unrouted"] = {"p50": t["p50"], "p99": t["p99"]}
    return out


def measure(passes: int) -> dict:
    """Every case, from one seed."""
    rng = np.random.default_rng(0)
    cases = {f"N={n}": field_case(n, rng, passes) for n in COUNTS}
    cases["channel"] = channel_case(rng, passes)
    return cases


def row(name: str, case: dict) -> str:
    """One table row: median / p99 (us) unrouted and routed, and the ratios."""
    u, r = case["unrouted"], case["routed"]
    return (
        f"{name}: unrouted {u['p50'] * 1e6:.1f} / {u['p99'] * 1e6:.1f} us, routed "
        f"{r['p50'] * 1e6:.1f} / {r['p99'] * 1e6:.1f} us, ratio {r['p50'] / u['p50']:.2f}x / "
        f"{r['p99'] / u['p99']:.2f}x"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer passes (smoke run)")
    parser.add_argument("--before", help="a tlshield package directory to measure first")
    parser.add_argument("--json", action="store_true", help="print the measurement as JSON")
    args = parser.parse_args(argv)
    passes = 3 if args.quick else 7
    before = None
    if args.before:
        env = {**os.environ, "PYTHONPATH": args.before}
        cmd = [sys.executable, __file__, "--json"] + (["--quick"] if args.quick else [])
        before = json.loads(subprocess.run(cmd, env=env, check=True, capture_output=True).stdout)
    import tlshield

    after = measure(passes)
    if args.json:
        print(json.dumps(after))
        return 0
    print(f"tlshield from {Path(tlshield.__file__).parent}, {passes} passes")
    for name, case in after.items():
        if before is not None:
            print("  before " + row(name, before[name]))
        print("  after  " + row(name, case))
    for name, case in after.items():
        if name != "channel":
            print(f"{name}: {case['planned']} of {STATES} states routed (target is not the goal)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
