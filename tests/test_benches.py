"""Every benchmark script runs end to end on a tiny budget (its own correctness checks
included), so a change that breaks a benchmark fails here, not when the README is regenerated.
No timing is asserted: the scripts exit 1 when a correctness check fails and 2 when a speed
target is missed, and only the first fails a test (speed belongs in the README, measured on a
quiet machine)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BENCHES = Path(__file__).resolve().parent.parent / "benches"


@pytest.mark.parametrize(
    ("script", "args", "expected"),
    [
        ("compare_robustness.py", ["--quick"], "tlshield speedup"),
        ("compare_automaton.py", ["--quick"], "tlshield speedup"),
        ("automaton_scaling.py", ["--sizes", "4", "6", "--timeout", "120"], "| FlatWorld F5 |"),
        ("compare_shield.py", ["--quick", "--memory-calls", "2000"], "tlshield speedup"),
        ("compare_routing.py", ["--quick", "--steps", "100"], "routed / unrouted median"),
        ("env_speed.py", ["--quick"], "ShieldedVecEnv"),
        ("step_crossings.py", ["--steps", "1000"], "| rl_cbf_clf | 1.00 |"),
        ("import_cost.py", ["--runs", "1"], "| `import tlshield` |"),
        ("moving_obstacles.py", ["--steps", "2000"], "moving-obstacle barrier"),
        ("compare_cbfpy.py", ["--quick"], "tlshield speedup"),
        ("compare_grad.py", ["--quick"], "| 8 |"),
        ("batch_rows.py", ["--quick", "--rows", "64"], "targets met"),
        ("ray_overhead.py", ["--quick"], "runs identical: yes"),
        ("ray_scaling.py", ["--quick"], "runs identical at every size: yes"),
        ("safety_gym_overhead.py", ["--rounds", "1", "--steps", "100"], "shield overhead"),
        (
            "safety_gym_overhead.py",
            ["--rounds", "1", "--steps", "100", "--sensing", "lidar"],
            "sensing=lidar: whole step",
        ),
    ],
)
def test_benchmark_runs(script: str, args: list[str], expected: str) -> None:
    done = subprocess.run(
        [sys.executable, str(BENCHES / script), *args],
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    assert done.returncode in (0, 2), done.stdout[-2000:] + done.stderr[-4000:]
    assert expected in done.stdout
