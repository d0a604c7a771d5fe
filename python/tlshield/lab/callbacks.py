"""The training loop's callbacks, in the style of SB3's own ``callbacks.py``: per-step metrics,
the CLF-bound schedule, validation (the kept checkpoint) and one ``metrics.csv`` row per update;
and, as an option, learning from the executed action (:class:`ExecutedActions`).
Importing this module loads SB3 (and torch); :func:`tlshield.lab.training.train` does so when it
trains."""

from __future__ import annotations

import collections
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from tlshield.codes import Status
from tlshield.envs.profile import profile_of
from tlshield.lab.evaluation import rollouts
from tlshield.lab.measures import step_violation
from tlshield.lab.metrics_log import record_row, run_logger
from tlshield.lab.presets import clf_scale
from tlshield.lab.runs import metric_columns
from tlshield.lab.saved import save_normalization
from tlshield.lab.seeds import validation_seed


@dataclass
class TrainingRun:
    """What the callback of one run needs: its folder and record, the model and the
    environments, and the run's settings."""

    folder: Path
    record: dict[str, Any]
    model: Any
    venv: Any  # VecNormalize over ``inner``
    inner: Any
    env_id: str
    config: str
    params: Any  # the environment's parameters (None for a user's env)
    seed: int
    updates: int
    overrides: dict[str, Any]
    clf_schedule: str
    clf_final_scale: float
    #: Applies a CLF-box scale to the training environments' shields (None: nothing to scale;
    #: :func:`tlshield.lab.training.prepare` builds it for the env that has one).
    rescale_clf: Callable[[float], Any] | None
    validate_every: int | None
    validation_trials: int
    on_update: Callable[[dict[str, float]], Any] | None
    progress: bool


class UpdateMetrics:
    """Accumulates one update's statistics from the step infos (raw rewards)."""

    def __init__(self, n_envs: int, gamma: float) -> None:
        self.gamma = gamma
        self.discounted = np.zeros(n_envs)
        self.discount = np.ones(n_envs)
        # The episode so far, undiscounted: the task's own reward and cost.
        self.task_return = np.zeros(n_envs)
        self.episode_cost = np.zeros(n_envs)
        self.was_trapped = np.zeros(n_envs, dtype=bool)
        #: Whether the episode so far touched an obstacle (``info["collision"]``).
        self.touched = np.zeros(n_envs, dtype=bool)
        self.reset_update()

    def reset_update(self) -> None:
        self.returns: list[float] = []
        #: Per finished episode, the task's own reward (``info["task_reward"]``, else the
        #: reward) and the cost (``info["cost"]``) summed without discount.
        self.task_returns: list[float] = []
        self.episode_costs: list[float] = []
        self.cost: float | None = None  # None: no step reported a cost
        #: Per constraint the env reports (``info["constraints"]``), its smallest value.
        self.min_h: dict[str, float] = {}
        self.min_d = math.inf
        self.violations: int | None = None  # None: nothing in the infos measured one
        self.trap_entries = self.successes = 0
        self.relaxed = self.failed = self.steps = 0
        self.correction = 0.0
        #: Per barrier, the steps of this update on which it gave way.
        self.gave_way: collections.Counter[str] = collections.Counter()

    def step(self, rewards: np.ndarray, dones: np.ndarray, infos: list[dict[str, Any]]) -> None:
        self.discounted += self.discount * rewards
        self.discount *= self.gamma
        for i, info in enumerate(infos):
            self.task_return[i] += float(info.get("task_reward", rewards[i]))
            if "cost" in info:
                self.cost = (self.cost or 0.0) + float(info["cost"])
                self.episode_cost[i] += float(info["cost"])
            for name, h in info.get("constraints", {}).items():
                self.min_h[name] = min(self.min_h.get(name, math.inf), h)
            self.min_d = min(self.min_d, info.get("min_obstacle_distance", math.inf))
            violation = step_violation(info, bool(self.was_trapped[i]))
            if violation is not None:
                self.violations = (self.violations or 0) + int(violation)
            self.trap_entries += info["trap"] and not self.was_trapped[i]
            self.was_trapped[i] = info["trap"]
            self.touched[i] |= bool(info.get("collision", False))
            # An episode that touched an obstacle is never a success.
            self.successes += bool(info["success"]) and not self.touched[i]
            shield = info.get("shield", {})
            status = shield.get("status")
            self.relaxed += status in (Status.RELAXED, Status.INACCURATE)
            self.failed += status == Status.FAILED
            if shield.get("gave_way") is not None:
                self.gave_way[str(shield["gave_way"][0])] += 1
            self.steps += 1
            if "a_cbf" in shield:  # |a_applied - a_rl|: what the shield and the CLF overruled
                self.correction += float(np.linalg.norm(shield["a_cbf"] + shield["a_clf"]))
            if dones[i]:
                self.returns.append(float(self.discounted[i]))
                self.task_returns.append(float(self.task_return[i]))
                self.episode_costs.append(float(self.episode_cost[i]))
                self.discounted[i], self.discount[i] = 0.0, 1.0
                self.task_return[i] = self.episode_cost[i] = 0.0
                self.was_trapped[i] = self.touched[i] = False


def _measured(value: float) -> float:
    """A running minimum as a metric: NaN when no step measured it (still infinite)."""
    return math.nan if math.isinf(value) else value


def _mean(values: list[float]) -> float:
    """The mean of a metric's values, NaN when there are none (no episode ended)."""
    return float(np.mean(values)) if values else math.nan


def metrics_text(count: float) -> str:
    """A count column as the progress bar shows it ("n/a": not measured)."""
    return "n/a" if math.isnan(count) else str(int(count))


class RunTotals:
    """What the progress bar shows of the run so far: the mean return of the last
    :attr:`RECENT` episodes (whichever updates they ended in: an update where none ended shows
    the last ones, not NaN) and the violating, relaxed and failed steps since the start (not
    only the last update's)."""

    #: Episodes the shown return averages.
    RECENT = 20

    def __init__(self) -> None:
        self.returns: collections.deque[float] = collections.deque(maxlen=self.RECENT)
        self.violations = math.nan  # NaN until an update measures them
        self.relaxed = 0
        self.failed = 0
        #: Per barrier, the steps on which it gave way since the start.
        self.gave_way: collections.Counter[str] = collections.Counter()

    def add(self, row: dict[str, Any]) -> dict[str, str]:
        """Adds an update's row (``returns``: the episodes that ended in it); returns the
        bar's postfix."""
        if not math.isnan(row["violations"]):
            self.violations = (0 if math.isnan(self.violations) else self.violations) + row[
                "violations"
            ]
        self.relaxed += int(row["relaxed"])
        self.failed += int(row["failed"])
        ret = f"{np.mean(self.returns):.1f}" if self.returns else "-"
        return {
            "ret": ret,
            "viol": metrics_text(self.violations),
            "relaxed": str(self.relaxed),
            "failed": str(self.failed),
            "gave_way": str(sum(self.gave_way.values())),
        }


def diagnostics(model: Any, metrics: UpdateMetrics) -> dict[str, float]:
    """The learning diagnostics of one update (:data:`tlshield.lab.runs.DIAGNOSTIC_COLUMNS`): the
    policy's std per dimension (under gSDE, the root mean square of its noise weights' stds),
    the sampled actions outside the box, the shield's mean
    correction and relaxed rate, and the statistics of PPO's last gradient step (logged by SB3
    before this rollout; NaN before the first)."""
    import torch

    log_std = getattr(model.policy, "log_std", None)
    std = torch.exp(log_std).detach().cpu().numpy() if log_std is not None else np.array([])
    if std.ndim == 2:  # gSDE: the std of each (latent feature, action) noise weight
        std = np.sqrt(np.mean(std**2, axis=0))
    actions = np.asarray(model.rollout_buffer.actions).reshape(-1, model.action_space.shape[0])
    low, high = model.action_space.low, model.action_space.high
    logged = model.logger.name_to_value
    steps = max(metrics.steps, 1)
    return {
        "policy_std_0": float(std[0]) if len(std) > 0 else math.nan,
        "policy_std_1": float(std[1]) if len(std) > 1 else math.nan,
        "out_of_box": float(np.mean(np.any((actions < low) | (actions > high), axis=1))),
        "mean_correction": metrics.correction / steps,
        "relaxed_rate": metrics.relaxed / steps,
        **{
            name: float(logged.get(f"train/{name}", math.nan))
            for name in (
                "approx_kl",
                "clip_fraction",
                "explained_variance",
                "value_loss",
                "entropy_loss",
            )
        },
    }


class ClfSchedule(BaseCallback):  # type: ignore[misc]
    """The CLF-bound schedule: before each rollout, the CLF box of the training environments'
    shield is scaled as :func:`tlshield.lab.presets.clf_scale` says for the progress so far."""

    def __init__(self, run: TrainingRun) -> None:
        super().__init__()
        self.run = run
        self.update = 0
        #: The scale of the rollout under way.
        self.scale = 1.0

    def _on_rollout_start(self) -> None:
        run = self.run
        self.scale = clf_scale(
            run.clf_schedule, self.update / max(run.updates - 1, 1), run.clf_final_scale
        )
        if run.rescale_clf is not None:
            run.rescale_clf(self.scale)

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        self.update += 1


class EntropySchedule(BaseCallback):  # type: ignore[misc]
    """PPO's entropy coefficient decayed linearly from ``start`` to 0 over ``updates``
    updates (setting ``ent_schedule="linear"``): set before each rollout, which the update
    that follows it reads."""

    def __init__(self, start: float, updates: int) -> None:
        super().__init__()
        self.start, self.updates, self.update = start, updates, 0

    def _on_rollout_start(self) -> None:
        self.model.ent_coef = self.start * (1.0 - self.update / max(self.updates, 1))

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        self.update += 1


class Validation(BaseCallback):  # type: ignore[misc]
    """Every ``validate_every`` updates, the validation episodes of the deterministic policy;
    the best so far (ties: the later) is saved as the run's kept model. Best means the highest
    success rate, or, for an env whose profile is ``scored_by_return``, the highest mean
    return (its cost is recorded beside it)."""

    def __init__(self, run: TrainingRun) -> None:
        super().__init__()
        self.run = run
        self.update = 0
        self.best = -math.inf
        #: This update's validation success, return and cost (NaN when it did not validate).
        self.last = self.last_return = self.last_cost = math.nan

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        self.update += 1
        self.last = self.last_return = self.last_cost = math.nan
        run = self.run
        if run.validate_every and self.update % run.validate_every == 0:
            self._validate()

    def _validate(self) -> None:
        run = self.run
        trials = run.validation_trials
        seeds = [validation_seed(run.seed, i) for i in range(trials)]
        model, venv = run.model, run.venv

        def policy(obs: np.ndarray) -> np.ndarray:
            return model.predict(venv.normalize_obs(obs), deterministic=True)[0]

        outcomes = rollouts(run.config, run.overrides, policy, seeds, run.env_id)
        self.last = sum(o["success"] for o in outcomes) / trials
        self.last_return = float(np.mean([o["return"] for o in outcomes]))
        costs = [o["cost"] for o in outcomes if o["cost"] is not None]
        self.last_cost = float(np.mean(costs)) if costs else math.nan
        by_return = profile_of(run.env_id).scored_by_return
        score = self.last_return if by_return else self.last
        if score >= self.best:
            self.best = score
            model.save(run.folder / "model.zip")
            save_normalization(venv, run.folder / "normalization.json")
            kept = {"update": self.update, "validation_success": self.last}
            if by_return:
                kept |= {"validation_return": self.last_return, "validation_cost": self.last_cost}
            run.record["kept"] = kept


class UpdateLog(BaseCallback):  # type: ignore[misc]
    """Collects the metrics of every step; per update, records a row in the model's SB3 logger
    (:mod:`tlshield.lab.metrics_log`: ``metrics.csv`` and TensorBoard), calls
    ``run.on_update`` and moves the progress bar. It reads the update's CLF
    scale and validation from the callbacks that own them. The constraint columns
    (``min_h_<name>``) are the constraints the environment reports at reset
    (``info["constraints"]``), in its order: names come from the env, none from here."""

    def __init__(self, run: TrainingRun, schedule: ClfSchedule, validation: Validation) -> None:
        super().__init__()
        self.run = run
        self.schedule, self.validation = schedule, validation
        self.update = 0
        self.start = time.perf_counter()
        self.logger_set = False
        self.bar: Any = None
        self.totals = RunTotals()

    def _init_callback(self) -> None:
        from tqdm.auto import tqdm

        run = self.run
        self.metrics = UpdateMetrics(run.inner.num_envs, run.model.gamma)
        # SB3 resets the environments before it initialises the callbacks.
        reset_info = (getattr(run.inner, "reset_infos", None) or [{}])[0]
        self.constraints = [str(name) for name in reset_info.get("constraints", {})]
        # metrics.csv and TensorBoard are the outputs of the model's SB3 logger: this callback
        # records each update's row there, and SB3 writes it when it dumps its own values.
        run.model.set_logger(run_logger(run.folder, metric_columns(self.constraints)))
        self.logger_set = True
        self.bar = tqdm(
            total=run.updates,
            desc=f"{run.config} seed {run.seed}",
            unit="update",
            disable=not run.progress,
            leave=False,
        )

    def elapsed(self) -> float:
        """Seconds since the run started."""
        return time.perf_counter() - self.start

    def close(self) -> None:
        """Closes the logger's outputs (metrics.csv, TensorBoard) and the progress bar (the run
        is over)."""
        if self.bar is not None:
            self.bar.close()
        if self.logger_set:
            self.run.model.logger.close()

    def _on_step(self) -> bool:
        raw = self.run.venv.get_original_reward()  # metrics in raw units, not normalised
        self.metrics.step(raw, self.locals["dones"], self.locals["infos"])
        return True

    def _on_rollout_end(self) -> None:
        self.update += 1
        metrics = self.metrics
        returns = metrics.returns
        row = {
            "update": self.update,
            "timesteps": self.num_timesteps,
            "episodes": len(returns),
            "return_mean": float(np.mean(returns)) if returns else math.nan,
            "return_std": float(np.std(returns)) if returns else math.nan,
            # Not measured (no step reported it): NaN, never a value that looks safe.
            **{
                f"min_h_{name}": _measured(metrics.min_h.get(name, math.inf))
                for name in self.constraints
            },
            "min_obstacle_distance": _measured(metrics.min_d),
            "violations": math.nan if metrics.violations is None else metrics.violations,
            "trap_entries": metrics.trap_entries,
            "successes": metrics.successes,
            "relaxed": metrics.relaxed,
            "failed": metrics.failed,
            "clf_scale": self.schedule.scale,
            "validation_success": self.validation.last,
            "wall_time": self.elapsed(),
            **diagnostics(self.model, metrics),
            "task_return_mean": _mean(metrics.task_returns),
            "episode_cost_mean": _mean(metrics.episode_costs)
            if metrics.cost is not None
            else math.nan,
            "cost": math.nan if metrics.cost is None else metrics.cost,
            "validation_return": self.validation.last_return,
            "validation_cost": self.validation.last_cost,
            "gave_way": sum(metrics.gave_way.values()),
        }
        record_row(self.logger, row)
        if self.run.on_update is not None:
            self.run.on_update(row)
        self.totals.returns.extend(returns)
        self.totals.gave_way.update(metrics.gave_way)
        metrics.reset_update()
        self.bar.update(1)
        self.bar.set_postfix(self.totals.add(row))


class TrainingCallback(CallbackList):  # type: ignore[misc]
    """One run's callbacks composed as SB3 composes them: the CLF schedule, validation with
    the kept checkpoint, then the update log (which reads both)."""

    def __init__(self, run: TrainingRun) -> None:
        self.schedule = ClfSchedule(run)
        self.validation = Validation(run)
        self.log = UpdateLog(run, self.schedule, self.validation)
        super().__init__([self.schedule, self.validation, self.log])

    def elapsed(self) -> float:
        """Seconds since the run started."""
        return self.log.elapsed()

    def gave_way(self) -> dict[str, int]:
        """Per barrier, the training steps (of finished updates) on which it gave way."""
        return dict(self.log.totals.gave_way)

    def close(self) -> None:
        """Closes the metrics file and the progress bar (the run is over)."""
        self.log.close()


class ExecutedActions(BaseCallback):  # type: ignore[misc]
    """PPO learns from the action the environment executed instead of the one it sampled.

    After each step, the rollout's sampled actions are replaced, in place, by the executed ones
    (``info["action"]``, mapped back to the policy's units). At the rollout's end, before PPO
    trains, their log-likelihoods under the policy that sampled them replace the sampled
    actions' (one batched pass: the policy does not change during a rollout), so that the
    ratio PPO clips is the ratio of what was done. With ``without_clf``, the CLF's part of the
    correction (``info["shield"]["a_clf"]``) is taken out first: the policy learns the shield's
    safety correction, while the CLF stays a guide of the environment (learning the CLF's push
    as its own action makes the CLF push again on top of it). The map back is the env's
    ``env_action`` (Safety-Gymnasium: ``info["action"]`` is already in the policy's units),
    the inverse of its ``rl_action`` (affine per dimension: Channel-v0), or the identity for an
    env whose actions are already in the shield's units (PointMass-v0)."""

    def __init__(self, inner: Any, without_clf: bool = False) -> None:
        super().__init__()
        self.without_clf = without_clf
        m = inner.action_space.shape[0]
        self.centre, self.half = np.zeros(m), np.ones(m)
        # An env whose policy acts in other units than the shield's says how to map the
        # shield's input back: Safety-Gymnasium's env_action (linear), or Channel-v0's
        # rl_action (affine, inverted here).
        self.env_action: Any = None
        try:
            self.env_action = inner.get_attr("env_action", [0])[0]
        except AttributeError:
            try:
                rl_action = inner.get_attr("rl_action", [0])[0]
            except AttributeError:
                pass
            else:
                self.centre = np.asarray(rl_action(np.zeros(m)), dtype=np.float64)
                self.half = np.asarray(rl_action(np.ones(m)), dtype=np.float64) - self.centre

    def _executed(self, info: dict[str, Any]) -> Any:
        if "action" not in info:
            raise ValueError(
                "learn_from: the environment's info has no 'action' (the executed action)"
            )
        if not (self.without_clf and "shield" in info):
            return info["action"]
        shield = info["shield"]
        if self.env_action is not None:
            # info["action"] is already in the policy's units; the CLF's part is taken out in
            # the shield's, where the input is a_rl + a_cbf + a_clf.
            return self.env_action(shield["a_rl"] + shield["a_cbf"])
        return info["action"] - shield["a_clf"]

    def _on_step(self) -> bool:
        infos = self.locals["infos"]
        executed = (np.stack([self._executed(i) for i in infos]) - self.centre) / self.half
        actions = self.locals["actions"]  # what the rollout buffer stores after this call
        actions[...] = executed.reshape(actions.shape)
        return True

    def _on_rollout_end(self) -> None:
        import torch

        model: Any = self.model  # PPO: an on-policy algorithm, with a rollout buffer
        buffer, policy = model.rollout_buffer, model.policy
        steps, envs = buffer.log_probs.shape
        obs = torch.as_tensor(buffer.observations.reshape(steps * envs, -1), device=policy.device)
        taken = torch.as_tensor(buffer.actions.reshape(steps * envs, -1), device=policy.device)
        with torch.no_grad():
            _, log_prob, _ = policy.evaluate_actions(obs, taken)
        buffer.log_probs[...] = log_prob.cpu().numpy().reshape(steps, envs)
