"""Trajectory robustness of the paper's task: tlshield against rtamt and argus, in one run.

Run from the repository root (``make bench`` installs rtamt and argus through the ``bench``
extra first)::

    .venv/bin/python benches/compare_robustness.py [--seed N] [--quick] [--json PATH]

The task ``(F g1 | F g2) & F g3 & (!g3 U (g1 | g2)) & ((c1 & c2) U g3)`` is evaluated at t = 0
over random trajectories of the 13-dimensional state
``[x, y, theta, g1x, g1y, g2x, g2y, g3x, g3y, o1x, o1y, o2x, o2y]`` (T = 200 steps), with
``g_i = 0.5 - |(x, y) - (g_ix, g_iy)|``, ``c1 = x - y + 1.5`` and ``c2 = y - x + 1.5``.

Every tool does the whole job a Python user would have it do, per trajectory: tlshield takes
the raw trajectory; rtamt and argus get the five predicate signals computed with numpy and
turned into their own input objects inside the timed region. Parsing the formula and building
the monitor happens once, outside it, for every tool.

Semantics (closed window over s_0..s_T; ``a U b`` = max over t' >= t of
min(b(t'), min over t <= t'' < t' of a(t''))):

* rtamt (``StlDiscreteTimeOfflineSpecification``): its offline ``until`` is the backward
  recursion ``r(t) = max(b(t), min(a(t), r(t+1)))``, ``r(T+1) = -inf``, which is exactly the
  definition above; ``eventually`` is the suffix max. The formula is sent as it is.
* argus: its untimed ``U`` also demands ``a`` at the instant ``b`` is met
  (``r(t) = max(min(a(t), b(t)), min(a(t), r(t+1)))``), so each ``a U b`` is sent as
  ``(a | b) U b``, which is equal to the definition above for every real-valued signal
  (min/max only, so bit for bit). Signals use ``interpolation_method="constant"``: with the
  default linear interpolation argus adds zero-crossing points and its robustness is no
  longer the discrete-time one.

Before timing, all available tools (and the numpy reference below, the oracle) must agree
within 1e-9 on the first 200 trajectories, or the script stops with exit code 1. A tool that
cannot be imported is reported and its column left out.
"""

from __future__ import annotations

import argparse
import gc
import importlib.metadata
import json
import math
import os
import platform
import re
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from tlshield.envs.channel import STATE_DIM
from tlshield.envs.channel import TASK as FORMULA

HORIZON = 200  # T: a trajectory has T + 1 states
RADIUS = 0.5
HALF_WIDTH = 1.5
GOAL_DIMS = {"g1": (3, 4), "g2": (5, 6), "g3": (7, 8)}
N_CHECK = 200  # trajectories every tool must agree on before timing
N_TIMED = 50  # distinct trajectories the single-call timings cycle through
BATCH = 1000
TOLERANCE = 1e-9

# Ratios the tlshield columns are expected to reach.
TARGET_SINGLE = 50.0
TARGET_BATCH_VS_LOOP = 100.0
TARGET_BATCH_VS_SINGLE = 1.6

Formula = tuple
Monitor = Callable[[np.ndarray], float]


# --------------------------------------------------------------------------------------------
# Trajectories and predicates
# --------------------------------------------------------------------------------------------


def make_trajectories(rng: np.random.Generator, n: int, horizon: int = HORIZON) -> np.ndarray:
    """Noisy goal-seeking walks, shape (n, horizon + 1, 13), some satisfying the task.

    Each walker heads for g1 or g2 and then for g3; a quarter take the two the other way round
    (breaking ``!g3 U (g1 | g2)``), and random speed and noise leave some short of their goals
    or outside the channel.
    """
    goal1 = np.array([2.0, 3.0]) + rng.uniform(-0.4, 0.4, (n, 2))
    goal2 = np.array([3.0, 2.0]) + rng.uniform(-0.4, 0.4, (n, 2))
    goal3 = np.array([5.5, 5.5]) + rng.uniform(-0.8, 0.8, (n, 2))
    obst1 = np.array([1.0, 2.5]) + rng.uniform(-0.3, 0.3, (n, 2))
    obst2 = np.array([4.5, 3.0]) + rng.uniform(-0.3, 0.3, (n, 2))
    first = np.where((rng.random(n) < 0.5)[:, None], goal1, goal2)
    reverse = (rng.random(n) < 0.25)[:, None]
    waypoint_a = np.where(reverse, goal3, first)
    waypoint_b = np.where(reverse, first, goal3)
    reached_a = np.zeros(n, dtype=bool)
    speed = rng.uniform(0.03, 0.1, n)[:, None]
    noise = rng.uniform(0.0, 0.2, n)[:, None]

    trajs = np.empty((n, horizon + 1, STATE_DIM))
    trajs[:, :, 3:5] = goal1[:, None]
    trajs[:, :, 5:7] = goal2[:, None]
    trajs[:, :, 7:9] = goal3[:, None]
    trajs[:, :, 9:11] = obst1[:, None]
    trajs[:, :, 11:13] = obst2[:, None]
    pos = rng.normal(0.0, 0.2, (n, 2))
    for t in range(horizon + 1):
        target = np.where(reached_a[:, None], waypoint_b, waypoint_a)
        delta = target - pos
        reached_a |= np.hypot(delta[:, 0], delta[:, 1]) < 0.3
        theta = np.arctan2(delta[:, 1], delta[:, 0])
        trajs[:, t, 0:2] = pos
        trajs[:, t, 2] = theta
        step = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        pos = pos + speed * step + noise * rng.normal(size=(n, 2))
    return trajs


def predicate_signals(traj: np.ndarray) -> dict[str, np.ndarray]:
    """The five atom signals over time, shape traj.shape[:-1] (works on one or many)."""
    x = traj[..., 0]
    y = traj[..., 1]
    signals = {
        name: RADIUS - np.hypot(x - traj[..., cx], y - traj[..., cy])
        for name, (cx, cy) in GOAL_DIMS.items()
    }
    signals["c1"] = x - y + HALF_WIDTH
    signals["c2"] = y - x + HALF_WIDTH
    return signals


# --------------------------------------------------------------------------------------------
# A small formula parser (the tlshield grammar's subset used here) and the numpy reference
# --------------------------------------------------------------------------------------------

_TOKEN = re.compile(r"\s*(?:([a-z_][a-z0-9_]*)|([!&|()FU]))")


def parse(text: str) -> Formula:
    """Parse ``! F & | U ( )`` and atoms; loosest to tightest: ``|`` < ``&`` < ``U`` < prefix.

    Nodes are ("atom", name), ("not", a), ("F", a), ("and", a, b), ("or", a, b),
    ("until", a, b); ``U`` is right-associative, ``&`` and ``|`` left-associative.
    """
    tokens: list[str] = []
    at = 0
    while at < len(text.rstrip()):
        match = _TOKEN.match(text, at)
        if match is None:
            raise ValueError(f"bad formula at column {at}: {text!r}")
        tokens.append(match.group(1) or match.group(2))
        at = match.end()
    tokens.append("")
    pos = 0

    def take(expected: str | None = None) -> str:
        nonlocal pos
        tok = tokens[pos]
        if expected is not None and tok != expected:
            raise ValueError(f"expected {expected!r}, got {tok!r} in {text!r}")
        pos += 1
        return tok

    def binary(op: str, name: str, operand: Callable[[], Formula]) -> Formula:
        node = operand()
        while tokens[pos] == op:
            take()
            node = (name, node, operand())
        return node

    def disjunction() -> Formula:
        return binary("|", "or", conjunction)

    def conjunction() -> Formula:
        return binary("&", "and", until)

    def until() -> Formula:
        left = unary()
        if tokens[pos] == "U":
            take()
            return ("until", left, until())
        return left

    def unary() -> Formula:
        tok = take()
        if tok == "!":
            return ("not", unary())
        if tok == "F":
            return ("F", unary())
        if tok == "(":
            node = disjunction()
            take(")")
            return node
        if re.fullmatch(r"[a-z_][a-z0-9_]*", tok):
            return ("atom", tok)
        raise ValueError(f"unexpected {tok!r} in {text!r}")

    tree = disjunction()
    take("")
    return tree


def atom_names(f: Formula) -> list[str]:
    """Atom names in order of first appearance."""
    if f[0] == "atom":
        return [f[1]]
    return list(dict.fromkeys(name for sub in f[1:] for name in atom_names(sub)))


def reference_signal(f: Formula, signals: dict[str, np.ndarray]) -> np.ndarray:
    """Robustness at every t (last axis is time), by backward recursion; the agreement oracle."""
    op = f[0]
    if op == "atom":
        return signals[f[1]]
    if op == "not":
        return -reference_signal(f[1], signals)
    if op == "F":
        sub = reference_signal(f[1], signals)
        return np.flip(np.maximum.accumulate(np.flip(sub, -1), axis=-1), -1)
    left = reference_signal(f[1], signals)
    right = reference_signal(f[2], signals)
    if op == "and":
        return np.minimum(left, right)
    if op == "or":
        return np.maximum(left, right)
    if op == "until":
        out = np.empty(np.broadcast_shapes(left.shape, right.shape))
        nxt = np.full(out.shape[:-1], -np.inf)
        for t in range(out.shape[-1] - 1, -1, -1):
            nxt = np.maximum(right[..., t], np.minimum(left[..., t], nxt))
            out[..., t] = nxt
        return out
    raise ValueError(f"unknown operator {op!r}")


class Reference:
    """Pure-numpy robustness at t = 0, single or vectorised over a batch."""

    def __init__(self, formula: str) -> None:
        self.tree = parse(formula)

    def robustness(self, traj: np.ndarray) -> float:
        return float(reference_signal(self.tree, predicate_signals(traj))[0])

    def robustness_batch(self, trajs: np.ndarray) -> np.ndarray:
        return reference_signal(self.tree, predicate_signals(trajs))[:, 0]


# --------------------------------------------------------------------------------------------
# The tools
# --------------------------------------------------------------------------------------------


def to_rtamt(f: Formula) -> str:
    """rtamt STL text; its offline ``until`` already has the semantics wanted here."""
    op = f[0]
    if op == "atom":
        return f"({f[1]} > 0)"
    if op == "not":
        return f"(not {to_rtamt(f[1])})"
    if op == "F":
        return f"(eventually {to_rtamt(f[1])})"
    return f"({to_rtamt(f[1])} {op} {to_rtamt(f[2])})"


def rtamt_monitor(formula: str) -> Monitor:
    import rtamt

    tree = parse(formula)
    spec = rtamt.StlDiscreteTimeOfflineSpecification()
    for name in atom_names(tree):
        spec.declare_var(name, "float")
    spec.spec = to_rtamt(tree)
    spec.parse()
    time_stamps = list(range(HORIZON + 1))

    def robustness(traj: np.ndarray) -> float:
        dataset: dict[str, list[Any]] = {"time": time_stamps}
        for name, values in predicate_signals(traj).items():
            dataset[name] = values.tolist()
        return spec.evaluate(dataset)[0][1]

    return robustness


def to_argus(f: Formula) -> Any:
    """argus expression; ``a U b`` becomes ``(a | b) U b`` (argus demands ``a`` at t' too)."""
    import argus

    op = f[0]
    if op == "atom":
        return argus.VarFloat(f[1]) > argus.ConstFloat(0.0)
    if op == "not":
        return argus.Not(to_argus(f[1]))
    if op == "F":
        return argus.Eventually(to_argus(f[1]), interval=(None, None))
    left, right = to_argus(f[1]), to_argus(f[2])
    if op == "and":
        return argus.And([left, right])
    if op == "or":
        return argus.Or([left, right])
    if op == "until":
        return argus.Until(argus.Or([left, right]), right, interval=(None, None))
    raise ValueError(f"unknown operator {op!r}")


def argus_monitor(formula: str) -> Monitor:
    import argus

    expr = to_argus(parse(formula))
    time_stamps = [float(t) for t in range(HORIZON + 1)]
    signal = argus.FloatSignal.from_samples

    def robustness(traj: np.ndarray) -> float:
        trace = argus.Trace(
            {
                name: signal(
                    list(zip(time_stamps, values.tolist(), strict=True)),
                    interpolation_method="constant",
                )
                for name, values in predicate_signals(traj).items()
            }
        )
        rob = argus.eval_robust_semantics(expr, trace, interpolation_method="constant")
        return rob.at(0.0)

    return robustness


def tlshield_spec(formula: str) -> Any:
    import tlshield

    def halfspace(wx: float, wy: float) -> Any:
        w = [0.0] * STATE_DIM
        w[0], w[1] = wx, wy
        return tlshield.Halfspace(w=w, b=HALF_WIDTH)

    predicates = {
        name: tlshield.Ball(pos=[0, 1], radius=RADIUS, center_dims=list(dims))
        for name, dims in GOAL_DIMS.items()
    }
    predicates["c1"] = halfspace(1.0, -1.0)
    predicates["c2"] = halfspace(-1.0, 1.0)
    return tlshield.Spec(formula, predicates)


def package_version(dist: str) -> str | None:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return None


# --------------------------------------------------------------------------------------------
# Timing
# --------------------------------------------------------------------------------------------


def measure(
    call: Callable[[Any], object],
    items: Sequence[Any],
    budget: float,
    min_reps: int,
    max_reps: int = 10_000,
    min_block: float = 2e-3,
) -> tuple[float, int, int]:
    """Median seconds per call over blocks of calls cycling through ``items``.

    Blocks are sized to last at least ``min_block`` seconds and their count fits ``budget``
    (between ``min_reps`` and ``max_reps``). Returns (median, blocks, calls per block).
    """
    call(items[0])  # warm-up
    calls, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < min_block:
        call(items[calls % len(items)])
        calls += 1
    per_call = elapsed / calls
    inner = max(1, math.ceil(min_block / per_call))
    reps = int(min(max_reps, max(min_reps, budget / (inner * per_call))))
    blocks = [[items[(r * inner + k) % len(items)] for k in range(inner)] for r in range(reps)]
    samples = []
    gc.collect()
    gc.disable()
    try:
        for block in blocks:
            t0 = time.perf_counter()
            for item in block:
                call(item)
            samples.append((time.perf_counter() - t0) / inner)
    finally:
        gc.enable()
    return statistics.median(samples), reps, inner


# --------------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------------


class Tools:
    """The monitors that could be built: name -> robustness of one trajectory."""

    def __init__(self) -> None:
        self.single: dict[str, Monitor] = {}
        self.tlshield_batch: Callable[[np.ndarray], np.ndarray] | None = None
        self.skipped: dict[str, str] = {}
        self.versions = {"python": platform.python_version(), "numpy": np.__version__}

    @classmethod
    def load(cls, formula: str) -> Tools:
        tools = cls()
        builders: dict[str, Callable[[], Any]] = {
            "tlshield": lambda: tlshield_spec(formula),
            "rtamt": lambda: rtamt_monitor(formula),
            "argus": lambda: argus_monitor(formula),
        }
        for name, build in builders.items():
            try:
                built = build()
            except ImportError as err:
                tools.skipped[name] = f"{type(err).__name__}: {err}"
                print(f"note: {name} cannot be imported ({tools.skipped[name]}); column skipped")
                continue
            if name == "tlshield":
                tools.versions[name] = sys.modules["tlshield"].__version__
                tools.single[name] = built.robustness
                tools.tlshield_batch = built.robustness_batch
            else:
                dist = "argus-temporal-logic" if name == "argus" else name
                tools.versions[name] = package_version(dist)
                tools.single[name] = built
        tools.single["numpy-ref"] = Reference(formula).robustness
        return tools


def check_agreement(tools: Tools, trajs: np.ndarray, expected: np.ndarray) -> dict[str, float]:
    """Max |tool - reference| over ``trajs`` for every tool (and tlshield's batch call)."""
    diffs = {
        name: float(np.max(np.abs(np.array([fn(tr) for tr in trajs]) - expected)))
        for name, fn in tools.single.items()
    }
    if tools.tlshield_batch is not None:
        got = np.asarray(tools.tlshield_batch(trajs))
        diffs["tlshield batch"] = float(np.max(np.abs(got - expected)))
    return diffs


def time_batches(
    tools: Tools, reference: Reference, trajs: np.ndarray, budget: float, loop_reps: int
) -> tuple[dict[str, float], dict[str, dict[str, int]]]:
    """Median us per trajectory for a whole batch: batch calls, or Python loops of calls."""
    as_list = list(trajs)

    def loop(fn: Monitor) -> Callable[[object], object]:
        return lambda _: [fn(tr) for tr in as_list]

    plans: list[tuple[str, Callable[[object], object], float, int]] = []
    batch = tools.tlshield_batch
    if batch is not None:
        plans.append(("tlshield batch", lambda _: batch(trajs), budget, 5))
        plans.append(("tlshield loop", loop(tools.single["tlshield"]), budget, 3))
    for name in ("rtamt", "argus"):
        if name in tools.single:
            plans.append((f"{name} loop", loop(tools.single[name]), 0.0, loop_reps))
    plans.append(("numpy-ref batch", lambda _: reference.robustness_batch(trajs), budget, 3))
    per_traj: dict[str, float] = {}
    runs: dict[str, dict[str, int]] = {}
    for label, fn, plan_budget, min_reps in plans:
        median, reps, inner = measure(fn, [None], plan_budget, min_reps, max(min_reps, 200))
        per_traj[label] = median / len(trajs) * 1e6
        runs[label] = {"blocks": reps, "calls_per_block": inner}
    return per_traj, runs


def speedups(
    single_us: dict[str, float], batch_us: dict[str, float]
) -> list[tuple[str, float | None, float]]:
    """(label, tlshield speedup or None when a side is missing, target)."""

    def ratio(slow: float | None, fast: float | None) -> float | None:
        return None if slow is None or fast is None else slow / fast

    tls_single = single_us.get("tlshield")
    tls_batch = batch_us.get("tlshield batch")
    rows = [
        (f"single: tlshield vs {other}", ratio(single_us.get(other), tls_single), TARGET_SINGLE)
        for other in ("rtamt", "argus")
    ]
    rows += [
        (
            f"batch: tlshield batch vs looping {other}",
            ratio(batch_us.get(f"{other} loop"), tls_batch),
            TARGET_BATCH_VS_LOOP,
        )
        for other in ("rtamt", "argus")
    ]
    rows.append(
        (
            f"batch: tlshield batch vs {BATCH} single tlshield calls",
            ratio(batch_us.get("tlshield loop"), tls_batch),
            TARGET_BATCH_VS_SINGLE,
        )
    )
    return rows


def print_tables(
    single_us: dict[str, float],
    batch_us: dict[str, float],
    ratios: list[tuple[str, float | None, float]],
) -> None:
    def cell(value: float | None) -> str:
        return "-" if value is None else f"{value:,.2f}"

    columns = ["tlshield", "rtamt", "argus", "numpy-ref"]
    batch_row = [batch_us.get(f"{c} batch", batch_us.get(f"{c} loop")) for c in columns]
    print(
        f"\nMedian us per trajectory (T = {HORIZON}; {os.cpu_count()} cores, which tlshield's"
        " batch call may all use; everything else runs on one):\n"
    )
    print("| measurement | " + " | ".join(columns) + " |")
    print("|---|" + "---:|" * len(columns))
    print("| single trajectory | " + " | ".join(cell(single_us.get(c)) for c in columns) + " |")
    print(
        f"| batch of {BATCH} (tlshield, numpy-ref: one batch call; rtamt, argus: Python loop) | "
        + " | ".join(cell(v) for v in batch_row)
        + " |"
    )
    print(
        f"| {BATCH} single tlshield calls in a Python loop | "
        + cell(batch_us.get("tlshield loop"))
        + " | - | - | - |"
    )
    print("\n| tlshield speedup | value | target | |")
    print("|---|---:|---:|---|")
    for label, value, target in ratios:
        status = "n/a" if value is None else ("ok" if value >= target else "BELOW TARGET")
        shown = "-" if value is None else f"{value:,.1f}x"
        print(f"| {label} | {shown} | >= {target:g}x | {status} |")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="trajectory seed (default 0)")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    parser.add_argument("--json", metavar="PATH", help="also write the numbers to PATH")
    args = parser.parse_args(argv)
    budget = 0.6 if args.quick else 4.0  # seconds per measurement, roughly
    loop_reps = 1 if args.quick else 3  # rtamt and argus loops over the whole batch

    trajs = make_trajectories(np.random.default_rng(args.seed), BATCH)
    reference = Reference(FORMULA)
    tools = Tools.load(FORMULA)
    print(f"versions: {tools.versions}")

    # Agreement before any timing, against the numpy reference.
    expected = reference.robustness_batch(trajs[:N_CHECK])
    satisfied = float(np.mean(reference.robustness_batch(trajs) > 0))
    print(f"formula: {FORMULA}")
    print(
        f"{BATCH} trajectories of {HORIZON + 1} states, seed {args.seed}: {satisfied:.0%} satisfy;"
        f" robustness of the first {N_CHECK} in [{expected.min():.3f}, {expected.max():.3f}]"
    )
    diffs = check_agreement(tools, trajs[:N_CHECK], expected)
    for name, diff in diffs.items():
        print(f"max |{name} - reference| over {N_CHECK} trajectories: {diff:.3g}")
    bad = {name: diff for name, diff in diffs.items() if not diff <= TOLERANCE}
    if bad:
        print(f"ERROR: robustness disagrees beyond {TOLERANCE:g}: {bad}", file=sys.stderr)
        return 1

    single_us: dict[str, float] = {}
    runs: dict[str, dict[str, int]] = {}
    singles = list(trajs[:N_TIMED])
    for name, fn in tools.single.items():
        median, reps, inner = measure(fn, singles, budget, min_reps=5)
        single_us[name] = median * 1e6
        runs[f"single {name}"] = {"blocks": reps, "calls_per_block": inner}
    batch_us, batch_runs = time_batches(tools, reference, trajs, budget, loop_reps)
    runs.update(batch_runs)
    ratios = speedups(single_us, batch_us)
    print_tables(single_us, batch_us, ratios)
    for name, why in tools.skipped.items():
        print(f"\n{name} skipped: {why}")

    if args.json:
        report = {
            "formula": FORMULA,
            "horizon": HORIZON,
            "batch": BATCH,
            "seed": args.seed,
            "quick": args.quick,
            "cores": os.cpu_count(),
            "satisfied_fraction": satisfied,
            "max_abs_diff_vs_reference": diffs,
            "single_us": single_us,
            "batch_us_per_trajectory": batch_us,
            "speedups": {label: {"value": v, "target": t} for label, v, t in ratios},
            "runs": runs,
            "skipped": tools.skipped,
            "versions": tools.versions,
        }
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=2)
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
