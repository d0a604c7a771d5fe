"""The spellings of tlshield 0.1 (CHANGELOG.md, 0.2.0), removed in 0.3: renamed parameters are
errors that name the new spelling, renamed classes and module names are gone; a swapped
argument order fails with a hint (``test_automaton``); a record written by 0.1 still loads
(``tests/lab/test_cli_errors``)."""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import gymnasium as gym
import pytest

from tlshield.envs import ENV_ID, FLATWORLD_ID, POINT_MASS_ID
from tlshield.envs.params import as_flat
from tlshield.lab import settings
from tlshield.lab.runs import Run


@pytest.mark.parametrize("env_id", [ENV_ID, POINT_MASS_ID, FLATWORLD_ID])
def test_renamed_parameters_are_errors_that_name_the_new_one(env_id: str) -> None:
    """0.3 removed the 0.1 spellings: each is a TypeError naming its new spelling, ``env.cfg``
    is gone."""
    with pytest.raises(TypeError, match="'K' is now called 'k'"):
        gym.make(env_id, K=123.0)
    with pytest.raises(TypeError, match="'cbf_margin' is now called 'margin'"):
        gym.make(env_id, cbf_margin=0.05)
    env = gym.make(env_id, k=123.0)
    assert as_flat(env.unwrapped.params)["k"] == 123.0
    assert not hasattr(env.unwrapped, "cfg")


@pytest.mark.parametrize(
    ("module", "old"),
    [
        ("tlshield.envs", "ChannelConfig"),
        ("tlshield.envs.channel", "ChannelConfig"),
        ("tlshield.envs.point_mass", "PointMassConfig"),
        ("tlshield.envs.flatworld", "FlatWorldConfig"),
    ],
)
def test_renamed_classes_are_gone(module: str, old: str) -> None:
    with pytest.raises(AttributeError, match=old):
        getattr(importlib.import_module(module), old)


def test_settings_refuse_the_old_names_and_files_still_read(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="--set: 'K' is now called 'k'"):
        settings.parse_assignments(["K=100"])
    with pytest.raises(TypeError, match="'cbf_margin' is now called 'margin'"):
        settings.split({"cbf_margin": 0.01})
    old_file = tmp_path / "settings.json"
    old_file.write_text(json.dumps({"K": 100.0}))  # written by 0.1: data, still read
    assert settings.load(old_file)[0] == {"k": 100.0}


def test_a_0_1_record_reads_its_old_names_silently(recwarn: pytest.WarningsRecorder) -> None:
    run = Run.__new__(Run)
    object.__setattr__(run, "record", {"env": {"K": 55.0, "cbf_margin": 0.002}})
    assert (run.env.shield.k, run.env.shield.margin) == (55.0, 0.002)
    assert not [w for w in recwarn if issubclass(w.category, DeprecationWarning)]


def test_the_monitor_overloads_are_gone() -> None:
    """``filter(monitor, a_rl)`` and ``filter_batch(monitors, a_rl)`` (0.2's overloads by
    argument type, deprecated) were removed in 0.3: ``a_rl`` is required, and a monitor where
    the state goes is a TypeError naming the method that takes it."""
    import numpy as np

    import tlshield
    from tests.fixtures import task_shield

    shield = task_shield()
    monitor = tlshield.Monitor(shield.automaton)
    monitor.reset(np.zeros(13))
    with pytest.raises(TypeError, match="a_rl"):
        shield.filter(monitor, np.array([1.0, -2.0]))  # type: ignore[call-arg]
    batch = tlshield.MonitorBatch(shield.automaton, 2)
    batch.reset(np.zeros((2, 13)))
    with pytest.raises(TypeError, match="a_rl"):
        shield.filter_batch(batch, np.zeros((2, 2)))  # type: ignore[call-arg]
    with pytest.raises(TypeError, match="use filter_monitors"):
        shield.filter_batch(batch, np.zeros(2, dtype=int), np.zeros((2, 2)))


@pytest.mark.parametrize("old", ["training", "plots", "plots.curves", "cli", "benchmark"])
def test_the_0_1_module_names_are_gone(old: str) -> None:
    """0.3 removed the lab modules' 0.1 names and the import finder that answered for them:
    ``import tlshield`` puts nothing of its own on ``sys.meta_path``, and an old name is a
    plain ModuleNotFoundError (the module lives under ``tlshield.lab``)."""
    import tlshield

    finders = [f for f in sys.meta_path if type(f).__module__.startswith("tlshield")]
    assert finders == [], finders
    assert "tlshield._moved" not in sys.modules
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(f"tlshield.{old}")
    assert importlib.import_module(f"tlshield.lab.{old}").__name__ == f"tlshield.lab.{old}"
    assert tlshield.__name__ == "tlshield"


def test_every_deprecation_names_its_removal_and_is_in_the_changelog() -> None:
    """The inventory of what warns: every place in the library that emits a deprecation
    (Python ``DeprecationWarning``, a stub's ``@deprecated``, Rust ``#[deprecated]``) says in
    which version the name goes, and the CHANGELOG's unreleased section lists deprecations
    exactly when the sources have some (0.3 removed every 0.1 name; 0.4 deprecates the "!" name
    of a bare barrier)."""
    import re

    root = Path(__file__).resolve().parent.parent
    sources = [*(root / "python" / "tlshield").rglob("*.py")]
    sources += [*(root / "python" / "tlshield").rglob("*.pyi")]
    sources += [*(root / "rust").rglob("src/**/*.rs")]
    pattern = re.compile(r"DeprecationWarning|@deprecated\(|#\[deprecated")
    sites = []
    for path in sources:
        lines = path.read_text().splitlines()
        for i, line in enumerate(lines):
            if pattern.search(line) and not line.lstrip().startswith(("//", "#:", "# ")):
                context = " ".join(lines[max(0, i - 3) : i + 4])
                sites.append((f"{path.relative_to(root)}:{i + 1}", context))
    for where, context in sites:
        assert re.search(r"removed in \d+\.\d+|since = ", context), f"{where}: no removal version"
    changelog = (root / "CHANGELOG.md").read_text()
    unreleased = changelog.split("## [Unreleased]", 1)[1].split("\n## [", 1)[0]
    listed = "### Deprecated" in unreleased
    assert listed == bool(sites), (listed, [w for w, _ in sites])
