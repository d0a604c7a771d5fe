"""``tlshield benchmark safety-gym``: PPO on Safety-Gymnasium's navigation tasks, unshielded
(``rl``) and shielded (``rl_cbf``, ``rl_cbf_clf``, and the levers of :data:`VARIANTS`), beside
OmniSafe's rows.

Per (env, variant, seed) one run trains through :func:`tlshield.lab.training.prepare` and
:func:`tlshield.lab.training.learn`, as every other benchmark does, with the ``"safety-gym"``
preset (Stable-Baselines3's PPO defaults, the same for every variant) on the standard
observation of ``tlshield/<env>``. The run folder is a tlshield run folder
(:mod:`tlshield.lab.runs`): ``metrics.csv`` has the return and the cost per update, validation
on the return keeps the best policy, and the last policy is kept beside it. Both are evaluated
(:func:`tlshield.lab.evaluation.evaluate`: deterministic, each variant as it trained, ``rl``
unshielded, 1,000-step episodes). Jobs run as Ray tasks (:mod:`tlshield.lab.cluster`); a
finished job keeps its folder, so an interrupted run resumes where it stopped.

What the shield reads is the ``sensing`` column (:data:`tlshield.envs.safety_gym.env.SENSING`):
``"state"``, the privileged true state (agent pose and velocity, goal, hazards, vases), which
the policy never sees; or ``"lidar"``, the policy's own observation and nothing else. Every
table says which.

Seeds (:mod:`tlshield.lab.seeds`): training resets from ``train_seed(seed)``, validation from
``validation_seed(seed, k)``, evaluation episode ``k`` from ``EVAL_SEED + k`` (disjoint, never
used for tuning), and PPO takes ``learner_seed(seed)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from tlshield._removed import refuse
from tlshield.lab import bench
from tlshield.lab.presets import updates_for
from tlshield.lab.seeds import check_block, check_seeds

#: The default budget per env (PPO steps per agent).
DEFAULT_STEPS = {
    "SafetyPointGoal1-v0": 1_000_000,
    "SafetyPointGoal2-v0": 300_000,
    "SafetyCarGoal1-v0": 1_000_000,
}
#: The default rows: unshielded PPO, the CBF alone, and the CLF as the base controller with
#: PPO learning on top of it, each at the env's defaults (the policy acts in the robot's
#: units); and unshielded PPO in Safety-Gymnasium's own action space, the field's row.
DEFAULT_CONFIGS = ("rl", "rl+native", "rl_cbf", "rl_cbf_clf")
DEFAULT_SEEDS = (0, 1, 2)
DEFAULT_EPISODES = 10
#: What the shield reads by default (``--sensing``): MuJoCo's true state.
DEFAULT_SENSING = ("state",)
#: The ``sensing`` of an unshielded row (``rl``, ``rl+native``): no shield reads anything.
UNSHIELDED = "none"
#: The training preset (:data:`tlshield.lab.presets.PRESETS`).
PRESET = "safety-gym"


@dataclass(frozen=True)
class Variant:
    """One row of the benchmark: a shield configuration, the env's settings
    (:class:`tlshield.envs.safety_gym.SafetyGoalParams`) and PPO's (the preset's keys)."""

    config: str
    env: dict[str, Any] = field(default_factory=dict)
    ppo: dict[str, Any] = field(default_factory=dict)


#: The rows the benchmark knows, by name (``--configs``): the four configurations at the env's
#: defaults, the field's unshielded row in Safety-Gymnasium's own action space, and the levers
#: of learning through the shield, one change each (docs/guides/safety-gym.md measures them).
VARIANTS: dict[str, Variant] = {
    **{c: Variant(c) for c in ("rl", "rl_cbf", "rl_clf", "rl_cbf_clf")},
    # PPO as the field runs it: Safety-Gymnasium's action box (docs/guides/safety-gym.md).
    "rl+native": Variant("rl", env={"actions": "native"}),
    # A penalty on the shield's correction |u - u_rl| (Krasowski et al. 2023).
    "rl_cbf+penalty": Variant("rl_cbf", env={"correction_penalty": 0.01}),
    # PPO learns from the executed action, not the sampled one.
    "rl_cbf+executed": Variant("rl_cbf", ppo={"learn_from": "executed"}),
    # A residual on the CLF that starts small: the policy's std e^-1 = 0.37 of the robot's
    # range instead of 1.
    "rl_cbf_clf+small_std": Variant("rl_cbf_clf", ppo={"log_std_init": -1.0}),
    # ... and a Gaussian whose mean is tanh-bounded (tlshield.lab.policies).
    "rl_cbf_clf+small_std+tanh": Variant(
        "rl_cbf_clf", ppo={"log_std_init": -1.0, "policy": "tanh_mean"}
    ),
    # PPO learns from the executed action less the CLF's part (the residual plus the shield's
    # safety correction), so the log-probabilities describe what the robot did beyond its guide.
    "rl_cbf_clf+executed": Variant("rl_cbf_clf", ppo={"learn_from": "executed_without_clf"}),
    # The learning rate decays linearly to 0 over the run (late updates cannot undo early ones).
    "rl_cbf_clf+lr_linear": Variant("rl_cbf_clf", ppo={"lr_schedule": "linear"}),
    # An entropy bonus that decays linearly from 0.01 to 0 (explore early, settle late).
    "rl_cbf_clf+ent_linear": Variant(
        "rl_cbf_clf", ppo={"ent_coef": 0.01, "ent_schedule": "linear"}
    ),
}
#: The columns of ``safety_gym.csv``: per policy (``kept``: the best on validation, ``last``)
#: the evaluation return and cost per episode; then the update the kept policy comes from, the
#: cost summed over training and per step, and the wall time of training and evaluation.
COLUMNS = (
    "env",
    "method",
    "sensing",
    "seed",
    "steps",
    "kept_return",
    "kept_cost",
    "last_return",
    "last_cost",
    "kept_update",
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
    "SafetyCarGoal1-v0": {
        "PPO": (33.41, 58.06),
        "PPO-Lag": (13.27, 21.72),
    },
}


def folder_name(env: str, variant: str, seed: int, budget: int, sensing: str) -> str:
    """The run folder of one job under ``out/runs`` (the state mode's keeps the name it had
    before the ``sensing`` column, so that its finished jobs resume)."""
    tail = "" if sensing in ("state", UNSHIELDED) else f"-{sensing}"
    return f"{env}-{variant}-s{seed}-{budget}{tail}"


def train_and_evaluate(
    env: str,
    variant: str,
    seed: int,
    steps: int,
    episodes: int,
    folder: Path,
    sensing: str = "state",
) -> None:
    """One (env, variant, seed, sensing): a run of at least ``steps`` PPO steps trained into
    ``folder``, then ``episodes`` evaluation episodes of the kept and of the last policy;
    writes ``result.json`` last, so a folder without it is not finished (a Ray task)."""
    import time

    import torch

    from tlshield.lab.evaluation import evaluate
    from tlshield.lab.runs import load_run
    from tlshield.lab.training import learn, prepare

    torch.set_num_threads(1)
    start = time.perf_counter()
    v = VARIANTS[variant]
    # The state mode passes nothing, so its runs read as they did before the column.
    reads = {} if sensing in ("state", UNSHIELDED) else {"sensing": sensing}
    run = prepare(
        v.config,
        seed,
        updates_for(steps, PRESET),
        folder,
        progress=False,
        preset=PRESET,
        ppo=dict(v.ppo),
        env=f"tlshield/{env}",
        **v.env,
        **reads,
    )
    learn(run)
    kept = evaluate(folder, trials=episodes)
    last = evaluate(folder, trials=episodes, which="last")
    loaded = load_run(folder)
    assert loaded is not None  # prepare and learn wrote it
    metrics = loaded.metrics
    timesteps = int(metrics["timesteps"][-1])
    train_cost = float(np.nansum(metrics["cost"]))
    row = {
        "env": env,
        "method": variant,
        "sensing": sensing,
        "seed": seed,
        "steps": timesteps,
        "budget": steps,
        "kept_return": kept["return_mean"],
        "kept_cost": kept["cost_mean"],
        "last_return": last["return_mean"],
        "last_cost": last["cost_mean"],
        "kept_update": loaded.record.get("kept", {}).get("update"),
        "train_cost": train_cost,
        "train_cost_rate": train_cost / max(timesteps, 1),
        "wall_s": time.perf_counter() - start,
        "kept_returns": [o["return"] for o in kept["outcomes"]],
        "kept_costs": [o["cost"] for o in kept["outcomes"]],
        "last_returns": [o["return"] for o in last["outcomes"]],
        "last_costs": [o["cost"] for o in last["outcomes"]],
    }
    bench.write_result(folder, row)  # last: the job is finished


def safety_gym(
    out: str | Path,
    *,
    envs: Sequence[str] = tuple(DEFAULT_STEPS),
    configs: Sequence[str] = DEFAULT_CONFIGS,
    seeds: Sequence[int] = DEFAULT_SEEDS,
    sensing: Sequence[str] = DEFAULT_SENSING,
    steps: int | None = None,
    episodes: int = DEFAULT_EPISODES,
    address: str | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> Path:
    """Runs the benchmark into ``out`` (resumable: finished jobs are kept) and writes
    ``safety_gym.csv``, ``safety_gym.md`` and ``safety_gym.png``. ``steps`` overrides
    :data:`DEFAULT_STEPS` for every env; ``configs`` are names of :data:`VARIANTS`;
    ``sensing`` what the shield reads, each a row of its own."""
    from tlshield.envs.safety_gym import TASKS, load_builder
    from tlshield.envs.safety_gym.env import SENSING

    load_builder()  # a missing stack is one clear ImportError, before any job
    for e in envs:
        if e not in TASKS:
            raise ValueError(f"env {e!r}: expected one of {', '.join(TASKS)}")
    for c in configs:
        if c not in VARIANTS:
            raise ValueError(f"config {c!r}: expected one of {', '.join(VARIANTS)}")
    for m in sensing:
        if m not in SENSING:
            raise ValueError(f"sensing {m!r}: expected one of {', '.join(SENSING)}")
    if not sensing:
        raise ValueError("sensing: expected at least one of " + ", ".join(SENSING))
    check_block(episodes, "episodes")
    if steps is not None and not (isinstance(steps, int) and steps > 0):
        raise ValueError(f"steps = {steps!r}: expected a positive integer")
    check_seeds(seeds)
    out = Path(out)
    runs = out / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    jobs = {
        runs / folder_name(e, c, s, budget, m): partial(
            train_and_evaluate, e, c, s, budget, episodes, sensing=m
        )
        for e in envs
        for budget in (steps or DEFAULT_STEPS[e],)
        for c in configs
        # An unshielded row reads nothing: one job, whatever the modes.
        for m in ((UNSHIELDED,) if VARIANTS[c].config == "rl" else dict.fromkeys(sensing))
        for s in seeds
    }
    return bench.run(REPORT, out, jobs, address, workers, progress)


def _cost(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.1f}"


def _sensing(row: dict[str, Any]) -> str:
    # Rows written before the column read the true state.
    return str(row.get("sensing") or "state")


def markdown(rows: list[dict[str, Any]]) -> str:
    """The per-seed table (the kept and the last policy), then OmniSafe's rows for the same
    envs."""
    modes = {_sensing(r) for r in rows}
    reads = {
        "state": "With `sensing` = state the shield reads the privileged true state (agent pose "
        "and velocity, goal, hazards, vases), which the policy never sees.",
        "lidar": "With `sensing` = lidar the shield reads only the policy's own observation "
        "(lidars, velocimeter, magnetometer): no privileged state.",
    }
    lines = [
        "Per seed: evaluation return and cost per episode of the kept policy (the best on the "
        "validation episodes' return) and of the last one (deterministic, each variant as "
        "trained; `rl` is unshielded), the update the kept policy comes from, the cost summed "
        "over training, and the wall time of training and evaluation. The policy sees "
        "Safety-Gymnasium's standard observation. "
        + " ".join(reads[m] for m in sorted(modes) if m in reads),
        "",
        "| env | method | sensing | seed | PPO steps | kept return | kept cost | last return | "
        "last cost | kept update | train cost | train cost / step | wall (s) |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['env']} | {r['method']} | {_sensing(r)} | {r['seed']} | {r['steps']:,} | "
            f"{r['kept_return']:.2f} | {_cost(r['kept_cost'])} | {r['last_return']:.2f} | "
            f"{_cost(r['last_cost'])} | {r['kept_update']} | {r['train_cost']:.0f} | "
            f"{r['train_cost_rate']:.4f} | {r['wall_s']:.0f} |"
        )
    envs = sorted({r["env"] for r in rows})
    published = [(e, m, v) for e in envs for m, v in OMNISAFE.get(e, {}).items()]
    if published:
        like = (
            "like for like with the rows read from the lidar, not with those read from the "
            "true state"
            if "lidar" in modes
            else "not like for like"
        )
        lines += [
            "",
            "OmniSafe's published rows (1e7 steps against the budgets above, cost limit 25, "
            f"and no privileged state: {like}):",
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

    from tlshield.lab.runs import load_run

    envs = sorted({r["env"] for r in rows})
    if not envs:
        return
    fig, axes = plt.subplots(2, len(envs), figsize=(5.5 * len(envs), 6), squeeze=False)

    # A (method, sensing)'s colour.
    def key(r: dict[str, Any]) -> tuple[str, str]:
        return (r["method"], _sensing(r))

    methods = sorted({key(r) for r in rows})
    colours = {m: plt.get_cmap("tab10")(k % 10) for k, m in enumerate(methods)}
    # A method's colour, a seed's line style: the legend tells the seeds apart.
    seeds = sorted({r["seed"] for r in rows})
    styles = {s: ("-", "--", ":", "-.")[k % 4] for k, s in enumerate(seeds)}
    for j, e in enumerate(envs):
        for r in (r for r in rows if r["env"] == e):
            name = folder_name(e, r["method"], r["seed"], r["budget"], _sensing(r))
            run = load_run(out / "runs" / name)
            if run is None:
                continue
            m = run.metrics
            label = f"{r['method']} {_sensing(r)} s{r['seed']}"
            look = {"color": colours[key(r)], "ls": styles[r["seed"]], "lw": 1}
            axes[0, j].plot(m["timesteps"], m["task_return_mean"], label=label, **look)
            axes[1, j].plot(m["timesteps"], m["episode_cost_mean"], **look)
        axes[0, j].set_title(e)
        axes[0, j].set_ylabel("training return / episode")
        axes[1, j].set_ylabel("training cost / episode")
        axes[1, j].set_xlabel("PPO steps")
        for ax in axes[:, j]:
            ax.xaxis.set_major_formatter(EngFormatter())
        axes[0, j].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(out / "safety_gym.png", dpi=110)
    plt.close(fig)


#: The benchmark as data for :mod:`tlshield.lab.bench`: ``safety_gym.csv`` (:data:`COLUMNS`),
#: ``safety_gym.md`` (:func:`markdown`) and ``safety_gym.png``.
REPORT = bench.Benchmark(
    name="safety_gym",
    columns=COLUMNS,
    order=lambda r: (r["env"], r["budget"], r["method"], _sensing(r), r["seed"]),
    markdown=markdown,
    figure=_figure,
)


#: Names removed in 0.4, refused with a message naming what replaced them.
__getattr__ = refuse(
    __name__,
    {
        "read_rows": "tlshield.lab.bench.read_rows(bench, out) with bench = "
        "tlshield.lab.benchmark_safety_gym.REPORT",
        "write_report": "tlshield.lab.bench.write_report(bench, out) with bench = "
        "tlshield.lab.benchmark_safety_gym.REPORT",
    },
)
