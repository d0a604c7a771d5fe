"""Every bad path or file given to the command line gets one line, ``tlshield <cmd>: error:
<what, and where>``, and exit code 2, never a traceback (issue 20, point 4).

The subcommands come from the parser itself, so a new one without cases fails
:func:`test_every_subcommand_has_cases`. ``python -m tests.lab.test_cli_errors`` prints the table.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import zipfile
from collections.abc import Callable
from pathlib import Path

import pytest

from tlshield.lab import cli
from tlshield.lab.training import train

#: A bad input: what it is, and how to make the argv from a scratch folder and a real run.
Case = tuple[str, Callable[[Path, Path], list[str]]]


def _file(base: Path, name: str = "file.txt", content: bytes = b"x") -> Path:
    path = base / name
    path.write_bytes(content)
    return path


def _run_copy(run: Path, base: Path, edit: Callable[[Path], None]) -> str:
    folder = base / "copy"
    shutil.copytree(run, folder)
    edit(folder)
    return str(folder)


def _truncate(path: Path, keep: int = 100) -> None:
    path.write_bytes(path.read_bytes()[:keep])


UNDER_A_FILE = "under_a_file"


def _under_a_file(base: Path) -> str:
    """A path whose parent is a regular file: unwritable even for root."""
    return str(_file(base, UNDER_A_FILE) / "x")


CASES: dict[str, list[Case]] = {
    "demo": [("--steps below 2", lambda b, r: ["demo", "--steps", "1"])],
    "fsa": [
        ("--dot is a folder", lambda b, r: ["fsa", "F a", "--dot", str(b)]),
        ("--dot under a file", lambda b, r: ["fsa", "F a", "--dot", _under_a_file(b)]),
        ("--dot in a missing folder", lambda b, r: ["fsa", "F a", "--dot", str(b / "no/x.dot")]),
    ],
    "train": [
        ("--out is an existing file", lambda b, r: ["train", "--out", str(_file(b))]),
        ("--out under a file", lambda b, r: ["train", "--out", _under_a_file(b)]),
        ("--out in /proc", lambda b, r: ["train", "--out", "/proc/tlshield-run"]),
        ("--settings missing", lambda b, r: ["train", "--out", f"{b}/o", "--settings", "nope"]),
        ("--settings a folder", lambda b, r: ["train", "--out", f"{b}/o", "--settings", str(b)]),
        (
            "--settings corrupt JSON",
            lambda b, r: ["train", "--out", str(b / "o"), "--settings", str(_file(b, "s.json"))],
        ),
        (
            "--settings truncated JSON",
            lambda b, r: [
                "train",
                "--out",
                str(b / "o"),
                "--settings",
                str(_file(b, "t.json", b'{"settings": {"alpha": 3')),
            ],
        ),
    ],
    "evaluate": [
        ("missing folder", lambda b, r: ["evaluate", str(b / "nope")]),
        ("a file, not a folder", lambda b, r: ["evaluate", str(_file(b))]),
        ("a folder without a run", lambda b, r: ["evaluate", str(b)]),
        (
            "corrupt run.json",
            lambda b, r: ["evaluate", _run_copy(r, b, lambda f: _file(f, "run.json"))],
        ),
        (
            "truncated run.json",
            lambda b, r: ["evaluate", _run_copy(r, b, lambda f: _truncate(f / "run.json"))],
        ),
        (
            "corrupt model.zip",
            lambda b, r: ["evaluate", _run_copy(r, b, lambda f: _file(f, "model.zip"))],
        ),
        (
            "truncated model.zip",
            lambda b, r: ["evaluate", _run_copy(r, b, lambda f: _truncate(f / "model.zip", 2000))],
        ),
        (
            "model.zip is a folder",
            lambda b, r: [
                "evaluate",
                _run_copy(r, b, lambda f: ((f / "model.zip").unlink(), (f / "model.zip").mkdir())),
            ],
        ),
        (
            "model.zip without policy.pth",
            lambda b, r: [
                "evaluate",
                _run_copy(
                    r, b, lambda f: zipfile.ZipFile(f / "model.zip", "w").writestr("data", "{}")
                ),
            ],
        ),
        (
            "truncated normalization.json",
            lambda b, r: [
                "evaluate",
                _run_copy(r, b, lambda f: _truncate(f / "normalization.json", 20)),
            ],
        ),
    ],
    "reproduce": [
        ("--out is an existing file", lambda b, r: ["reproduce", "--out", str(_file(b))]),
        ("--out under a file", lambda b, r: ["reproduce", "--out", _under_a_file(b)]),
        ("--settings missing", lambda b, r: ["reproduce", "--out", str(b), "--settings", "nope"]),
    ],
    "ablation": [
        ("--out is an existing file", lambda b, r: ["ablation", "--out", str(_file(b))]),
        ("--out under a file", lambda b, r: ["ablation", "--out", _under_a_file(b)]),
    ],
    "tune": [
        ("--out is an existing file", lambda b, r: ["tune", "--out", str(_file(b))]),
        ("--out under a file", lambda b, r: ["tune", "--out", _under_a_file(b)]),
    ],
    "benchmark": [
        ("an unknown colour", lambda b, r: ["benchmark", "flatworld", "--formulas", "F purple"]),
        ("a negative seed", lambda b, r: ["benchmark", "flatworld", "--seeds", "-1"]),
        ("--envs for flatworld", lambda b, r: ["benchmark", "flatworld", "--envs", "X-v0"]),
        (
            "--formulas for safety-gym",
            lambda b, r: ["benchmark", "safety-gym", "--formulas", "F a"],
        ),
        ("an unknown env", lambda b, r: ["benchmark", "safety-gym", "--envs", "SafetyCarGoal2-v0"]),
    ],
    "plot": [
        ("missing folder", lambda b, r: ["plot", str(b / "nope")]),
        ("a file, not a folder", lambda b, r: ["plot", str(_file(b))]),
        ("a folder without runs", lambda b, r: ["plot", str(b)]),
        (
            "--out under a file",
            lambda b, r: ["plot", _run_copy(r, b, lambda f: None), "--out", _under_a_file(b)],
        ),
    ],
}


def subcommands() -> list[str]:
    parser = cli.build_parser()
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return sorted(actions[0].choices)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train("rl_cbf_clf", 0, 1, tmp_path_factory.mktemp("runs") / "r", progress=False)


def test_every_subcommand_has_cases() -> None:
    assert sorted(CASES) == subcommands()


PARAMS = [(cmd, what, make) for cmd, cases in CASES.items() for what, make in cases]


@pytest.mark.parametrize(
    ("command", "what", "make"), PARAMS, ids=[f"{c}: {w}" for c, w, _ in PARAMS]
)
def test_one_line_and_exit_2(
    command: str,
    what: str,
    make: Callable[[Path, Path], list[str]],
    run: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = make(tmp_path, run)
    code = cli.main(argv)  # an exception escaping here is the traceback a user would see
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, (argv, err)
    assert len(lines) == 1 and lines[0].startswith(f"tlshield {command}: error: "), err
    assert "Traceback" not in err


def test_a_subprocess_prints_no_traceback(tmp_path: Path) -> None:
    """The installed entry point behaves as ``main`` does in-process."""
    out = subprocess.run(
        [sys.executable, "-m", "tlshield", "fsa", "F a", "--dot", str(tmp_path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr.startswith("tlshield fsa: error: ") and "directory" in out.stderr


if __name__ == "__main__":
    import contextlib
    import io
    import tempfile

    base = Path(tempfile.mkdtemp())
    the_run = train("rl_cbf_clf", 0, 1, base / "run", progress=False)
    print("| command | bad input | exit | stderr |")
    print("|---|---|---:|---|")
    for command, what, make in PARAMS:
        scratch = Path(tempfile.mkdtemp())
        stderr = io.StringIO()
        with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(io.StringIO()):
            code = cli.main(make(scratch, the_run))
        line = stderr.getvalue().strip().replace(str(scratch), "DIR").replace(str(base), "DIR")
        print(f"| {command} | {what} | {code} | `{line}` |")


def test_a_run_folder_of_tlshield_0_1_still_loads(run: Path, tmp_path: Path) -> None:
    """0.1 wrote the record as ``config.json``; it is read where no ``run.json`` is."""
    from tlshield.lab.runs import RUN_FILE, load_run, read_record

    old = tmp_path / "old"
    shutil.copytree(run, old)
    (old / RUN_FILE).rename(old / "config.json")
    assert read_record(old) == read_record(run)
    loaded = load_run(old)
    assert loaded is not None and loaded.config == load_run(run).config  # type: ignore[union-attr]
