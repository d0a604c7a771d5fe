"""The learning levers of docs/learning.md that training offers as settings: learning from the
executed action, and gSDE."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

from tlshield.envs.safety_gym import load_builder
from tlshield.lab import settings
from tlshield.lab.callbacks import ExecutedActions
from tlshield.lab.evaluation import evaluate
from tlshield.lab.training import train
from tlshield.sb3 import make_vec_env


class Check(BaseCallback):  # type: ignore[misc]
    """Records each step's executed actions and, at the rollout's end (before PPO trains),
    what the rollout buffer holds and the policy's log-likelihood of it."""

    def __init__(self) -> None:
        super().__init__()
        self.executed: list[np.ndarray] = []
        self.clf: list[np.ndarray] = []

    def _on_step(self) -> bool:
        self.executed.append(np.stack([i["action"] for i in self.locals["infos"]]))
        self.clf.append(np.stack([i["shield"]["a_clf"] for i in self.locals["infos"]]))
        return True

    def _on_rollout_end(self) -> None:
        buf = self.model.rollout_buffer
        self.actions = buf.actions.copy()
        obs = torch.as_tensor(buf.observations.reshape(-1, buf.observations.shape[-1]))
        taken = torch.as_tensor(buf.actions.reshape(-1, buf.actions.shape[-1]))
        with torch.no_grad():
            _, log_prob, _ = self.model.policy.evaluate_actions(obs, taken)
        self.log_prob = log_prob.numpy().reshape(buf.log_probs.shape)
        self.stored = buf.log_probs.copy()


@pytest.mark.parametrize("env_id", ["tlshield/Channel-v0", "tlshield/PointMass-v0"])
def test_the_rollout_holds_the_executed_actions(env_id: str) -> None:
    venv = make_vec_env(env_id, 4, "rl_cbf_clf")
    venv.seed(5)
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=64, seed=0, device="cpu")
    check = Check()
    model.learn(total_timesteps=64, callback=[ExecutedActions(venv), check])
    executed = np.stack(check.executed)  # (steps, envs, 2), in the plant's units
    first = venv.envs[0]
    if hasattr(first, "rl_action"):  # Channel-v0: policy units map affinely onto the plant's
        mapped = np.stack([first.rl_action(np.clip(a, -1.0, 1.0)) for a in check.actions])
        inside = np.all(np.abs(check.actions) <= 1.0, axis=-1)
        assert inside.sum() > 0
        np.testing.assert_allclose(mapped[inside], executed[inside], atol=1e-5)
    else:  # PointMass-v0: the policy acts in the plant's units
        np.testing.assert_allclose(check.actions, executed, atol=1e-6)
    # Their stored log-likelihoods are the sampling policy's, of the executed actions.
    np.testing.assert_allclose(check.stored, check.log_prob, rtol=1e-5, atol=1e-5)


def test_without_the_callback_the_rollout_holds_other_actions() -> None:
    # The control of the test above: the shield and the CLF change the actions, so the
    # sampled ones it would otherwise find are not the executed ones.
    venv = make_vec_env("tlshield/Channel-v0", 4, "rl_cbf_clf")
    venv.seed(5)
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=64, seed=0, device="cpu")
    check = Check()
    model.learn(total_timesteps=64, callback=[check])
    first = venv.envs[0]
    mapped = np.stack([first.rl_action(np.clip(a, -1.0, 1.0)) for a in check.actions])
    assert np.abs(mapped - np.stack(check.executed)).max() > 0.1


def test_training_with_the_levers(tmp_path: Path) -> None:
    run = train(
        "rl_cbf_clf",
        0,
        2,
        tmp_path / "e",
        progress=False,
        ppo={"learn_from": "executed_without_clf"},
    )
    assert json.loads((run / "run.json").read_text())["ppo"]["learn_from"] == "executed_without_clf"
    sde: dict[str, Any] = {"policy": "gaussian", "use_sde": True, "sde_sample_freq": 4}
    run = train("rl_cbf", 0, 2, tmp_path / "g", progress=False, ppo=sde)
    # A gSDE policy loads back from its run folder (its noise weights are part of it).
    assert evaluate(run, trials=2)["trials"] == 2
    lines = (run / "metrics.csv").read_text().splitlines()
    header, last = lines[0].split(","), lines[-1].split(",")
    std = float(last[header.index("policy_std_0")])
    assert np.isfinite(std) and std > 0.0
    assert settings.split({"use_sde": True, "learn_from": "executed"})["ppo"] == {
        "use_sde": True,
        "learn_from": "executed",
    }


def test_gsde_needs_sb3s_own_policy(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="use_sde needs policy 'gaussian', not 'tanh_mean'"):
        train("rl_cbf", 0, 1, tmp_path / "x", ppo={"use_sde": True})
    assert not (tmp_path / "x").exists()
    with pytest.raises(ValueError, match="learn_from = 'shield': expected one of"):
        train("rl_cbf", 0, 1, tmp_path / "x", ppo={"learn_from": "shield"})


def test_without_the_clf_the_rollout_holds_the_safety_correction_only() -> None:
    venv = make_vec_env("tlshield/Channel-v0", 4, "rl_cbf_clf")
    venv.seed(5)
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=64, seed=0, device="cpu")
    check = Check()
    model.learn(total_timesteps=64, callback=[ExecutedActions(venv, without_clf=True), check])
    first = venv.envs[0]
    mapped = np.stack([first.rl_action(np.clip(a, -1.0, 1.0)) for a in check.actions])
    wanted = np.stack(check.executed) - np.stack(check.clf)
    inside = np.all(np.abs(check.actions) <= 1.0, axis=-1)
    assert inside.sum() > 0 and np.abs(np.stack(check.clf)).max() > 0.1
    np.testing.assert_allclose(mapped[inside], wanted[inside], atol=1e-5)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # gymnasium's Box casts
@pytest.mark.parametrize("task", ["SafetyPointGoal1-v0", "SafetyCarGoal1-v0"])
@pytest.mark.parametrize("without_clf", [False, True])
def test_safety_gym_rollout_holds_what_the_robot_did(task: str, without_clf: bool) -> None:
    # Safety-Gymnasium's policy acts in the robot's units, not the shield's: the rollout holds
    # info["action"] (already in the policy's units), or, without the CLF, the env's action for
    # the shield's input less the CLF's part (a_rl + a_cbf), recomputed here from the shield's
    # own parts.
    load_builder()  # make test installs the stack; without it, this is the error that says so
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: gym.make(f"tlshield/{task}", config="rl_cbf_clf")])
    venv.seed(5)
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=32, seed=0, device="cpu")
    check = Check()
    parts: list[np.ndarray] = []

    class Parts(BaseCallback):  # type: ignore[misc]
        def _on_step(self) -> bool:
            info = self.locals["infos"][0]
            parts.append(info["shield"]["a_rl"] + info["shield"]["a_cbf"])
            return True

    callback = ExecutedActions(venv, without_clf=without_clf)
    model.learn(total_timesteps=32, callback=[Parts(), callback, check])
    env = venv.envs[0].unwrapped
    executed = np.stack(check.executed)[:, 0]
    if without_clf:
        wanted = np.stack([env.env_action(p) for p in parts])
        # the CLF pushed, so this is not the executed action
        assert np.abs(np.stack(check.clf)).max() > 0.1
        assert np.abs(wanted - executed).max() > 1e-3
    else:
        wanted = executed
    np.testing.assert_allclose(check.actions[:, 0], wanted, atol=1e-6)
    np.testing.assert_allclose(check.stored, check.log_prob, rtol=1e-5, atol=1e-5)


def test_the_learning_rate_schedule_is_a_setting(tmp_path: Path) -> None:
    run = train("rl_cbf", 0, 2, tmp_path / "c", progress=False, ppo={"lr_schedule": "constant"})
    assert json.loads((run / "run.json").read_text())["ppo"]["lr_schedule"] == "constant"
    with pytest.raises(ValueError, match="lr_schedule = 'cosine': expected one of"):
        train("rl_cbf", 0, 1, tmp_path / "x", ppo={"lr_schedule": "cosine"})
    assert not (tmp_path / "x").exists()


def _script(name: str, *args: str) -> str:
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]
    done = subprocess.run(
        [sys.executable, str(root / "scripts" / name), *args],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def test_the_lever_scripts_run(tmp_path: Path) -> None:
    # SAC on the core vector env: trains, validates, evaluates kept and last, writes its table.
    out = _script(
        "learning_sac.py",
        *("--out", str(tmp_path / "sac"), "--configs", "rl_cbf_clf", "--seeds", "0"),
        *("--steps", "1600", "--validate-every", "800", "--trials", "2"),
    )
    assert "| rl_cbf_clf | 0 |" in out
    row = json.loads((tmp_path / "sac" / "rl_cbf_clf_s0.json").read_text())
    assert row["violations"] == 0 and row["kept_step"] in (800, 1600)
    # The profile's parts add up to the rollouts and gradient steps it measured.
    out = _script("profile_update.py", "--updates", "2")
    shares = [
        float(line.rsplit("|", 2)[1].strip().rstrip("%"))
        for line in out.splitlines()
        if line.startswith("| -")
    ]
    assert len(shares) == 8 and all(s >= 0 for s in shares)
    # The time-to-solve figure from two sets of runs.
    for name in ("a", "b"):
        train("rl_cbf_clf", 0, 10, tmp_path / name / "rl_cbf_clf_s0", progress=False)
    _script(
        "time_to_solve.py", str(tmp_path / "t.png"), f"a={tmp_path / 'a'}", f"b={tmp_path / 'b'}"
    )
    assert (tmp_path / "t.png").stat().st_size > 10_000


def test_the_exploration_script_counts_reaches_and_traps() -> None:
    # Untrained policies on every configuration: the shielded ones never enter the trap, and
    # the CLF's push reaches g1/g2 where the policy alone does not.
    out = _script("exploration_reach.py", "--episodes", "6")
    rows = {
        (cells[1], cells[2]): [float(c) for c in cells[3:6]]
        for line in out.splitlines()
        if line.startswith("| rl") and len(cells := [c.strip() for c in line.split("|")]) > 6
    }
    assert len(rows) == 8
    for (config, _), (reached, trapped, moved) in rows.items():
        assert 0.0 <= reached <= 1.0 and moved >= 0.0
        if "cbf" in config:
            assert trapped == 0.0
    assert rows[("rl_cbf_clf", "uniform")][0] > rows[("rl_cbf", "uniform")][0]


def test_the_entropy_schedule_decays_ent_coef_to_zero(tmp_path: Path) -> None:
    seen: list[float] = []

    class Watch(BaseCallback):  # type: ignore[misc]
        def _on_rollout_end(self) -> None:
            seen.append(float(self.model.ent_coef))

        def _on_step(self) -> bool:
            return True

    from tlshield.lab.callbacks import EntropySchedule

    venv = make_vec_env("tlshield/Channel-v0", 2, "rl_cbf")
    model = PPO("MlpPolicy", venv, n_steps=8, batch_size=16, seed=0, device="cpu", ent_coef=0.5)
    model.learn(total_timesteps=4 * 16, callback=[EntropySchedule(0.02, 4), Watch()])
    assert seen == pytest.approx([0.02, 0.015, 0.01, 0.005])
    run = train(
        "rl_cbf",
        0,
        2,
        tmp_path / "e",
        progress=False,
        ppo={"ent_coef": 0.01, "ent_schedule": "linear"},
    )
    assert json.loads((run / "run.json").read_text())["ppo"]["ent_schedule"] == "linear"
    assert settings.split({"ent_schedule": "linear"})["ppo"] == {"ent_schedule": "linear"}
    with pytest.raises(ValueError, match="ent_schedule = 'cosine': expected one of"):
        train("rl_cbf", 0, 1, tmp_path / "x", ppo={"ent_schedule": "cosine"})
