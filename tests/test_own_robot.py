"""The "your own robot" guide (docs/guides/own-robot.md), run: the bicycle room of
``examples/bicycle_room.py`` passes Gymnasium's env checker; the shield keeps its barriers
under attack (0 violating steps) where the same policies without it break them; the guide's
table is what the example prints; and the room trains and evaluates from the command line as
``module:Env-v0``, with violations measured by tlshield (the env reports none of its own)."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from tlshield.lab import measures

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
GUIDE = ROOT / "docs" / "guides" / "own-robot.md"


@pytest.fixture(scope="module")
def room() -> Any:
    sys.path.insert(0, str(EXAMPLES))
    try:
        import bicycle_room

        yield bicycle_room
    finally:
        sys.path.remove(str(EXAMPLES))


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped version")
def test_the_room_passes_gymnasiums_checker_in_every_configuration(room: Any) -> None:
    for config in room.CONFIGS:
        env = room.make_room(config)
        check_env(env.unwrapped, skip_render_check=True)
        check_env(env, skip_render_check=True)
    with pytest.raises(ValueError, match="config"):
        room.make_room("nope")


def test_the_shield_keeps_the_barriers_under_attack_and_the_guide_says_so(room: Any) -> None:
    table = {}
    for policy in ("attacker", "random"):
        for config in room.CONFIGS:
            table[policy, config] = room.attack(config, policy, 20)
    for policy in ("attacker", "random"):
        assert table[policy, "rl_cbf"]["violating steps"] == 0
        assert table[policy, "rl_cbf_clf"]["violating steps"] == 0
        assert table[policy, "rl"]["violating steps"] > 0  # the attack does attack
    # The guide's table is the example's output, number for number.
    shown = {"rl": "off", "rl_cbf": "CBF", "rl_cbf_clf": "CBF + CLF"}
    text = GUIDE.read_text()
    for (policy, config), got in table.items():
        row = (
            f"| {policy} | {shown[config]} | 20 | {got['violating steps']} "
            f"| {got['episodes with one']} | {got['successes']} |"
        )
        assert row in text, f"the guide lacks the measured row {row}"


def test_every_code_block_of_the_guide_is_the_examples_code(room: Any) -> None:
    """The guide quotes the example; a quote that drifted from it fails here."""
    source = (EXAMPLES / "bicycle_room.py").read_text()
    blocks = re.findall(r"```python\n(.*?)```", GUIDE.read_text(), flags=re.S)
    assert len(blocks) >= 4
    for block in blocks:
        for line in block.strip().splitlines():
            if line.strip() and not line.lstrip().startswith("#"):
                assert line.rstrip() in source, f"not in examples/bicycle_room.py: {line!r}"


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "tlshield", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )


def test_the_room_trains_and_evaluates_from_the_command_line(tmp_path: Path) -> None:
    run = tmp_path / "run"
    env = "bicycle_room:BicycleRoom-v0"
    done = _cli("train", "--env", env, "--updates", "1", "--out", str(run), "--quiet", cwd=EXAMPLES)
    assert done.returncode == 0, done.stderr[-3000:]
    record = json.loads((run / "run.json").read_text())
    assert record["env_id"] == env
    assert record["overrides"]["gamma"] == record["ppo"]["gamma"]  # the trainer's discount
    with (run / "metrics.csv").open() as f:
        row = next(csv.DictReader(f))
    assert float(row["violations"]) == 0.0  # measured from the barriers and the trap
    # The constraint columns are the env's own: this one reports no info["constraints"], so
    # there are none (no NaN columns under Channel-v0's names, as before issue 36).
    assert [c for c in row if c.startswith("min_h_")] == []
    done = _cli("evaluate", str(run), "--trials", "3", cwd=EXAMPLES)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "collisions not measured, violation steps 0" in done.stdout
    result = json.loads((run / "evaluation.json").read_text())
    assert result["collisions"] is None and result["violation_steps"] == 0
    # Elsewhere the module is not importable: one line, exit 2.
    done = _cli("evaluate", str(run), "--trials", "3", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1, done.stderr
    assert "no module named 'bicycle_room'" in done.stderr
    # --import makes a registered id available, and is recorded for evaluate.
    other = tmp_path / "other"
    done = _cli(
        "train", "--import", "bicycle_room", "--env", "BicycleRoom-v0", "--updates", "1",
        "--out", str(other), "--quiet", cwd=EXAMPLES,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    assert json.loads((other / "run.json").read_text())["imports"] == ["bicycle_room"]
    # The training environment's failures are one line and exit 2 as well, a factory that
    # does not take the trainer's keywords among them.
    (tmp_path / "badfactory.py").write_text(
        "import gymnasium as gym\n"
        "gym.register(id='Bad-v0', entry_point=lambda: gym.make('CartPole-v1'))\n"
    )
    for bad in ("nomodule:Env-v0", "NotRegistered-v0", "badfactory:Bad-v0"):
        done = _cli("train", "--env", bad, "--updates", "1", "--out", str(tmp_path / "x"),
                    "--quiet", cwd=tmp_path)  # fmt: skip
        assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr


def test_the_guides_command_works_from_the_console_script(tmp_path: Path) -> None:
    """The guide's command as written, with the ``tlshield`` console script (not ``python -m``,
    which puts the working folder on sys.path itself) and no PYTHONPATH: the module is found
    in the folder the command runs in."""
    script = Path(sys.executable).with_name("tlshield")
    assert script.exists(), f"no console script at {script}"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = tmp_path / "run"
    done = subprocess.run(
        [str(script), "train", "--env", "bicycle_room:BicycleRoom-v0", "--updates", "1",
         "--out", str(run), "--quiet"],
        cwd=EXAMPLES, env=env, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    assert json.loads((run / "run.json").read_text())["env_id"] == "bicycle_room:BicycleRoom-v0"


def test_what_cannot_be_measured_is_said_so_never_zero() -> None:
    assert measures.step_violation({}, False) is None
    assert measures.step_violation({"trap": False}, False) is False
    assert measures.step_violation({"trap": True}, False) is True
    assert measures.step_violation({"trap": True}, True) is False  # entered once, counted once
    assert measures.step_violation({"barriers": {"o": -0.1}, "trap": False}, False) is True
    assert measures.step_violation({"violation": False, "barriers": {"o": -1.0}}, False) is False
    assert measures.collision({}) is None
    assert measures.total([None, None]) is None and measures.total([None, 2, 1]) == 3
    assert measures.shown(None) == "not measured" and measures.shown(0) == "0"
    assert np.isfinite(measures.total([0]) or 0)
