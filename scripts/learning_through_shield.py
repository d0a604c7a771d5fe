"""Issue 35's demo: what the gradient through the shield buys, on Channel-v0.

A deterministic policy is trained by imitation (DAgger) of a CLF-guided shielded expert and
deployed under the CBF alone (``rl_cbf``: safety guaranteed at deployment, no CLF):

* the expert: a scripted goal-seeker heading for the automaton's CLF goal (``towards`` in
  ``tests/scripted.py``), its action filtered by the ``rl_cbf_clf`` shield (CBF and CLF);
* ``through``: the student's loss is on its *shielded* action, ``|CBF(s, q, a_rl(pi(obs))) -
  a_expert|^2``, through ``tlshield.torch.ShieldLayer`` (the gradient this issue adds);
* ``direct``: the same data and budget, the loss on the student's own action
  ``|a_rl(pi(obs)) - a_expert|^2`` (behaviour cloning that treats the shield as a black box).

Each run: iteration 0 rolls out the expert, later iterations the student; every visited state is
labelled with the expert's action and added to the data set, and the student is trained on all
of it. The table's executed-action error is the mean squared distance between each student's
deployed action (its ``a_rl`` through the CBF) and the expert's, over all the data gathered, the
same measure for both. After every iteration the student runs 20 validation episodes (reset
seeds ``tlshield.lab.seeds.validation_seed``). The policy of the last iteration is evaluated (no
checkpoint selection) on the 100 evaluation episodes PPO's runs are evaluated on (reset seeds
``EVAL_SEED + i``, ``tlshield.lab.evaluation.rollouts``). Training resets use
``tlshield.lab.seeds.train_seed``.

Run: ``.venv/bin/python scripts/learning_through_shield.py --seeds 0 1 2 --out DIR``
(``--ppo DIR`` adds a ``tlshield reproduce --configs rl_cbf`` results folder to the table and the
figure). Writes ``DIR/through_shield.json``, ``DIR/through_shield.md`` and
``DIR/through_shield.png``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

METHODS = ("through", "direct")


def expert_rl_action(env: Any) -> np.ndarray:
    """The goal-seeker's normalised action towards the automaton's CLF goal (zero without one)."""
    from tests.scripted import towards

    goal = env.tracker.goal
    return towards(env, goal) if goal is not None else np.zeros(2)


def run(seed: int, method: str, args: argparse.Namespace) -> dict[str, Any]:
    import torch

    from tlshield.envs.channel import ChannelEnv
    from tlshield.envs.channel_task import ChannelParams, channel_shield
    from tlshield.lab.evaluation import rollouts
    from tlshield.lab.seeds import EVAL_SEED, learner_seed, train_seed, validation_seed
    from tlshield.torch import ShieldLayer

    torch.manual_seed(learner_seed(seed))
    torch.set_num_threads(1)
    cfg = ChannelParams()
    expert_shield = channel_shield(cfg, "rl_cbf_clf")
    deploy_shield = channel_shield(cfg, "rl_cbf")
    assert expert_shield is not None and deploy_shield is not None
    layer = ShieldLayer(deploy_shield)
    envs = [ChannelEnv(config="rl_cbf") for _ in range(args.envs)]
    lo, hi = (np.asarray(b, dtype=float) for b in cfg.agent.rl_bounds)
    centre, half = torch.tensor((hi + lo) / 2), torch.tensor((hi - lo) / 2)
    obs_dim = envs[0].observation_space.shape[0]
    policy = torch.nn.Sequential(
        torch.nn.Linear(obs_dim, 64),
        torch.nn.Tanh(),
        torch.nn.Linear(64, 64),
        torch.nn.Tanh(),
        torch.nn.Linear(64, 2),
        torch.nn.Tanh(),
    ).double()
    optim = torch.optim.Adam(policy.parameters(), lr=args.lr)
    norm = {
        "mean": torch.zeros(obs_dim, dtype=torch.float64),
        "std": torch.ones(obs_dim, dtype=torch.float64),
    }

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            x = (torch.from_numpy(np.asarray(obs, dtype=np.float64)) - norm["mean"]) / norm["std"]
            return policy(x).numpy()

    data: dict[str, list[np.ndarray]] = {k: [] for k in ("obs", "s", "q", "drift", "a_exp")}
    curve: list[dict[str, float]] = []
    steps_done, resets = 0, 0
    corrections: list[float] = []
    obs = [np.zeros(obs_dim)] * len(envs)

    def reset(i: int) -> None:
        # Training resets: run seed's training block, one reset seed per episode.
        nonlocal resets
        obs[i] = envs[i].reset(seed=train_seed(seed, resets))[0]
        resets += 1

    start = time.perf_counter()
    for it in range(args.iterations):
        corrections = []
        for i in range(len(envs)):
            reset(i)
        for _ in range(args.horizon):
            states = np.stack([env.state for env in envs])
            qs = np.array([env.tracker.q for env in envs])
            drift = np.stack([env.drift for env in envs])
            obs_b = np.stack(obs)
            expert = np.stack([expert_rl_action(env) for env in envs])
            a_exp = expert_shield.filter_batch(states, qs, envs[0].rl_action(expert), drift).action
            for key, value in zip(
                ("obs", "s", "q", "drift", "a_exp"),
                (obs_b, states, qs, drift, a_exp),
                strict=True,
            ):
                data[key].append(value)
            actions = expert if it == 0 else act(obs_b)
            for i, (env, a) in enumerate(zip(envs, actions, strict=True)):
                obs[i], _, term, trunc, info = env.step(a)
                if it > 0:
                    corrections.append(float(np.linalg.norm(info["shield"]["a_cbf"])))
                if term or trunc:
                    reset(i)
            steps_done += len(envs)
        # Train on everything gathered so far.
        obs_all = torch.from_numpy(np.concatenate(data["obs"]))
        s_all = np.concatenate(data["s"])
        q_all = np.concatenate(data["q"])
        d_all = np.concatenate(data["drift"])
        a_all = torch.from_numpy(np.concatenate(data["a_exp"]))
        norm["mean"], norm["std"] = obs_all.mean(0), obs_all.std(0) + 1e-6
        x_all = (obs_all - norm["mean"]) / norm["std"]
        gen = torch.Generator().manual_seed(learner_seed(seed) + it)
        for _ in range(args.epochs):
            perm = torch.randperm(len(x_all), generator=gen)
            for b in range(0, len(perm), args.batch):
                idx = perm[b : b + args.batch]
                a_rl = centre + half * policy(x_all[idx])
                if method == "through":
                    i_np = idx.numpy()
                    out = layer(torch.from_numpy(s_all[i_np]), q_all[i_np], a_rl, d_all[i_np])
                else:
                    out = a_rl
                loss = ((out - a_all[idx]) ** 2).sum(-1).mean()
                optim.zero_grad()
                loss.backward()
                optim.step()
        val = rollouts(
            "rl_cbf", {}, act, [validation_seed(seed, e) for e in range(args.validation)]
        )
        curve.append(
            {
                "iteration": it,
                "env_steps": steps_done,
                "wall_s": time.perf_counter() - start,
                "validation_success": float(np.mean([o["success"] for o in val])),
                "loss": float(loss.detach()),
            }
        )
        print(f"seed {seed} {method} it {it}: {curve[-1]}", flush=True)
    wall = time.perf_counter() - start
    # Both students measured the same way: the deployed (CBF-filtered) action against the
    # expert's, over all the data gathered.
    with torch.no_grad():
        a_rl = centre + half * policy(x_all)
        executed = layer(torch.from_numpy(s_all), q_all, a_rl, d_all)
        executed_error = float(((executed - a_all) ** 2).sum(-1).mean())
    outcomes = rollouts("rl_cbf", {}, act, [EVAL_SEED + i for i in range(args.trials)])
    return {
        "seed": seed,
        "method": method,
        "success": float(np.mean([o["success"] for o in outcomes])),
        "collisions": int(sum(bool(o["collision"]) for o in outcomes)),
        "violations": int(sum(o["violations"] or 0 for o in outcomes)),
        "mean_correction": float(np.mean(corrections)) if corrections else 0.0,
        "executed_error": executed_error,
        "env_steps": steps_done,
        "wall_s": wall,
        "curve": curve,
    }


def ppo_rows(folder: Path) -> list[dict[str, Any]]:
    """Per seed of a ``tlshield reproduce --configs rl_cbf`` folder: kept and last success,
    the last update's mean correction, env steps, wall time and the validation curve."""
    import csv

    rows = []
    for run in sorted(folder.glob("rl_cbf_s*")):
        record = json.loads((run / "run.json").read_text())
        kept = json.loads((run / "evaluation.json").read_text())
        last = json.loads((run / "last_evaluation.json").read_text())
        with open(run / "metrics.csv") as f:
            metrics = list(csv.DictReader(f))
        # Validation runs every few updates; the other rows hold nan.
        curve = [
            (int(m["timesteps"]), float(m["validation_success"]))
            for m in metrics
            if m.get("validation_success") not in (None, "", "nan")
        ]
        rows.append(
            {
                "seed": record["seed"],
                "kept": kept["success_rate"],
                "last": last["success_rate"],
                "collisions": kept["collisions"],
                "mean_correction": float(metrics[-1]["mean_correction"]),
                "env_steps": int(metrics[-1]["timesteps"]),
                "wall_s": float(record["wall_time"]),
                "curve": curve,
            }
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--ppo", type=Path, help="a tlshield reproduce --configs rl_cbf folder")
    parser.add_argument("--iterations", type=int, default=8)
    parser.add_argument("--envs", type=int, default=8)
    parser.add_argument("--horizon", type=int, default=200)
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--validation", type=int, default=20)
    parser.add_argument("--trials", type=int, default=100)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results = [run(seed, method, args) for seed in args.seeds for method in METHODS]
    ppo = ppo_rows(args.ppo) if args.ppo else []
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    (args.out / "through_shield.json").write_text(
        json.dumps(
            {
                "commit": commit,
                "args": {k: str(v) for k, v in vars(args).items()},
                "students": results,
                "ppo": ppo,
            },
            indent=1,
        )
    )
    lines = [
        f"At {commit}: `python scripts/learning_through_shield.py --seeds "
        f"{' '.join(map(str, args.seeds))}` (DAgger, {args.iterations} iterations of "
        f"{args.envs} envs x {args.horizon} steps; {args.trials} evaluation episodes, reset seeds "
        f"10000-{10000 + args.trials - 1}, deployed under rl_cbf).",
        "",
        "| method | seed | eval success (kept / last) | collisions | mean correction "
        "| executed-action error | env steps | wall (s) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        lines.append(
            f"| {r['method']} | {r['seed']} | {r['success']:.2f} (no selection) "
            f"| {r['collisions']} | {r['mean_correction']:.3f} | {r['executed_error']:.3f} "
            f"| {r['env_steps']:,} | {r['wall_s']:.0f} |"
        )
    for r in ppo:
        lines.append(
            f"| PPO default (rl_cbf) | {r['seed']} | {r['kept']:.2f} / {r['last']:.2f} "
            f"| {r['collisions']} "
            f"| {r['mean_correction']:.3f} | - | {r['env_steps']:,} | {r['wall_s']:.0f} |"
        )
    (args.out / "through_shield.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    colours = {"through": "tab:blue", "direct": "tab:orange"}
    for r in results:
        xs = [c["env_steps"] for c in r["curve"]]
        ys = [c["validation_success"] for c in r["curve"]]
        label = f"{r['method']}" if r["seed"] == args.seeds[0] else None
        ax.plot(xs, ys, marker="o", ms=3, color=colours[r["method"]], alpha=0.8, label=label)
    for r in ppo:
        xs, ys = zip(*r["curve"], strict=True) if r["curve"] else ((), ())
        label = "PPO default (rl_cbf)" if r is ppo[0] else None
        ax.plot(xs, ys, color="tab:gray", alpha=0.8, label=label)
    ax.set_xscale("log")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("validation success (20 episodes)")
    seeds = ", ".join(map(str, args.seeds))
    ax.set_title(f"Channel-v0 under rl_cbf, seeds {seeds} (validation episodes)", fontsize=9)
    ax.set_ylim(-0.05, 1.05)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out / "through_shield.png", dpi=120)
    return 0


if __name__ == "__main__":
    sys.exit(main())
