"""The results table of a results folder (``results.md``): training and evaluation per
configuration, mean +- std over seeds (population standard deviation, ``ddof=0``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tlshield.lab import measures
from tlshield.lab.runs import Run, load_results

__all__ = ["SEED_COLUMNS", "TABLE_COLUMNS", "results_table", "seeds_table"]

#: Header of :func:`results_table`.
TABLE_COLUMNS = (
    "config",
    "seeds",
    "updates",
    "train violations",
    "trap entries",
    "relaxed / failed QPs",
    "return, first 20%",
    "return, last 10%",
    "eval success rate",
    "eval collisions",
    "eval violation steps",
)
_MISSING = "—"

#: Header of :func:`seeds_table`.
SEED_COLUMNS = (
    "config",
    "seed",
    "kept policy: eval success",
    "last policy: eval success",
    "best validation",
    "last validation",
    "kept update",
    "train violations",
)


def seed_stat(values: Sequence[float]) -> tuple[float, float] | None:
    """Mean and std over seeds of the finite values; None when there is none."""
    finite = [v for v in values if math.isfinite(v)]
    if not finite:
        return None
    return float(np.mean(finite)), float(np.std(finite))


def _fraction_mean(values: NDArray[np.float64], fraction: float, first: bool) -> float:
    """Mean of the finite values among the first (or last) ``fraction`` of ``values``."""
    if len(values) == 0:
        return math.nan
    k = max(1, math.ceil(fraction * len(values)))
    part = values[:k] if first else values[-k:]
    part = part[np.isfinite(part)]
    return float(np.mean(part)) if len(part) else math.nan


def _pm(stat: tuple[float, float] | None, digits: int) -> str:
    if stat is None:
        return _MISSING
    mean, std = stat
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def trials_note(evaluations: Sequence[dict[str, Any]]) -> str:
    """ "2 x 100 trials" (or the total when the seeds differ)."""
    trials = [int(e.get("trials", 0)) for e in evaluations]
    if len(set(trials)) == 1:
        return f"{len(trials)} x {trials[0]} trials"
    return f"{sum(trials)} trials"


def results_table(results: str | Path) -> str:
    """A Markdown table of a results folder, one row per configuration (columns:
    :data:`TABLE_COLUMNS`).

    Training columns sum over every update of every seed (violations are environment steps
    outside the channel; relaxed / failed count shield QPs). Returns are the mean discounted
    episode return over the first 20% and the last 10% of each seed's updates, then mean +- std
    over seeds. Evaluation columns: success rate mean +- std over the evaluated seeds (with the
    number of trials), collisions out of all trials, and the steps outside the channel.
    """
    groups = load_results(results)
    lines = [
        "| " + " | ".join(TABLE_COLUMNS) + " |",
        "|" + "|".join(["---"] + ["---:"] * (len(TABLE_COLUMNS) - 1)) + "|",
    ]
    for config, runs in groups.items():
        counts = sorted({r.updates for r in runs})
        updates = str(counts[0]) if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
        trained = [r for r in runs if r.updates > 0]

        def total(column: str, trained: list[Run] = trained) -> str:
            if not trained:
                return _MISSING
            return str(int(sum(np.nansum(r.metrics[column]) for r in trained)))

        first = seed_stat([_fraction_mean(r.metrics["return_mean"], 0.2, True) for r in trained])
        final = seed_stat([_fraction_mean(r.metrics["return_mean"], 0.1, False) for r in trained])
        evaluations = [r.evaluation for r in runs if r.evaluation is not None]
        if evaluations:
            rate = seed_stat([float(e.get("success_rate", math.nan)) for e in evaluations])
            success = f"{_pm(rate, 2)} ({trials_note(evaluations)})"
            trials = sum(int(e.get("trials", 0)) for e in evaluations)
            hits = measures.total([e.get("collisions", 0) for e in evaluations])
            collisions = f"{measures.shown(hits)} / {trials}"
            steps = measures.total([e.get("violation_steps", 0) for e in evaluations])
            violation_steps = measures.shown(steps)
        else:
            success = collisions = violation_steps = _MISSING
        relaxed_failed = f"{total('relaxed')} / {total('failed')}" if trained else _MISSING
        cells = (
            config,
            ", ".join(str(r.seed) for r in runs),
            updates,
            total("violations"),
            total("trap_entries"),
            relaxed_failed,
            _pm(first, 1),
            _pm(final, 1),
            success,
            collisions,
            violation_steps,
        )
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _rate(evaluation: dict[str, Any] | None) -> str:
    return _MISSING if evaluation is None else f"{float(evaluation['success_rate']):.2f}"


def seeds_table(results: str | Path) -> str:
    """A Markdown table of a results folder, one row per run (columns :data:`SEED_COLUMNS`):
    the evaluation success of the kept policy (the best validated) and of the last one side by
    side, so that a checkpoint choice can never hide a collapse; the best and the last
    validation success; the update of the kept policy; the training violations."""
    lines = [
        "| " + " | ".join(SEED_COLUMNS) + " |",
        "|" + "|".join(["---", "---:"] + ["---:"] * (len(SEED_COLUMNS) - 2)) + "|",
    ]
    for config, runs in load_results(results).items():
        for run in runs:
            val = run.metrics["validation_success"]
            val = val[np.isfinite(val)]
            kept = run.record.get("kept", {}).get("update", "last") if run.updates else _MISSING
            cells = (
                config,
                str(run.seed),
                _rate(run.evaluation),
                _rate(run.last_evaluation),
                f"{val.max():.2f}" if len(val) else _MISSING,
                f"{val[-1]:.2f}" if len(val) else _MISSING,
                str(kept),
                str(int(np.nansum(run.metrics["violations"]))) if run.updates else _MISSING,
            )
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
