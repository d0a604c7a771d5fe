"""What an env is, said once in its registration (:mod:`tlshield.envs.profile`): the bundled
envs' profiles, a user's env declaring one, the lab reading it (never an env id), and the
0.4 removals refused with a message naming the replacement."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import tlshield
from tlshield.envs import ENV_ID, FLATWORLD_ID, POINT_MASS_ID, SAFETY_GYM_IDS, ChannelParams
from tlshield.envs.profile import DEFAULT, EnvProfile, profile_of, register
from tlshield.lab.evaluation import Recorder, rollouts

LAB = Path(tlshield.__file__).parent / "lab"


def test_the_bundled_envs_declare_their_profiles() -> None:
    channel = profile_of(ENV_ID)
    assert channel.params_class() is ChannelParams and not channel.scored_by_return
    assert channel.recorder and channel.clf_shield and "paper" in channel.preset_overrides
    assert profile_of(f"tlshield.envs:{ENV_ID}") is channel  # "module:Env-v0" reads Env-v0's
    assert profile_of(FLATWORLD_ID).task_keywords == ("formula",)
    assert profile_of(POINT_MASS_ID).params_class().__name__ == "PointMassParams"
    for env_id in SAFETY_GYM_IDS:
        assert profile_of(env_id).scored_by_return and profile_of(env_id).params is None
    assert profile_of("NoSuchEnv-v9") is DEFAULT


class _GoalOnce(gym.Env[np.ndarray, np.ndarray]):
    """A user's env that meets its goal at step 2 and goes on (as Safety-Gymnasium's goal
    moves): ``info["success"]`` is true on that step only."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (2,))
    action_space = gym.spaces.Box(-1.0, 1.0, (2,))

    def __init__(self, config: str = "rl", evaluation: bool = False) -> None:
        self.t = 0

    def reset(self, *, seed: int | None = None, options: Any = None) -> Any:
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(2, dtype=np.float32), {}

    def step(self, action: np.ndarray) -> Any:
        self.t += 1
        info = {"success": self.t == 2, "task_reward": 1.0}
        return np.zeros(2, dtype=np.float32), 0.0, False, False, info


def test_a_user_env_scored_by_return_is_evaluated_as_its_profile_says() -> None:
    """The same env registered twice: with the default profile a trial is a success only if
    its last step is; declared ``scored_by_return``, any goal met counts, and both run to the
    horizon (the registered ``max_episode_steps``)."""
    register("test/GoalOnceTask-v0", _GoalOnce, max_episode_steps=5)
    register(
        "test/GoalOnceReturn-v0",
        _GoalOnce,
        max_episode_steps=5,
        profile=EnvProfile(scored_by_return=True),
    )
    zero = lambda obs: np.zeros((len(obs), 2))  # noqa: E731
    task = rollouts("rl", {}, zero, [1, 2], "test/GoalOnceTask-v0")
    by_return = rollouts("rl", {}, zero, [1, 2], "test/GoalOnceReturn-v0")
    assert [o["success"] for o in task] == [False, False]
    assert [o["success"] for o in by_return] == [True, True]
    assert [o["steps"] for o in task + by_return] == [5] * 4
    assert [o["return"] for o in by_return] == [5.0, 5.0]


def test_recorders_see_every_step_and_add_to_the_outcome() -> None:
    class Count(Recorder):
        def __init__(self) -> None:
            self.steps: dict[int, int] = {}

        def start(self, trial: int, env: Any) -> None:
            self.steps[trial] = 0

        def step(self, trial: int, env: Any) -> None:
            self.steps[trial] += 1

        def end(self, trial: int, env: Any, info: dict[str, Any], terminated: bool) -> Any:
            return {"counted": self.steps[trial]}

    count = Count()
    outcomes = rollouts("rl_cbf", {}, lambda o: np.zeros((len(o), 2)), [3, 4], recorders=[count])
    assert [o["counted"] for o in outcomes] == [o["steps"] for o in outcomes]
    assert all(o["steps"] > 0 for o in outcomes)


def test_a_bad_profile_is_a_clear_error() -> None:
    with pytest.raises(TypeError, match="scored_by_return = 'yes': expected a bool"):
        EnvProfile(scored_by_return="yes")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"params = .*expected 'module:attr'"):
        EnvProfile(params=ChannelParams)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="task_keywords = 'formula'"):
        EnvProfile(task_keywords="formula")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="preset_overrides"):
        EnvProfile(preset_overrides={"paper": 1})  # type: ignore[dict-item]
    with pytest.raises(TypeError, match="expected an EnvProfile"):
        register("test/Bad-v0", _GoalOnce, profile={"scored_by_return": True})  # type: ignore[arg-type]
    assert "test/Bad-v0" not in gym.registry


def test_the_lab_checks_no_env_id() -> None:
    """The lab reads an env's profile, never its id: no comparison with a bundled id, no
    id-keyed table, no ``scored_by_return(env_id)``."""
    ids = r"(ENV_ID|FLATWORLD_ID|POINT_MASS_ID|SAFETY_GYM_IDS)"
    pattern = re.compile(
        rf"[!=]=\s*{ids}|{ids}\s*[!=]=|\bin\s+{ids}|{ids}\s*:|scored_by_return\(|"
        r"env(_id)?\s*[!=]=\s*\""
    )
    hits = [
        f"{path.relative_to(LAB)}:{i}: {line.strip()}"
        for path in sorted(LAB.rglob("*.py"))
        for i, line in enumerate(path.read_text().splitlines(), 1)
        if pattern.search(line)
    ]
    assert hits == []


def test_the_0_4_removals_name_their_replacement() -> None:
    with pytest.raises(ImportError, match=r"profile_of\(env_id\)\.scored_by_return"):
        from tlshield.lab.envs import scored_by_return  # noqa: F401
    with pytest.raises(ImportError, match=r"tlshield\.sb3\.make_vec_env"):
        from tlshield.lab.training import make_vec_env  # noqa: F401
    with pytest.raises(ImportError, match=r"profile_of\(env_id\)\.task_keywords"):
        from tlshield.lab.settings import TASK_KEYWORDS  # noqa: F401
    with pytest.raises(ImportError, match=r"tlshield\.lab\.bench\.write_report\(bench, out\)"):
        from tlshield.lab.benchmark import write_report  # noqa: F401
    with pytest.raises(ImportError, match=r"benchmark_safety_gym\.REPORT"):
        from tlshield.lab.benchmark_safety_gym import read_rows  # noqa: F401
    with pytest.raises(TypeError, match="recorders="):
        rollouts("rl", {}, lambda o: o, [1], extra=lambda *a: {})  # type: ignore[arg-type]
    import tlshield.lab.envs

    assert not hasattr(tlshield.lab.envs, "no_such_name")
