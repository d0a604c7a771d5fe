"""The learning experiments of docs/learning.md: candidate fixes for the PPO collapse, each
trained on several seeds at the default budget, with the kept and the last policy evaluated.

    .venv/bin/python scripts/learning_experiments.py --out results_learning \\
        --variants gaussian tanh_mean squashed --configs rl_cbf_clf rl_cbf --seeds 0 1 2

Each variant is a set of training settings (:data:`VARIANTS`, names as ``tlshield train
--set``). Runs go to ``OUT/<variant>/<config>_s<seed>/`` as Ray tasks (2 at a time on 2 cores)
and finished runs are kept, so an interrupted sweep resumes. Prints, and writes to
``OUT/candidates.md``, one table of every run (:func:`table`): per variant, configuration and
seed, the kept and the last policy's evaluation success (100 trials), the best and the last
validation success, and the training violations. ``--table`` prints the table of what ``OUT``
holds for the given variants, configurations and seeds, and runs nothing.
"""

from __future__ import annotations

import argparse
from functools import partial
from pathlib import Path
from typing import Any

from tlshield.lab.cluster import run_counted
from tlshield.lab.report import seeds_table
from tlshield.lab.training import is_finished, run_job

#: Candidate settings (as ``--set NAME=VALUE``), each complete over the default preset. Issue
#: 21's: the old default was SB3's Gaussian with normalised rewards and a learning rate of
#: 3e-4; the new one is ``tanh_mean+raw+lr1e-3``. ``tanh_mean+env16`` keeps the budget with
#: ``--updates 150``. Every variant before issue 34's learns from the sampled action, as the
#: preset did then.
SAMPLED = {"learn_from": "sampled"}
OLD = {**SAMPLED, "norm_reward": True, "learning_rate": 3e-4}
VARIANTS: dict[str, dict[str, Any]] = {
    "gaussian": {**OLD, "policy": "gaussian"},
    "tanh_mean": {**OLD, "policy": "tanh_mean"},
    "squashed": {**OLD, "policy": "squashed"},
    "tanh_mean+std0.6": {**OLD, "policy": "tanh_mean", "log_std_init": -0.5},
    "tanh_mean+env16": {**OLD, "policy": "tanh_mean", "n_envs": 16},
    "tanh_mean+w0.01": {**OLD, "policy": "tanh_mean", "w": 0.01},
    "tanh_mean+raw": {
        **SAMPLED,
        "policy": "tanh_mean",
        "norm_reward": False,
        "learning_rate": 3e-4,
    },
    "tanh_mean+raw+g0.99": {
        **SAMPLED,
        "policy": "tanh_mean",
        "norm_reward": False,
        "learning_rate": 3e-4,
        "gamma": 0.99,
    },
    "tanh_mean+raw+lr1e-3": {
        **SAMPLED,
        "policy": "tanh_mean",
        "norm_reward": False,
        "learning_rate": 1e-3,
    },
    "tanh_mean+raw+lr2e-3": {
        **SAMPLED,
        "policy": "tanh_mean",
        "norm_reward": False,
        "learning_rate": 2e-3,
    },
    # Issue 34's levers (docs/learning.md), each over the default preset, which learns from
    # SB3's sampled action ("sampled" is the preset itself).
    "sampled": SAMPLED,
    "budget_x4": {**SAMPLED, "updates_scale": 4.0},
    "vec64": {**SAMPLED, "n_envs": 64, "batch_size": 2048, "updates_scale": 0.4},
    "gsde": {
        **SAMPLED,
        "policy": "gaussian",
        "use_sde": True,
        "sde_sample_freq": 4,
        "log_std_init": -2.0,
    },
    "clf_linear": {**SAMPLED, "clf_schedule": "linear"},
    "clf_exponential": {**SAMPLED, "clf_schedule": "exponential"},
    "executed": {"learn_from": "executed"},
    "executed_without_clf": {"learn_from": "executed_without_clf"},
    # Potential-based shaping towards the automaton's CLF goal (the progress reward's goal
    # term, ChannelTask.goal_weight), over the default preset: the CLF's information without
    # its push. These pin the goal term and end_on_trap (the defaults changed with them), so
    # each names the same run at any commit.
    "no_goal": {"goal_weight": 0.0, "end_on_trap": False},
    "no_goal+x2": {"goal_weight": 0.0, "end_on_trap": False, "updates_scale": 2.0},
    # The paper's shrinking CLF bounds, over the old default (it was measured there).
    "no_goal+clf_exp": {"goal_weight": 0.0, "end_on_trap": False, "clf_schedule": "exponential"},
    "goal0.25": {"goal_weight": 0.25, "end_on_trap": False},
    "goal0.5": {"goal_weight": 0.5, "end_on_trap": False},
    "goal1": {"goal_weight": 1.0, "end_on_trap": False},
    "goal0.5+x2": {"goal_weight": 0.5, "end_on_trap": False, "updates_scale": 2.0},
    "goal0.5+clf_exp": {"goal_weight": 0.5, "end_on_trap": False, "clf_schedule": "exponential"},
    # Training episodes end on entering the trap (ChannelTask.end_on_trap). With 600 updates
    # (--updates 300 x 2) this is the default.
    "goal0.5+end_on_trap+x2": {"goal_weight": 0.5, "end_on_trap": True, "updates_scale": 2.0},
    "goal0.5+end_on_trap+x3": {"goal_weight": 0.5, "end_on_trap": True, "updates_scale": 3.0},
    # The same levers on PointMass-v0, a task nothing was tuned on.
    "pm_x2": {"env": "tlshield/PointMass-v0", "goal_weight": 0.0, "updates_scale": 2.0},
    "pm_goal0.5+x2": {"env": "tlshield/PointMass-v0", "goal_weight": 0.5, "updates_scale": 2.0},
    "vec64+executed_without_clf": {
        "n_envs": 64,
        "batch_size": 2048,
        "updates_scale": 0.4,
        "learn_from": "executed_without_clf",
    },
}


def _options(variant: str) -> dict[str, Any]:
    from tlshield.lab import settings

    # "env" picks the environment (Channel-v0 unless given); the rest are training settings.
    variant_settings = VARIANTS[variant]
    options = settings.split(
        {k: v for k, v in variant_settings.items() if k not in ("updates_scale", "env")}
    )
    if "env" in variant_settings:
        options["env"] = variant_settings["env"]
    return options


def _updates(variant: str, updates: int) -> int:
    """The variant's updates: ``updates`` times its ``updates_scale`` (a variant with more
    samples per update takes fewer updates for about the same wall time)."""
    return max(1, round(updates * VARIANTS[variant].get("updates_scale", 1.0)))


def table(root: Path, variants: list[str], configs: list[str], seeds: list[int]) -> str:
    """One table of every variant's runs of ``configs`` and ``seeds``: a variant column, then
    :func:`tlshield.lab.report.seeds_table`'s columns (kept and last policy side by side)."""
    lines: list[str] = []
    for variant in variants:
        if not (root / variant).is_dir():
            continue
        head, rule, *rows = seeds_table(root / variant).splitlines()
        if not lines:
            lines = ["| variant " + head, "|---" + rule]
        for row in rows:
            cells = [c.strip() for c in row.strip("|").split("|")]
            if cells[0] in configs and int(cells[1]) in seeds:
                lines.append(f"| {variant} " + row)
    return "\n".join(lines)


def compact(root: Path, variants: list[str], configs: list[str], seeds: list[int]) -> str:
    """:func:`table` folded to one row per variant and configuration: the kept and the last
    policy's evaluation success of every seed (in ``seeds`` order), the worst kept, and the
    training violations summed over the seeds."""
    rows: dict[tuple[str, str], dict[int, list[str]]] = {}
    for line in table(root, variants, configs, seeds).splitlines()[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows.setdefault((cells[0], cells[1]), {})[int(cells[2])] = cells[3:]
    lines = [
        "| variant | config | kept policy: eval success per seed | last policy: eval success "
        "per seed | worst kept | train violations |",
        "|---|---|---|---|---:|---:|",
    ]
    for (variant, config), by_seed in rows.items():
        runs = [by_seed[s] for s in seeds if s in by_seed]
        kept = " / ".join(r[0] for r in runs)
        last = " / ".join(r[1] for r in runs)
        worst = min(float(r[0]) for r in runs)
        violations = sum(int(r[5]) for r in runs)
        lines.append(f"| {variant} | {config} | {kept} | {last} | {worst:.2f} | {violations} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results_learning")
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=["tanh_mean"])
    parser.add_argument("--configs", nargs="+", default=["rl_cbf_clf", "rl_cbf"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--updates", type=int, default=300)
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--table", action="store_true", help="only print the table of OUT")
    parser.add_argument(
        "--compact", action="store_true", help="only print OUT's table, one row per variant"
    )
    args = parser.parse_args()
    root = Path(args.out)
    if args.table or args.compact:
        show = compact if args.compact else table
        print(show(root, args.variants, args.configs, args.seeds))
        return
    jobs = {}
    for variant in args.variants:
        options = _options(variant)
        updates = _updates(variant, args.updates)
        for config in args.configs:
            for seed in args.seeds:
                folder = root / variant / f"{config}_s{seed}"
                done = (folder / "last_evaluation.json").is_file()
                if not (done and is_finished(folder, updates)):
                    jobs[folder] = partial(run_job, config, seed, updates, args.trials, options)
    run_counted(jobs, None, args.workers, True)
    text = table(root, args.variants, args.configs, args.seeds)
    (root / "candidates.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
