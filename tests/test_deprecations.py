"""The spellings of tlshield 0.1 (CHANGELOG.md, 0.2.0): renamed parameters and classes still
work with a DeprecationWarning; a swapped argument order fails with a hint
(``test_automaton``); a record written by 0.1 still loads (``test_cli_errors``)."""

from __future__ import annotations

import importlib
import sys

import gymnasium as gym
import pytest

import tlshield.envs
from tlshield.envs import ENV_ID, FLATWORLD_ID, POINT_MASS_ID
from tlshield.envs.params import as_flat
from tlshield.lab import settings
from tlshield.lab.runs import Run


@pytest.mark.parametrize("env_id", [ENV_ID, POINT_MASS_ID, FLATWORLD_ID])
def test_renamed_parameters_warn_and_still_apply(env_id: str) -> None:
    with pytest.warns(DeprecationWarning, match="'K' is now called 'k'"):
        env = gym.make(env_id, K=123.0)
    assert as_flat(env.unwrapped.params)["k"] == 123.0
    with pytest.warns(DeprecationWarning, match="'cbf_margin' is now called 'margin'"):
        env = gym.make(env_id, cbf_margin=0.05)
    assert as_flat(env.unwrapped.params)["margin"] == 0.05
    with pytest.warns(DeprecationWarning, match="env.cfg is deprecated: use env.params"):
        assert env.unwrapped.cfg is env.unwrapped.params
    with pytest.raises(TypeError, match="'K' and 'k' given"):
        gym.make(env_id, K=1.0, k=2.0)


@pytest.mark.parametrize(
    ("module", "old", "new"),
    [
        ("tlshield.envs", "ChannelConfig", "ChannelParams"),
        ("tlshield.envs.channel", "ChannelConfig", "ChannelParams"),
        ("tlshield.envs.point_mass", "PointMassConfig", "PointMassParams"),
        ("tlshield.envs.flatworld", "FlatWorldConfig", "FlatWorldParams"),
    ],
)
def test_renamed_classes_warn_and_are_the_new_ones(module: str, old: str, new: str) -> None:
    mod = importlib.import_module(module)
    with pytest.warns(DeprecationWarning, match=f"{old} is now called {new}"):
        cls = getattr(mod, old)
    assert cls is getattr(mod, new)
    with pytest.raises(AttributeError, match="NoSuchConfig"):
        tlshield.envs.NoSuchConfig  # noqa: B018


def test_settings_accept_the_old_names_with_a_warning() -> None:
    with pytest.warns(DeprecationWarning, match="--set: 'K' is now called 'k'"):
        assert settings.parse_assignments(["K=100"]) == {"k": 100}
    with pytest.warns(DeprecationWarning):
        assert settings.split({"cbf_margin": 0.01})["margin"] == 0.01


def test_a_0_1_record_reads_its_old_names_silently(recwarn: pytest.WarningsRecorder) -> None:
    run = Run.__new__(Run)
    object.__setattr__(run, "record", {"env": {"K": 55.0, "cbf_margin": 0.002}})
    assert (run.env.shield.k, run.env.shield.margin) == (55.0, 0.002)
    assert not [w for w in recwarn if issubclass(w.category, DeprecationWarning)]


def test_monitor_overloads_warn_and_equal_the_named_methods() -> None:
    """``filter(monitor, a_rl)`` and ``filter_batch(monitors, a_rl)`` (0.2's overloads by
    argument type) warn and give what ``filter_monitor`` and ``filter_monitors`` give."""
    import numpy as np

    import tlshield
    from tests.fixtures import task_shield

    shield = task_shield()
    s = np.zeros(13)
    s[3:9] = [4.0, 4.0, 4.5, 6.5, 9.0, 9.0]
    monitor = tlshield.Monitor(shield.automaton)
    monitor.reset(s)
    a_rl = np.array([1.0, -2.0])
    with pytest.warns(DeprecationWarning, match="use Shield.filter_monitor"):
        old = shield.filter(monitor, a_rl)
    assert old.action.tolist() == shield.filter_monitor(monitor, a_rl).action.tolist()
    batch = tlshield.MonitorBatch(shield.automaton, 2)
    batch.reset(np.stack([s, s]))
    actions = np.stack([a_rl, -a_rl])
    with pytest.warns(DeprecationWarning, match="use Shield.filter_monitors"):
        old_batch = shield.filter_batch(batch, actions)
    new_batch = shield.filter_monitors(batch, actions)
    assert old_batch.action.tolist() == new_batch.action.tolist()


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
