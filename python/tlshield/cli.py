"""The ``tlshield`` command line."""

from __future__ import annotations

import argparse
import itertools
import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tlshield._core import Halfspace, Spec, SpecError, formula_atoms
from tlshield.envs.channel import STATE_DIM, TASK, channel_task_spec


def _straight_path(waypoints: Sequence[tuple[float, float]], steps_per_leg: int) -> np.ndarray:
    points = [np.asarray(waypoints[0], dtype=float)]
    for a, b in itertools.pairwise(waypoints):
        for k in range(1, steps_per_leg + 1):
            points.append(np.asarray(a) + (np.asarray(b) - np.asarray(a)) * k / steps_per_leg)
    return np.array(points)


def _demo(args: argparse.Namespace) -> int:
    if args.steps < 2:
        print("tlshield demo: error: --steps must be at least 2", file=sys.stderr)
        return 2
    spec = channel_task_spec(half_width=args.half_width, goal_radius=args.goal_radius)
    goals = np.array([[1.0, 2.0], [3.0, 1.0], [5.0, 5.2]])
    obstacles = np.array([[1.0, 3.0], [4.0, 2.0]])
    scene = np.concatenate([goals.ravel(), obstacles.ravel()])

    def trajectory(waypoints: Sequence[tuple[float, float]]) -> np.ndarray:
        xy = _straight_path(waypoints, steps_per_leg=args.steps // (len(waypoints) - 1))
        traj = np.zeros((len(xy), STATE_DIM))
        traj[:, :2] = xy
        traj[:, 3:] = scene
        return traj

    cases = {
        "g1 then g3, inside the channel": trajectory([(0.0, 0.0), (1.0, 2.0), (5.0, 5.2)]),
        "g3 first (violates !g3 U (g1|g2))": trajectory([(0.0, 0.0), (5.0, 5.2), (1.0, 2.0)]),
        "leaves the channel on the way": trajectory([(0.0, 0.0), (2.5, 0.0), (1.0, 2.0), (5, 5.2)]),
        "never reaches a goal": trajectory([(0.0, 0.0), (1.0, 1.0)]),
    }
    print(f"task: {spec}")
    print(f"atoms: {', '.join(spec.atoms)}")
    print(f"{'trajectory':<40} {'steps':>6} {'robustness':>11} satisfied")
    for name, traj in cases.items():
        rho = spec.robustness(traj)
        print(f"{name:<40} {len(traj) - 1:>6} {rho:>11.4f} {spec.satisfied(traj)}")
    batch = np.stack([cases["g1 then g3, inside the channel"]] * 4)
    print(f"batch of {len(batch)}: {spec.robustness_batch(batch)}")
    return 0


def _fsa(args: argparse.Namespace) -> int:
    try:
        atoms = formula_atoms(args.formula)
    except SpecError as err:
        print(f"tlshield fsa: {err}", file=sys.stderr)
        return 2
    # The automaton depends only on the formula; the predicates are placeholders.
    placeholder = Halfspace([1.0], 0.0)
    aut = Spec(args.formula, dict.fromkeys(atoms, placeholder)).automaton()
    roles = {aut.initial: "initial"}
    for q in aut.accepting:
        roles[q] = "accepting"
    if aut.trap is not None:
        roles[aut.trap] = "trap"
    print(f"formula: {aut.spec}")
    print(f"atoms:   {', '.join(aut.atoms)}")
    print(f"states:  {aut.num_states}")
    for q in range(aut.num_states):
        tags = [roles[q]] if q in roles else []
        if aut.initial == q and roles.get(q) != "initial":
            tags.insert(0, "initial")
        print(f"  q{q}{' (' + ', '.join(tags) + ')' if tags else ''}")
        for src, dst, guard in aut.edges():
            if src == q:
                print(f"    -> q{dst}: {guard}")
        clauses = aut.trap_cnf(q)
        if clauses:
            text = " & ".join(
                "(" + " | ".join(("" if pos else "!") + a for a, pos in clause) + ")"
                for clause in clauses
            )
            print(f"    safe set (CNF of the negated trap guard): {text}")
    if args.dot or args.png:
        dot = aut.to_dot()
        if args.dot:
            Path(args.dot).write_text(dot)
            print(f"wrote {args.dot}")
        if args.png:
            graphviz = shutil.which("dot")
            if graphviz is None:
                print(
                    "tlshield fsa: graphviz `dot` not found; install graphviz for --png",
                    file=sys.stderr,
                )
                return 1
            subprocess.run([graphviz, "-Tpng", "-o", args.png], input=dot, text=True, check=True)
            print(f"wrote {args.png}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``tlshield`` command."""
    parser = argparse.ArgumentParser(
        prog="tlshield",
        description="Temporal-logic guided safe reinforcement learning with CBF shields.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="robustness of the paper's task on sample trajectories")
    demo.add_argument("--steps", type=int, default=200, help="trajectory length T (default 200)")
    demo.add_argument("--half-width", type=float, default=1.5, help="channel half-width w")
    demo.add_argument("--goal-radius", type=float, default=0.5, help="goal radius")
    demo.set_defaults(handler=_demo)

    fsa = sub.add_parser("fsa", help="print the automaton of a formula (states, guards, safe sets)")
    fsa.add_argument(
        "formula", nargs="?", default=TASK, help="scTLTL formula (default: the paper's task)"
    )
    fsa.add_argument("--dot", metavar="PATH", help="write Graphviz DOT text to PATH")
    fsa.add_argument("--png", metavar="PATH", help="render a PNG to PATH (needs graphviz)")
    fsa.set_defaults(handler=_fsa)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tlshield`` and ``python -m tlshield``."""
    args = build_parser().parse_args(argv)
    return int(args.handler(args))
