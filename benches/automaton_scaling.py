"""How automaton construction scales with the number of atoms: tlshield against ltlf2dfa + MONA,
in one run, on formula shapes whose minimal automata stay small (issue 24).

Run from the repository root (ltlf2dfa needs Debian's ``mona``)::

    .venv/bin/python benches/automaton_scaling.py [--sizes 4 8 12 16 20 24] [--timeout 60]

Shapes, for n atoms ``a0 .. a(n-1)``:

* ``sequence``: ``F(a0 & F(a1 & ... & F a(n-1)))`` (n + 1 states);
* ``until chain``: ``a0 U (a1 U (... U a(n-1)))`` (n + 1 states);
* ``two sequences``: the sequence over the first half of the atoms, or over the second half;
* and FlatWorld's five published formulas (DeepLTL's benchmark, 3-6 colours each).

Each build runs in its own child process (a fresh interpreter: no cache is shared) with a time
limit, and reports its time (imports excluded), its peak RSS and, for tlshield, the nodes of the
decision diagrams that hold its transitions. tlshield:
``Automaton.from_formula``; MONA: ltlf2dfa's ``to_dfa(mona_dfa_out=True)`` (MONA's raw DFA, no
sympy; MONA's count includes the extra state of its WS1S encoding). A build that runs out of
time, or that a tool refuses, is reported as such. No target
is asserted here: the numbers go to docs/benchmarks.md (issue 24's targets: <= 1 s at every n
and >= 10x MONA wherever MONA finishes).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

PYTHON_PATH = str(Path(__file__).resolve().parent.parent / "python")


def sequence(atoms: Sequence[str]) -> str:
    return "F(" + " & F(".join(atoms) + ")" * len(atoms)


def until_chain(atoms: Sequence[str]) -> str:
    return " U (".join(atoms) + ")" * (len(atoms) - 1)


def two_sequences(atoms: Sequence[str]) -> str:
    half = len(atoms) // 2
    return f"({sequence(atoms[:half])}) | ({sequence(atoms[half:])})"


SHAPES: dict[str, Callable[[Sequence[str]], str]] = {
    "sequence": sequence,
    "until chain": until_chain,
    "two sequences": two_sequences,
}

CHILD = {
    "tlshield": """
import json, resource, sys, time
import tlshield
start = time.perf_counter()
try:
    aut = tlshield.Automaton.from_formula(sys.argv[1])
    out = {"seconds": time.perf_counter() - start, "states": aut.num_states,
           "nodes": aut.diagram_nodes}
except tlshield.AutomatonError as err:
    out = {"refused": str(err)}
out["rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps(out))
""",
    "ltlf2dfa + MONA": """
import json, re, resource, sys, time
from ltlf2dfa.parser.ltlf import LTLfParser
formula = LTLfParser()(sys.argv[1])
start = time.perf_counter()
dfa = formula.to_dfa(mona_dfa_out=True)
seconds = time.perf_counter() - start
found = re.search(r"Automaton has (\\d+) states", dfa) if isinstance(dfa, str) else None
out = {"seconds": seconds, "states": int(found.group(1))} if found else {
    "refused": "MONA gave no automaton"
}
children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
out["rss_mb"] = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, children)
print(json.dumps(out))
""",
}


def run(tool: str, formula: str, timeout: float) -> dict:
    env = {**os.environ, "PYTHONPATH": PYTHON_PATH + os.pathsep + os.environ.get("PYTHONPATH", "")}
    try:
        done = subprocess.run(
            [sys.executable, "-c", CHILD[tool], formula],
            capture_output=True,
            text=True,
            timeout=timeout,
            env=env,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return {"timeout": timeout}
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["?"])[-1]
        return {"refused": f"failed: {last}"}
    return json.loads(done.stdout.strip().splitlines()[-1])


def cell(result: dict) -> str:
    if "timeout" in result:
        return f"> {result['timeout']:g} s (stopped)"
    if "refused" in result:
        text = result["refused"]
        return "refused: " + (text if len(text) < 90 else text[:87] + "...")
    states = f", {result['states']} states" if "states" in result else ""
    nodes = f", {result['nodes']} nodes" if "nodes" in result else ""
    return f"{result['seconds']:.3g} s{states}{nodes}, {result['rss_mb']:.0f} MB"


def speedup(results: Sequence[dict]) -> str:
    """tlshield's build time over MONA's, when both built."""
    if len(results) < 2 or not all("seconds" in r for r in results):
        return "-"
    return f"{results[1]['seconds'] / results[0]['seconds']:,.0f}x"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[4, 8, 12, 16, 20, 24])
    parser.add_argument("--timeout", type=float, default=60.0, help="per build, seconds")
    parser.add_argument("--shapes", nargs="+", choices=sorted(SHAPES), default=list(SHAPES))
    parser.add_argument("--no-flatworld", action="store_true", help="leave FlatWorld's out")
    args = parser.parse_args(argv)
    tools = ["tlshield"]
    try:
        import ltlf2dfa  # noqa: F401

        if shutil.which("mona"):
            tools.append("ltlf2dfa + MONA")
        else:
            print("mona is not on PATH (Debian package `mona`): its column is left out\n")
    except ImportError:
        print("ltlf2dfa is not installed (the `bench` extra): its column is left out\n")
    print("| shape | atoms | " + " | ".join(tools) + " | MONA / tlshield |")
    print("|---|---:|" + "---|" * len(tools) + "---:|")
    rows: list[tuple[str, int, str]] = [
        (shape, n, SHAPES[shape]([f"a{i}" for i in range(n)]))
        for shape in args.shapes
        for n in args.sizes
    ]
    if not args.no_flatworld:
        from tlshield.envs.flatworld import FORMULAS

        for k, formula in enumerate(FORMULAS, start=1):
            atoms = len(set(re.findall(r"[a-z_][a-z0-9_]*", formula)))
            rows.append((f"FlatWorld F{k}", atoms, formula))
    for shape, n, formula in rows:
        results = [run(tool, formula, args.timeout) for tool in tools]
        cells = [cell(r) for r in results]
        print(f"| {shape} | {n} | " + " | ".join(cells) + f" | {speedup(results)} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
