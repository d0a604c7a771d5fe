"""What ``import tlshield`` costs a user who only wants the shield: wall time and peak resident
memory of a fresh interpreter running it, against the same interpreter also loading the training
stack (what every ``import tlshield`` cost while ``tlshield.wrappers`` imported SB3 at module
level), measured in the same run, alternating. Usage: ``python benches/import_cost.py [--runs N]``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time

PROBE = """
import json, resource, sys, time
t = time.perf_counter()
{code}
dt = time.perf_counter() - t
heavy = ("torch", "stable_baselines3", "ray", "matplotlib", "optuna")
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({{"import_s": dt, "rss_mib": rss,
                  "heavy": sorted(m for m in heavy if m in sys.modules)}}))
"""
CASES = {
    "import tlshield": "import tlshield",
    "import tlshield + the training stack (SB3, torch)": (
        "import tlshield\nfrom tlshield.wrappers import ShieldedVecEnv"
    ),
}


def measure(code: str) -> dict[str, object]:
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(code=code)], check=True, capture_output=True, text=True
    ).stdout
    result = json.loads(out.splitlines()[-1])
    result["process_s"] = time.perf_counter() - t0
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args(argv)
    results: dict[str, list[dict[str, object]]] = {name: [] for name in CASES}
    for code in CASES.values():
        measure(code)  # warm the file cache
    for _ in range(args.runs):
        for name, code in CASES.items():
            results[name].append(measure(code))
    print("| what | import (s) | whole process (s) | peak RSS (MiB) | training stack loaded |")
    print("|---|---:|---:|---:|---|")
    medians = {}
    for name, rows in results.items():
        med = {k: statistics.median(float(r[k]) for r in rows) for k in ("import_s", "process_s")}
        rss = statistics.median(float(r["rss_mib"]) for r in rows)
        medians[name] = (med["import_s"], rss)
        heavy = ", ".join(rows[0]["heavy"]) or "none"  # type: ignore[arg-type]
        print(
            f"| `{name}` | {med['import_s']:.3f} | {med['process_s']:.3f} | {rss:.0f} | {heavy} |"
        )
    (lite_s, lite_rss), (full_s, full_rss) = medians.values()
    print(
        f"\n`import tlshield` alone: {full_s / lite_s:.1f}x faster and {full_rss / lite_rss:.1f}x "
        f"less memory than with the training stack (medians of {args.runs} runs, same run)."
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
