"""``tlshield benchmark safety-gym``: SB3 PPO on Safety-Gymnasium's navigation tasks, unshielded
(``rl``) and shielded (``rl_cbf``, ``rl_cbf_clf``), beside OmniSafe's published rows.

Per (env, configuration, seed) a PPO agent (Stable-Baselines3's defaults, the same for every
configuration) is trained on the standard observation of ``tlshield/<env>`` and evaluated with
its deterministic policy, each configuration as it trained (``rl`` unshielded). Jobs run as
Ray tasks (:mod:`tlshield.lab.cluster`); a finished job keeps its folder, so an interrupted run
resumes where it stopped. The shield reads the privileged true state (agent pose and velocity,
goal, hazards, vases), which the policy never sees; every table says so.

Seeds (:mod:`tlshield.lab.seeds`): training resets from ``train_seed(seed)``, evaluation episode
``k`` from ``eval_block_seed(seed, k)`` (disjoint, never used for tuning), and PPO takes
``learner_seed(seed)``.
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from tlshield.lab.seeds import check_block, check_seeds, eval_block_seed, learner_seed, train_seed

#: The default budget per env (PPO steps per agent).
DEFAULT_STEPS = {"SafetyPointGoal1-v0": 1_000_000, "SafetyPointGoal2-v0": 300_000}
DEFAULT_CONFIGS = ("rl", "rl_cbf", "rl_cbf_clf")
DEFAULT_SEEDS = (0, 1, 2)
DEFAULT_EPISODES = 10
#: The columns of ``safety_gym.csv``.
COLUMNS = (
    "env",
    "method",
    "seed",
    "steps",
    "eval_return",
    "eval_cost",
    "train_cost",
    "train_cost_rate",
    "wall_s",
)
#: OmniSafe's published on-policy rows (1e7 steps, cost limit 25; the means of its
#: ``benchmarks/on-policy/README.md``): return, cost per episode.
OMNISAFE = {
    "SafetyPointGoal1-v0": {
        "PPO": (25.44, 55.72),
        "PPO-Lag": (12.96, 25.80),
        "CPO": (20.46, 28.84),
    },
    "SafetyPointGoal2-v0": {
        "PPO": (25.49, 159.28),
        "PPO-Lag": (1.98, 41.20),
        "CPO": (2.50, 40.84),
    },
}


def _make(env: str, config: str) -> Any:
    from tlshield.envs.safety_gym import SafetyGoalEnv

    return SafetyGoalEnv(env, config)


def train_and_evaluate(
    env: str, config: str, seed: int, steps: int, episodes: int, folder: Path
) -> None:
    """One (env, configuration, seed): PPO for ``steps``, then ``episodes`` evaluation
    episodes; writes ``result.json`` and ``curve.csv`` (return and cost per update) into
    ``folder`` (a Ray task)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import DummyVecEnv

    torch.set_num_threads(1)
    start = time.perf_counter()
    venv = DummyVecEnv([partial(_make, env, config)])
    venv.seed(train_seed(seed))
    totals = {"cost": 0.0}
    curve: list[dict[str, float]] = []
    episode = {"ret": 0.0, "cost": 0.0}
    finished: list[tuple[float, float]] = []

    class Count(BaseCallback):
        def _on_step(self) -> bool:
            info, done = self.locals["infos"][0], self.locals["dones"][0]
            episode["ret"] += float(self.locals["rewards"][0])
            episode["cost"] += float(info["cost"])
            totals["cost"] += float(info["cost"])
            if done:
                finished.append((episode["ret"], episode["cost"]))
                episode["ret"], episode["cost"] = 0.0, 0.0
            return True

        def _on_rollout_end(self) -> None:
            if finished:
                rets, costs = zip(*finished, strict=True)
                curve.append(
                    {
                        "steps": self.num_timesteps,
                        "return": float(np.mean(rets)),
                        "cost": float(np.mean(costs)),
                    }
                )
                finished.clear()

    model = PPO("MlpPolicy", venv, seed=learner_seed(seed), device="cpu", verbose=0)
    model.learn(total_timesteps=steps, callback=Count())
    venv.close()
    returns, costs = evaluate(env, config, model, seed, episodes)
    folder.mkdir(parents=True, exist_ok=True)
    row = {
        "env": env,
        "method": config,
        "seed": seed,
        "steps": int(model.num_timesteps),
        "budget": steps,
        "eval_return": float(np.mean(returns)),
        "eval_cost": float(np.mean(costs)),
        "train_cost": totals["cost"],
        "train_cost_rate": totals["cost"] / max(int(model.num_timesteps), 1),
        "wall_s": time.perf_counter() - start,
        "eval_returns": returns,
        "eval_costs": costs,
    }
    (folder / "result.json").write_text(json.dumps(row, indent=2))
    with open(folder / "curve.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=["steps", "return", "cost"])
        writer.writeheader()
        writer.writerows(curve)


def evaluate(
    env_id: str, config: str, model: Any, seed: int, episodes: int
) -> tuple[list[float], list[float]]:
    """Return and cost of ``episodes`` episodes of the deterministic policy, from the
    evaluation seeds of ``seed``."""
    env = _make(env_id, config)
    returns, costs = [], []
    for k in range(episodes):
        obs, _ = env.reset(seed=eval_block_seed(seed, k))
        ret, cost, done = 0.0, 0.0, False
        while not done:
            action = model.predict(obs, deterministic=True)[0]
            obs, r, terminated, truncated, info = env.step(action)
            ret += r
            cost += info["cost"]
            done = terminated or truncated
        returns.append(ret)
        costs.append(cost)
    return returns, costs


def safety_gym(
    out: str | Path,
    *,
    envs: Sequence[str] = tuple(DEFAULT_STEPS),
    configs: Sequence[str] = DEFAULT_CONFIGS,
    seeds: Sequence[int] = DEFAULT_SEEDS,
    steps: int | None = None,
    episodes: int = DEFAULT_EPISODES,
    address: str | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> Path:
    """Runs the benchmark into ``out`` (resumable: finished jobs are kept) and writes
    ``safety_gym.csv``, ``safety_gym.md`` and ``safety_gym.png``. ``steps`` overrides
    :data:`DEFAULT_STEPS` for every env."""
    from tlshield.envs.params import CONFIGS
    from tlshield.envs.safety_gym import TASKS, load_builder

    load_builder()  # a missing stack is one clear ImportError, before any job
    for e in envs:
        if e not in TASKS:
            raise ValueError(f"env {e!r}: expected one of {', '.join(TASKS)}")
    for c in configs:
        if c not in CONFIGS:
            raise ValueError(f"config {c!r}: expected one of {', '.join(CONFIGS)}")
    check_block(episodes, "episodes")
    if steps is not None and not (isinstance(steps, int) and steps > 0):
        raise ValueError(f"steps = {steps!r}: expected a positive integer")
    check_seeds(seeds)
    out = Path(out)
    runs = out / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    jobs = {}
    for e in envs:
        budget = steps or DEFAULT_STEPS[e]
        for c in configs:
            for s in seeds:
                folder = runs / f"{e}-{c}-s{s}-{budget}"
                if not (folder / "result.json").exists():
                    jobs[folder] = partial(train_and_evaluate, e, c, s, budget, episodes)
    from tlshield.lab import cluster

    cluster.run_counted(jobs, address, workers, progress)
    return write_report(out)


def read_rows(out: Path) -> list[dict[str, Any]]:
    """Every finished job's row, in a stable order."""
    rows = [json.loads(p.read_text()) for p in sorted((out / "runs").glob("*/result.json"))]
    return sorted(rows, key=lambda r: (r["env"], r["budget"], r["method"], r["seed"]))


def write_report(out: Path) -> Path:
    """``safety_gym.csv``, ``safety_gym.md`` and ``safety_gym.png`` from the finished jobs."""
    rows = read_rows(out)
    with open(out / "safety_gym.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    (out / "safety_gym.md").write_text(markdown(rows))
    _figure(out, rows)
    return out


def markdown(rows: list[dict[str, Any]]) -> str:
    """The per-seed table, then OmniSafe's rows for the same envs."""
    lines = [
        "Per seed: evaluation return and cost per episode (deterministic policy, each "
        "configuration as trained; `rl` is unshielded), cost summed over training. The shield "
        "reads the privileged true state (agent pose and velocity, goal, hazards, vases); the "
        "policy sees Safety-Gymnasium's standard observation.",
        "",
        "| env | method | seed | PPO steps | eval return | eval cost | train cost | "
        "train cost / step | wall (s) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['env']} | {r['method']} | {r['seed']} | {r['steps']:,} | "
            f"{r['eval_return']:.2f} | {r['eval_cost']:.1f} | {r['train_cost']:.0f} | "
            f"{r['train_cost_rate']:.4f} | {r['wall_s']:.0f} |"
        )
    envs = sorted({r["env"] for r in rows})
    published = [(e, m, v) for e in envs for m, v in OMNISAFE.get(e, {}).items()]
    if published:
        lines += [
            "",
            "OmniSafe's published rows (SB3 is not OmniSafe, 1e7 steps against the budgets "
            "above, cost limit 25, and no privileged state: not like for like):",
            "",
            "| env | method | return | cost |",
            "|---|---|---:|---:|",
        ]
        lines += [f"| {e} | {m} | {ret:.2f} | {cost:.2f} |" for e, m, (ret, cost) in published]
    return "\n".join(lines) + "\n"


def _figure(out: Path, rows: list[dict[str, Any]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import EngFormatter

    envs = sorted({r["env"] for r in rows})
    if not envs:
        return
    fig, axes = plt.subplots(2, len(envs), figsize=(5.5 * len(envs), 6), squeeze=False)
    colours = {"rl": "tab:red", "rl_cbf": "tab:blue", "rl_clf": "tab:orange"}
    for j, e in enumerate(envs):
        for r in (r for r in rows if r["env"] == e):
            folder = out / "runs" / f"{e}-{r['method']}-s{r['seed']}-{r['budget']}"
            path = folder / "curve.csv"
            if not path.exists():
                continue
            with open(path) as fh:
                curve = list(csv.DictReader(fh))
            x = [int(c["steps"]) for c in curve]
            colour = colours.get(r["method"], "tab:green")
            label = f"{r['method']} s{r['seed']}"
            axes[0, j].plot(x, [float(c["return"]) for c in curve], color=colour, lw=1, label=label)
            axes[1, j].plot(x, [float(c["cost"]) for c in curve], color=colour, lw=1)
        axes[0, j].set_title(e)
        axes[0, j].set_ylabel("training return / episode")
        axes[1, j].set_ylabel("training cost / episode")
        axes[1, j].set_xlabel("PPO steps")
        for ax in axes[:, j]:
            ax.xaxis.set_major_formatter(EngFormatter())
        axes[0, j].legend(fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(out / "safety_gym.png", dpi=110)
    plt.close(fig)
