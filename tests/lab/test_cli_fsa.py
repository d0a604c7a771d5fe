"""``tlshield fsa``: the task automaton printed and drawn from the command line, and the command
line's errors on a bad formula, a bad command and a bad setting."""

from __future__ import annotations

import pytest

from tlshield.lab.cli import main


def test_cli_fsa(capsys: pytest.CaptureFixture[str], tmp_path) -> None:
    dot = tmp_path / "task.dot"
    assert main(["fsa", "--dot", str(dot)]) == 0
    out = capsys.readouterr().out
    assert "q1 (trap)" in out and "q2 (accepting)" in out
    assert "(g3 | c1) & (g3 | c2) & (g1 | g2 | !g3)" in out
    assert dot.read_text().startswith("digraph fsa")
    assert main(["fsa", "F a & X b"]) == 0


def test_cli_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fsa", "G a"]) == 2
    assert "`G` (always) is not allowed" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    with pytest.raises(SystemExit) as info:
        main(["nonsense"])
    assert info.value.code == 2
    assert main(["demo", "--steps", "1"]) == 2
