"""Training on FlatWorld-v0 and DeepLTL's benchmark (issue 22): training checks the task it is
given (any registered environment), the command line trains and evaluates, and the benchmark's
pipeline (Ray jobs, the CSV, the report) trains as plain SB3 would."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from tlshield.envs.flatworld import flatworld_spec

ID = "tlshield/FlatWorld-v0"
F2 = "F(orange & (!red U magenta))"


def test_training_checks_the_task_it_is_given(tmp_path: Path) -> None:
    from tlshield.lab.training import train

    with pytest.raises(ValueError, match="not a registered Gymnasium id"):
        train("rl", 0, 1, tmp_path / "a", env="nobody/Nothing-v0")
    # A user's env whose reward is sized for another discount, or a shorter horizon.
    spec = flatworld_spec("F yellow")

    def fixed_discount(config: str = "rl", evaluation: bool = False) -> gym.Env:
        """A factory that sizes its reward for gamma 0.9 and does not take the trainer's."""
        from tlshield.envs.flatworld import FlatWorld, FlatWorldParams
        from tlshield.wrappers import FsaAugmented

        return FsaAugmented(FlatWorld(FlatWorldParams()), spec, gamma=0.9, horizon=500)

    def user_env(
        config: str = "rl", evaluation: bool = False, gamma: float = 0.9, horizon: int = 500
    ) -> gym.Env:
        """A factory that names gamma: the trainer hands it its own discount."""
        from tlshield.envs.flatworld import FlatWorld, FlatWorldParams
        from tlshield.wrappers import FsaAugmented

        return FsaAugmented(FlatWorld(FlatWorldParams()), spec, gamma=gamma, horizon=horizon)

    gym.register("tests/FixedFlat-v0", entry_point=fixed_discount)
    gym.register("tests/UserFlat-v0", entry_point=user_env)
    try:
        with pytest.raises(ValueError, match="gamma"):
            train("rl", 0, 1, tmp_path / "b", env="tests/FixedFlat-v0")
        with pytest.raises(ValueError, match="horizon"):
            train("rl", 0, 1, tmp_path / "c", env="tests/UserFlat-v0", horizon=100)
        run = train("rl", 0, 1, tmp_path / "d", env="tests/UserFlat-v0", progress=False)
        record = json.loads((run / "run.json").read_text())
        assert record["finished"]
        assert record["overrides"]["gamma"] == record["ppo"]["gamma"]
    finally:
        del gym.registry["tests/FixedFlat-v0"]
        del gym.registry["tests/UserFlat-v0"]


def test_train_and_evaluate_flatworld_from_the_cli(tmp_path: Path) -> None:
    from tlshield.lab import cli
    from tlshield.lab.evaluation import evaluate

    out = tmp_path / "fw"
    args = ["train", "--env", ID, "--config", "rl_cbf_clf", "--set", "formula=F(aqua & blue)"]
    assert cli.main([*args, "--updates", "1", "--out", str(out), "--quiet"]) == 0
    with (out / "metrics.csv").open() as fh:
        assert int(next(csv.DictReader(fh))["violations"]) == 0
    result = evaluate(out, trials=3)
    assert result["trials"] == 3 and result["collisions"] == 0


def test_benchmark_pipeline_on_a_formula_outside_the_table(tmp_path: Path) -> None:
    """Tiny budget: the plumbing (Ray jobs, the CSV, the report), and no violation anywhere."""
    from tlshield.lab.benchmark import COLUMNS, flatworld

    formula = "F(yellow & F(aqua & blue))"
    out = flatworld(
        tmp_path / "b",
        formulas=[formula],
        configs=["rl_cbf_clf"],
        seeds=[1],
        episodes=4,
        steps=512,
        workers=1,
        progress=False,
    )
    with (out / "flatworld.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == COLUMNS
    methods = {r["method"] for r in rows}
    assert methods == {"tlshield-rl_cbf_clf", "tlshield-zero", "tlshield-random"}
    for r in rows:
        assert r["task"] == formula and r["seed"] == "1"
        assert int(r["violations"]) == 0 and int(r["box_exits"]) == 0
        assert int(r["train_violations"]) == 0
    trained = next(r for r in rows if r["method"] == "tlshield-rl_cbf_clf")
    assert int(trained["train_steps"]) >= 512
    table = (out / "flatworld.md").read_text()
    assert "trains one agent per formula" in table and "(published)" not in table
    assert (out / "flatworld_paths.png").stat().st_size > 0


def test_benchmark_job_trains_through_the_pipeline_as_plain_sb3_would(tmp_path: Path) -> None:
    """One training pipeline (issue 36): a benchmark job trains through
    ``training.prepare``/``learn`` with the ``flatworld`` preset. Plain SB3 with the preset's
    settings, seeds and a callback of its own counting failures must give the same weights and
    the same training counts; the job's folder is a run folder that ``load_policy`` reads back
    (raw observations, Tanh networks)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import DummyVecEnv

    from tlshield.lab.benchmark import PRESET, job
    from tlshield.lab.presets import PRESETS
    from tlshield.lab.saved import load_policy
    from tlshield.lab.seeds import learner_seed, train_seed

    seed, steps = 1, 4096
    folder = tmp_path / "job"
    job(F2, 2, "rl", seed, steps, 4, folder)  # unshielded: it leaves the square in training
    result = json.loads((folder / "result.json").read_text())
    record = json.loads((folder / "run.json").read_text())
    assert record["preset"] == PRESET and record["env_id"] == ID and record["finished"]

    spec = PRESETS[PRESET]
    failures = 0

    class Count(BaseCallback):  # type: ignore[misc]
        def _on_step(self) -> bool:
            nonlocal failures
            for info, done in zip(self.locals["infos"], self.locals["dones"], strict=True):
                failures += int(done) * (int(info["trap"]) + int(info["box_exit"]))
            return True

    torch.set_num_threads(1)
    make = lambda: gym.make(ID, formula=F2, config="rl", gamma=spec["ppo"]["gamma"])  # noqa: E731
    venv = DummyVecEnv([make] * spec["n_envs"])
    venv.seed(train_seed(seed))
    model = PPO(
        "MlpPolicy",
        venv,
        seed=learner_seed(seed),
        device="cpu",
        policy_kwargs={"net_arch": [64, 64]},  # SB3's Tanh: the preset names it
        **spec["ppo"],
    )
    model.learn(total_timesteps=steps, callback=Count())
    assert failures > 0, "the reference should leave the square at least once"
    assert result["train_violations"] == failures
    assert result["train_steps"] == model.num_timesteps == steps
    kept = load_policy(folder)
    xy = np.random.default_rng(0).uniform(-2.0, 2.0, size=(16, 2))
    n_q = venv.observation_space.shape[0] - 2  # then the automaton state, one-hot
    obs = np.hstack([xy, np.eye(n_q)[np.arange(16) % n_q]])
    np.testing.assert_array_equal(kept(obs), model.predict(obs, deterministic=True)[0])
