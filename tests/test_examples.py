"""The shipped examples run end to end on a tiny budget (their numbers belong in the README)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.mark.parametrize(
    "flags",
    [(), ("--model", "body", "--alpha", "0.5", "--clf", "--line-up")],
    ids=["default", "line_up"],
)
def test_highway_parking_example_runs(flags: tuple[str, ...]) -> None:
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / "highway_parking.py"), "--steps", "150", *flags],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    rows = [line for line in done.stdout.splitlines() if line.startswith(("| off", "| on"))]
    assert len(rows) == 2, done.stdout
    # With the shield on, the shield never failed to return an action.
    assert rows[1].split("|")[7].strip() == "0"
    if flags:  # the body shield: no crash
        assert rows[1].split("|")[4].strip() == "0 (0)", done.stdout


def test_the_readme_example_is_the_shipped_one_and_does_the_task() -> None:
    """The README's loop is ``examples/own_loop.py`` word for word, and the robot it shields
    (a random policy, the CLF pulling towards the goals) finishes the task without entering
    the trap."""
    readme = (EXAMPLES.parent / "README.md").read_text()
    block = readme.split("\n## Example", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    assert block == (EXAMPLES / "own_loop.py").read_text()
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / "own_loop.py")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().endswith("accepted=True, trapped=False"), done.stdout
