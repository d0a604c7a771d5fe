"""The run-folder schema and its loaders, shared by training, evaluation, the report and the
figures.

A results folder holds one run folder per configuration and seed (``<config>_s<seed>/``):

* ``run.json`` (:data:`RUN_FILE`): the run's record, what it trained with (configuration,
  seed, preset, environment overrides, PPO settings), whether it finished and which checkpoint
  was kept (``config.json`` in folders written by tlshield 0.1, still read);
* ``metrics.csv``: one row per PPO update (:func:`metric_columns`, with a ``min_h_<name>``
  column per constraint the environment reports; Channel-v0's are :data:`METRIC_COLUMNS`),
  written as it goes;
* ``model.zip`` (SB3) with ``normalization.json`` (observation statistics: ``obs_mean``,
  ``obs_var``, ``epsilon``, ``clip_obs``), the kept policy, and ``last_model.zip`` with
  ``last_normalization.json``, the last one; read without unpickling (:mod:`tlshield.lab.saved`);
* after evaluation, ``evaluation.json`` (totals and one record per trial: reset seed, success,
  collision, steps, violating steps) and ``trajectories.npz`` (each trial's start state, agent
  path and obstacle paths), and ``last_evaluation.json`` / ``last_trajectories.npz`` for the
  last policy.

Any of the last three may be missing, empty or partial (an interrupted run): the loaders leave
out what is not there, never an error.
"""

from __future__ import annotations

import csv
import json
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tlshield.envs import ENV_ID
from tlshield.envs.channel import CONFIGS
from tlshield.envs.layout import STATE_DIM
from tlshield.envs.params import flat_names, from_flat, upgrade
from tlshield.envs.profile import profile_of

__all__ = [
    "DIAGNOSTIC_COLUMNS",
    "GIVE_WAY_COLUMNS",
    "METRIC_COLUMNS",
    "RETURN_COLUMNS",
    "RUN_FILE",
    "Run",
    "is_finished",
    "load_results",
    "load_run",
    "metric_columns",
    "read_record",
    "record_path",
]

#: The run's record in a run folder. "config" means one thing in tlshield, a configuration of
#: the shield (rl, rl_cbf, rl_clf, rl_cbf_clf), so the file is no longer ``config.json``.
RUN_FILE = "run.json"
#: The record's name in run folders written by tlshield 0.1 (still read).
OLD_RUN_FILE = "config.json"


def record_path(folder: str | Path) -> Path:
    """The record of the run in ``folder``: ``run.json``, else a 0.1 folder's ``config.json``
    (``run.json``, which may not exist, when neither does)."""
    folder = Path(folder)
    new = folder / RUN_FILE
    old = folder / OLD_RUN_FILE
    return old if not new.is_file() and old.is_file() else new


#: Diagnostics of learning, per update (the last columns of metrics.csv; NaN in older runs):
#: the policy's std per action dimension (of the Gaussian before any squashing), the fraction
#: of sampled actions outside the action box, the mean norm of the shield's correction
#: ``|a_applied - a_rl|`` (physical units), the fraction of relaxed or inaccurate QPs, and
#: PPO's statistics of the gradient step that preceded the update's rollout (approx_kl,
#: clip_fraction, explained_variance, value_loss, entropy_loss; NaN before the first step).
DIAGNOSTIC_COLUMNS = (
    "policy_std_0",
    "policy_std_1",
    "out_of_box",
    "mean_correction",
    "relaxed_rate",
    "approx_kl",
    "clip_fraction",
    "explained_variance",
    "value_loss",
    "entropy_loss",
)
#: Return and cost, per update (the last columns of metrics.csv; NaN in older runs, and cost
#: NaN where the environment reports none): the mean undiscounted return of the episodes that
#: ended in the update (the task's own reward, ``info["task_reward"]`` where an env shapes
#: it), their mean cost (``info["cost"]``), the cost summed over every step of the update, and
#: the validation episodes' mean return and cost (NaN when the update did not validate).
RETURN_COLUMNS = (
    "task_return_mean",
    "episode_cost_mean",
    "cost",
    "validation_return",
    "validation_cost",
)
#: Give-ways, per update: the steps whose QP was relaxed and named a barrier that gave way
#: (``info["shield"]["gave_way"]``; by barrier over the whole run: ``run.json``'s
#: ``gave_way``). NaN in older runs.
GIVE_WAY_COLUMNS = ("gave_way",)
#: Columns that came later: a run written before them reads them as NaN.
_LATER_COLUMNS = (*DIAGNOSTIC_COLUMNS, *RETURN_COLUMNS, *GIVE_WAY_COLUMNS)
#: The columns of metrics.csv before the constraint columns.
_HEAD_COLUMNS = ("update", "timesteps", "episodes", "return_mean", "return_std")
#: The columns of metrics.csv after the constraint columns.
_TAIL_COLUMNS = (
    "min_obstacle_distance",
    "violations",
    "trap_entries",
    "successes",
    "relaxed",
    "failed",
    "clf_scale",
    "validation_success",
    "wall_time",
    *DIAGNOSTIC_COLUMNS,
    *RETURN_COLUMNS,
    *GIVE_WAY_COLUMNS,
)


def metric_columns(constraints: Sequence[str]) -> tuple[str, ...]:
    """The columns of metrics.csv, in order, for an environment that reports ``constraints``
    (the names of its ``info["constraints"]``): one ``min_h_<name>`` column each, the smallest
    value of that constraint in the update."""
    return (*_HEAD_COLUMNS, *(f"min_h_{name}" for name in constraints), *_TAIL_COLUMNS)


#: The columns of metrics.csv for Channel-v0 (constraints ``c1``, ``c2``), in order.
METRIC_COLUMNS = metric_columns(("c1", "c2"))


@dataclass
class Run:
    """One run folder of a results folder."""

    #: The run folder.
    path: Path
    #: Configuration name ("rl", "rl_cbf", "rl_clf", "rl_cbf_clf").
    config: str
    #: Training seed.
    seed: int
    #: metrics.csv by column (:func:`tlshield.lab.runs.metric_columns`), one value per update;
    #: every array is empty when the run has no complete row yet.
    metrics: dict[str, NDArray[np.float64]]
    #: evaluation.json, or None when the run was not evaluated.
    evaluation: dict[str, Any] | None
    #: ``(starts, paths)`` of trajectories.npz: the ``(trials, 13)`` initial states and one
    #: ``(length, 2)`` xy path per trial; None when missing.
    trajectories: tuple[NDArray[np.float64], list[NDArray[np.float64]]] | None
    #: The whole record (run.json).
    record: dict[str, Any] = field(default_factory=dict)
    #: One ``(length, 4)`` path of the two obstacle centres per trial (None when missing).
    obstacle_paths: list[NDArray[np.float64]] | None = None
    #: last_evaluation.json (the last policy, beside the kept one), or None.
    last_evaluation: dict[str, Any] | None = None

    @property
    def updates(self) -> int:
        """Number of complete metric rows (PPO updates)."""
        return len(self.metrics["update"])

    @property
    def env(self) -> Any:
        """The environment constants the run trained with, as its env's parameters class
        (:mod:`tlshield.envs.profile`; defaults for missing fields); None for an env whose
        profile names no parameters class."""
        return _env_params(self.record)


def json_tuples(value: Any) -> Any:
    """JSON lists back into the (nested) tuples the parameters dataclasses hold."""
    return tuple(json_tuples(v) for v in value) if isinstance(value, list) else value


def _env_params(record: dict[str, Any]) -> Any:
    cls = profile_of(str(record.get("env_id", ENV_ID))).params_class()
    if cls is None:
        return None
    env = record.get("env")
    # A 0.1 record spells some parameters the old way: read them as data, without a warning.
    env = upgrade(env, "run record", from_file=True) if isinstance(env, dict) else {}
    known = set(flat_names(cls))
    values = {k: json_tuples(v) for k, v in env.items() if k in known}
    try:
        return from_flat(cls, values)
    except TypeError:  # pragma: no cover - a record from an incompatible version
        return cls()


def _read_metrics(path: Path) -> dict[str, NDArray[np.float64]]:
    """metrics.csv by column (its own constraint columns; Channel-v0's when it has no header);
    tolerates a missing or empty file and a last row cut short."""
    rows: list[list[float]] = []
    columns = METRIC_COLUMNS
    if path.is_file():
        with path.open(newline="") as f:
            reader = csv.DictReader(f)
            header = reader.fieldnames or []
            if header:
                constraints = [c[len("min_h_") :] for c in header if c.startswith("min_h_")]
                columns = metric_columns(constraints)
            for row in reader:
                try:
                    # Some columns came later: older runs read them as NaN.
                    rows.append(
                        [
                            float(row.get(c) or "nan") if c in _LATER_COLUMNS else float(row[c])
                            for c in columns
                        ]
                    )
                except (KeyError, TypeError, ValueError):
                    continue  # an incomplete row (the run was stopped while writing it)
    table = np.array(rows, dtype=np.float64).reshape(len(rows), len(columns))
    return {c: table[:, i].copy() for i, c in enumerate(columns)}


def _read_json(path: Path) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        warnings.warn(f"{path}: unreadable ({err}); ignoring it", RuntimeWarning, stacklevel=3)
        return None
    return data if isinstance(data, dict) else None


def _read_trajectories(
    path: Path,
) -> tuple[NDArray[np.float64], list[NDArray[np.float64]]] | None:
    if not path.is_file():
        return None
    try:
        with np.load(path) as data:
            starts = np.asarray(data["starts"], dtype=np.float64)
            lengths = np.asarray(data["lengths"], dtype=np.int64)
            flat = np.asarray(data["paths"], dtype=np.float64)
    except (OSError, ValueError, KeyError) as err:
        warnings.warn(f"{path}: unreadable ({err}); ignoring it", RuntimeWarning, stacklevel=3)
        return None
    if (
        starts.ndim != 2
        or starts.shape[1] < STATE_DIM
        or lengths.shape != (len(starts),)
        or flat.ndim != 2
        or flat.shape[1] != 2
        or int(lengths.sum()) != len(flat)
    ):
        warnings.warn(f"{path}: inconsistent arrays; ignoring it", RuntimeWarning, stacklevel=3)
        return None
    paths = np.split(flat, np.cumsum(lengths)[:-1]) if len(lengths) else []
    return starts, list(paths)


def _read_obstacle_paths(path: Path, lengths: list[int]) -> list[NDArray[np.float64]] | None:
    if not path.is_file():
        return None
    try:
        with np.load(path) as data:
            if "obstacle_paths" not in data:
                return None
            flat = np.asarray(data["obstacle_paths"], dtype=np.float64)
    except (OSError, ValueError) as err:
        warnings.warn(f"{path}: unreadable ({err}); ignoring it", RuntimeWarning, stacklevel=3)
        return None
    if flat.ndim != 2 or flat.shape[1] != 4 or len(flat) != sum(lengths):
        return None
    return list(np.split(flat, np.cumsum(lengths)[:-1])) if lengths else []


def load_run(folder: str | Path) -> Run | None:
    """The run in ``folder``; None when it has no readable record (``run.json``)."""
    folder = Path(folder)
    record = _read_json(record_path(folder))
    if record is None or "config" not in record:
        return None
    try:
        seed = int(record.get("seed", 0))
    except (TypeError, ValueError):
        seed = 0
    trajectories = _read_trajectories(folder / "trajectories.npz")
    lengths = [len(p) for p in trajectories[1]] if trajectories else []
    return Run(
        path=folder,
        config=str(record["config"]),
        seed=seed,
        metrics=_read_metrics(folder / "metrics.csv"),
        evaluation=_read_json(folder / "evaluation.json"),
        trajectories=trajectories,
        record=record,
        obstacle_paths=_read_obstacle_paths(folder / "trajectories.npz", lengths),
        last_evaluation=_read_json(folder / "last_evaluation.json"),
    )


def _config_order(config: str) -> tuple[int, str]:
    known = list(CONFIGS)
    return (known.index(config), "") if config in known else (len(known), config)


def load_results(results: str | Path) -> dict[str, list[Run]]:
    """The runs of a results folder: configuration -> runs sorted by seed, configurations in
    the paper's order ("rl", "rl_cbf", "rl_clf", "rl_cbf_clf", then any other).

    A run is a sub-folder with a record (``run.json``; ``results`` itself counts when it is a run
    folder). Raises FileNotFoundError when the folder does not exist or holds no run.
    """
    root = Path(results)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such results folder")
    folders = [root] if record_path(root).is_file() else sorted(root.iterdir())
    runs = [run for folder in folders if folder.is_dir() and (run := load_run(folder))]
    if not runs:
        raise FileNotFoundError(
            f"{root}: no runs found (expected sub-folders <config>_s<seed>/ with a run.json, "
            "as written by `tlshield reproduce --out`)"
        )
    grouped: dict[str, list[Run]] = {}
    for run in sorted(runs, key=lambda r: (_config_order(r.config), r.seed, r.path.name)):
        grouped.setdefault(run.config, []).append(run)
    return grouped


def read_record(run: str | Path) -> dict[str, Any]:
    """The run's record, ``run.json`` (FileNotFoundError or ValueError with a clear message)."""
    path = record_path(run)
    if not path.is_file():
        raise FileNotFoundError(f"{run}: not a tlshield run folder (no {RUN_FILE})")
    try:
        record = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{path}: not JSON ({err})") from None
    if not isinstance(record, dict) or "config" not in record:
        raise ValueError(f'{path}: not a run\'s record (no "config" entry)')
    return record


def is_finished(folder: str | Path, updates: int) -> bool:
    """Whether the run in ``folder`` finished training ``updates`` updates."""
    try:
        record = read_record(folder)
    except FileNotFoundError:
        return False
    return bool(record.get("finished")) and record.get("updates") == updates
