"""A fingerprint of what the bundled environments and training produce: hashes of seeded random
rollouts of Channel-v0 (every configuration and observation), FlatWorld-v0 and PointMass-v0
(and SafetyPointGoal1-v0 where ``make safety-gym`` installed it), of a 12-update training
run (metrics, kept and last policy weights) and of one FlatWorld benchmark job (its result row
and evaluation paths). Run it in two checkouts (or with two PYTHONPATHs)
to show that a refactor left every number as it was:

    python scripts/fingerprint.py > before.txt   # in the old checkout
    python scripts/fingerprint.py > after.txt    # in the new one
    diff before.txt after.txt
"""

from __future__ import annotations

import csv
import hashlib
import json
import tempfile
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np

import tlshield  # noqa: F401  (registers the environments)


def _digest(parts: list[str]) -> str:
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:16]


def rollout(env: gym.Env, steps: int = 1000) -> str:
    """Random actions (seed 5) from reset seed 7, resetting from drawn seeds at episode ends;
    every other episode drives ahead and turns (into walls and obstacles, so the shield acts)."""
    rng = np.random.default_rng(5)
    obs, _ = env.reset(seed=7)
    parts = [np.asarray(obs).tobytes().hex()]
    episode = 0
    for _ in range(steps):
        action = rng.uniform(-1, 1, env.action_space.shape)
        if episode % 2:  # full speed ahead, turning slowly: into a wall, unless shielded
            action = 0.1 * action + 0.2
            action[0] = 1.0
        obs, reward, term, trunc, info = env.step(action)
        shield = info.get("shield", {})
        parts.append(
            f"{np.asarray(obs).tobytes().hex()}|{reward!r}|{term}|{trunc}|{info.get('fsa_state')}"
            f"|{np.asarray(shield.get('a_cbf', [])).tobytes().hex()}"
            f"|{np.asarray(shield.get('a_clf', [])).tobytes().hex()}"
        )
        if term or trunc:
            episode += 1
            obs, _ = env.reset(seed=int(rng.integers(1000)))
            parts.append(np.asarray(obs).tobytes().hex())
    return _digest(parts)


#: metrics.csv columns newer than the fingerprint (tlshield.lab.runs.RETURN_COLUMNS).
NEW_COLUMNS = (
    "task_return_mean",
    "episode_cost_mean",
    "cost",
    "validation_return",
    "validation_cost",
)


def training() -> str:
    try:
        from tlshield.lab.training import train
    except ImportError:  # a checkout from before tlshield.lab
        from tlshield.training import train  # type: ignore[no-redef]

    with tempfile.TemporaryDirectory() as tmp:
        folder = train("rl_cbf_clf", 0, 12, Path(tmp) / "run", progress=False)
        rows = list(csv.DictReader((folder / "metrics.csv").open()))
        for row in rows:
            row.pop("wall_time")
            # Return and cost came later (issue 45): left out, so that older checkouts compare.
            for name in NEW_COLUMNS:
                row.pop(name, None)
        weights = [
            zipfile.ZipFile(folder / name).read("policy.pth").hex()
            for name in ("model.zip", "last_model.zip")
        ]
        # The run's record: run.json since 0.2, config.json before (so old checkouts compare).
        record = next(p for p in (folder / "run.json", folder / "config.json") if p.is_file())
        kept = json.loads(record.read_text()).get("kept")
        return _digest([json.dumps(rows), *weights, json.dumps(kept)])


def flatworld_training() -> str:
    """One FlatWorld benchmark job (2 PPO updates, 20 stochastic evaluation episodes): its
    result row (wall time left out) and the evaluation paths."""
    try:
        from tlshield.lab.benchmark import job
    except ImportError:  # a checkout from before tlshield.lab
        from tlshield.benchmark import job  # type: ignore[no-redef]
    from tlshield.envs.flatworld import FORMULAS

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "job"
        job(FORMULAS[1], 2, "rl_cbf_clf", 1, 4096, 20, folder)
        row = json.loads((folder / "result.json").read_text())
        row.pop("wall_time")
        with np.load(folder / "paths.npz") as data:
            paths = [data[k].tobytes().hex() for k in sorted(data.files)]
        return _digest([json.dumps(row, sort_keys=True), *paths])


def main() -> None:
    from tlshield.envs.channel import CONFIGS

    for config in CONFIGS:
        for observation in ("relative", "paper"):
            env = gym.make("tlshield/Channel-v0", config=config, observation=observation)
            print(f"Channel-v0 {config} {observation}: {rollout(env.unwrapped)}")
    for env_id, kwargs in (
        ("tlshield/FlatWorld-v0", {"formula": "F(orange & (!red U magenta))"}),
        ("tlshield/PointMass-v0", {}),
    ):
        for config in ("rl", "rl_cbf_clf"):
            print(f"{env_id} {config}: {rollout(gym.make(env_id, config=config, **kwargs))}")
    try:
        from tlshield.envs import safety_gym
    except ImportError:  # a checkout from before the Safety-Gymnasium envs
        safety_gym = None
    if safety_gym is not None and safety_gym.installed():  # make safety-gym
        for config in ("rl", "rl_cbf_clf"):
            env = safety_gym.SafetyGoalEnv("SafetyPointGoal1-v0", config)
            print(f"SafetyPointGoal1-v0 {config}: {rollout(env)}")
    print(f"train rl_cbf_clf seed 0, 12 updates: {training()}")
    print(f"FlatWorld benchmark job, formula 2, seed 1, 4096 steps: {flatworld_training()}")


if __name__ == "__main__":
    main()
