"""The paper's evaluation of a trained run (Li & Belta, Sec. VI): the CBF always on; an
episode ends at the horizon, on success or on collision. All trials run side by side with one
batched policy call per step.

Evaluation reset seeds start at ``EVAL_SEED`` (10,000 + trial); the seed ranges of training,
validation and evaluation live in :mod:`tlshield.lab.seeds`, so the three never meet.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tlshield.envs import ENV_ID
from tlshield.envs.profile import load_attr, profile_of
from tlshield.lab import measures
from tlshield.lab.envs import env_horizon, import_modules, make
from tlshield.lab.presets import DEFAULT_TRIALS
from tlshield.lab.runs import read_record
from tlshield.lab.seeds import EVAL_SEED, MAX_TRIALS

__all__ = ["EVAL_SEED", "Recorder", "evaluate", "rollouts", "saved_policy"]


class Recorder:
    """What :func:`rollouts` calls besides the policy, as SB3's ``evaluate_policy`` calls its
    ``callback``: after each trial's reset (:meth:`start`), after each of its steps
    (:meth:`step`) and once after its last step (:meth:`end`, whose fields are added to the
    trial's outcome). :meth:`arrays` is what :func:`evaluate` saves as ``trajectories.npz``
    (nothing by default). An env's profile may name one (``EnvProfile.recorder``:
    Channel-v0's paths, :class:`tlshield.envs.channel_paths.ChannelPaths`); any object with
    these four methods serves."""

    def start(self, trial: int, env: Any) -> None:
        """After trial ``trial``'s reset."""

    def step(self, trial: int, env: Any) -> None:
        """After each of trial ``trial``'s steps."""

    def end(self, trial: int, env: Any, info: dict[str, Any], terminated: bool) -> dict[str, Any]:
        """After the trial's last step (its ``info`` and ``terminated``): fields to add to its
        outcome."""
        return {}

    def arrays(self) -> dict[str, np.ndarray]:
        """Arrays to save (empty: nothing)."""
        return {}


def rollouts(
    config: str,
    overrides: dict[str, Any],
    policy: Callable[[np.ndarray], np.ndarray],
    seeds: list[int],
    env_id: str = ENV_ID,
    *,
    evaluation: bool | None = None,
    recorders: Sequence[Recorder] = (),
    extra: None = None,
) -> list[dict[str, Any]]:
    """Evaluation episodes (CBF on; end at the horizon, on success or on collision), all side
    by side with one batched policy call per step: one outcome per trial. Violations and
    collisions are counted as :mod:`tlshield.lab.measures` says; ``None`` where the
    environment gives nothing to measure them by. Each outcome also has the trial's
    undiscounted ``return`` (the task's own reward, ``info["task_reward"]`` where the env
    shapes it) and ``cost`` (``info["cost"]`` summed; ``None`` where the env reports none).

    An env whose profile is ``scored_by_return`` (Safety-Gymnasium's) runs as it trained,
    the unshielded ``rl`` unshielded, and every episode runs to the horizon (a met goal moves,
    it does not end the task); its ``success`` says whether any goal was met.

    ``evaluation``: the env factory's ``evaluation=`` (default: the rules above, the CBF on
    except for an env scored by return); ``overrides`` go to the factory as keywords.
    ``recorders`` (:class:`Recorder`) are called after each reset and step and once at each
    trial's end; what their :meth:`Recorder.end` returns is added to the trial's outcome. The
    envs are closed before this returns. (``extra=``, a per-trial function, was removed in
    0.4: a :class:`Recorder`'s :meth:`Recorder.end` does its job.)"""
    if extra is not None:
        raise TypeError(
            "rollouts(extra=...) was removed in tlshield 0.4: pass recorders=[a Recorder whose "
            "end(trial, env, info, terminated) returns the fields]; rollouts returns the "
            "outcomes alone (trajectories come from a recorder's arrays())"
        )
    by_return = profile_of(env_id).scored_by_return
    if evaluation is None:
        # The paper's evaluation rules: the CBF on in every configuration.
        evaluation = not by_return
    envs = [make(env_id, config, evaluation=evaluation, **overrides) for _ in seeds]
    obs = np.stack([env.reset(seed=s)[0] for env, s in zip(envs, seeds, strict=True)])
    for i, env in enumerate(envs):
        for recorder in recorders:
            recorder.start(i, env)
    outcomes: list[dict[str, Any]] = [
        {
            "reset_seed": s,
            "success": False,
            "collision": None,
            "steps": 0,
            "violations": None,
            "return": 0.0,
            "cost": None,
            "gave_way": {},
            "unreported_contacts": 0,
        }
        for s in seeds
    ]
    trapped = [False] * len(seeds)
    last: list[tuple[dict[str, Any], bool]] = [({}, False)] * len(seeds)  # info, terminated
    horizon = env_horizon(envs[0]) or 1000
    active = list(range(len(seeds)))
    for t in range(horizon):
        if not active:
            break
        actions = np.asarray(policy(obs[active]), dtype=np.float64).reshape(len(active), -1)
        still = []
        for i, action in zip(active, actions, strict=True):
            o, reward, terminated, truncated, info = envs[i].step(action)
            obs[i] = o
            last[i] = info, bool(terminated)
            for recorder in recorders:
                recorder.step(i, envs[i])
            out = outcomes[i]
            _count_step(out, info, reward, trapped[i])
            out["steps"] = t + 1
            trapped[i] = bool(info.get("trap", False))
            collision = measures.collision(info)
            # A trial that touched an obstacle is never a success, however the obstacles are
            # encoded (in the formula, or as the shield's barriers only).
            touched = bool(out["collision"])
            if by_return:
                out["success"] = out["success"] or bool(info.get("success", False))
                if not (terminated or truncated):
                    still.append(i)
            elif terminated or truncated or collision:
                out["success"] = bool(info["success"]) and not touched
            else:
                still.append(i)
        active = still
    for i, (env, out, (info, terminated)) in enumerate(zip(envs, outcomes, last, strict=True)):
        for recorder in recorders:
            out.update(recorder.end(i, env, info, terminated))
        env.close()
    return outcomes


def _count_step(out: dict[str, Any], info: dict[str, Any], reward: float, trapped: bool) -> None:
    """Adds one step's violation, return, cost, collision and give-way to a trial's outcome."""
    violation = measures.step_violation(info, trapped)
    if violation is not None:
        out["violations"] = (out["violations"] or 0) + int(violation)
    out["return"] += float(info.get("task_reward", reward))
    if "cost" in info:
        out["cost"] = (out["cost"] or 0.0) + float(info["cost"])
    collision = measures.collision(info)
    if collision is not None:
        # Sticky: a trial that touched an obstacle once collided.
        out["collision"] = bool(out["collision"]) or collision
    gave_way = info.get("shield", {}).get("gave_way")
    if collision and "shield" in info and gave_way is None:
        # A contact on a step where no barrier gave way: the shield did not report it.
        out["unreported_contacts"] += 1
    if gave_way is not None:
        name = str(gave_way[0])
        out["gave_way"][name] = out["gave_way"].get(name, 0) + 1


def gave_way_totals(outcomes: list[dict[str, Any]]) -> dict[str, int]:
    """Per barrier, the steps on which it gave way, summed over the trials."""
    totals: dict[str, int] = {}
    for o in outcomes:
        for name, count in o.get("gave_way", {}).items():
            totals[name] = totals.get(name, 0) + count
    return dict(sorted(totals.items()))


def _count(value: bool | int | None) -> int | None:
    """1 for a trial that collided or violated, 0 for one that did not, None if unmeasured."""
    return None if value is None else int(bool(value))


#: The files an evaluation writes, per policy ("kept": the run's model, "last": its last).
EVALUATION_FILES = {
    "kept": ("evaluation.json", "trajectories.npz"),
    "last": ("last_evaluation.json", "last_trajectories.npz"),
}


def evaluate(
    run: str | Path,
    trials: int = DEFAULT_TRIALS,
    seed: int = EVAL_SEED,
    policy: Callable[[np.ndarray], np.ndarray] | None = None,
    *,
    which: str = "kept",
    trust_pickles: bool = False,
) -> dict[str, Any]:
    """The paper's evaluation of a trained run: CBF always on; an episode ends at the horizon,
    on success or on collision. All trials run side by side (one batched policy call per
    step); ``policy`` maps a batch of observations ``(N, d)`` to actions ``(N, 2)``. Trial
    ``i`` resets with seed ``seed + i``. Writes ``evaluation.json`` (totals and one record per
    trial: reset seed, success, collision, steps, violating steps) and, where the env's profile
    names a :class:`Recorder`, its arrays as ``trajectories.npz`` (Channel-v0: each trial's
    start state, agent path and obstacle paths). The run's
    environment is the one its run.json names (``env_id``; Channel-v0 when absent).
    ``which="last"`` evaluates the last policy instead of the kept one and writes
    ``last_evaluation.json`` and ``last_trajectories.npz``; ``trust_pickles`` lets an older run
    folder's pickled statistics load (see :mod:`tlshield.lab.saved`). ``evaluation.json`` also
    has the trials' mean undiscounted ``return_mean`` and ``cost_mean`` (None where the env
    reports no cost). An env whose profile is ``scored_by_return`` (Safety-Gymnasium's) is
    evaluated as :func:`rollouts` says: as it trained, to the horizon."""
    if not (isinstance(trials, int) and 0 < trials <= MAX_TRIALS):
        raise ValueError(f"trials = {trials!r}: expected a positive integer <= {MAX_TRIALS}")
    if which not in EVALUATION_FILES:
        raise ValueError(f"which = {which!r}: expected one of {', '.join(EVALUATION_FILES)}")
    record = read_record(run)
    import_modules(record.get("imports", []))  # where the run's environment registers itself
    if policy is None:
        policy = saved_policy(Path(run), which, trust_pickles=trust_pickles)
    evaluation_file, trajectories_file = EVALUATION_FILES[which]
    env_id = record.get("env_id", ENV_ID)
    profile = profile_of(env_id)
    recorders = [load_attr(profile.recorder)()] if profile.recorder else []
    outcomes = rollouts(
        record["config"],
        record.get("overrides", {}),
        policy,
        [seed + i for i in range(trials)],
        env_id,
        recorders=recorders,
    )
    successes = sum(o["success"] for o in outcomes)
    steps_to_success = [o["steps"] for o in outcomes if o["success"]]
    costs = [o["cost"] for o in outcomes if o["cost"] is not None]
    result = {
        "config": record["config"],
        "seed": record["seed"],
        "policy": which,
        "trials": trials,
        "eval_seed": seed,
        "success_rate": successes / trials,
        "successes": successes,
        "collisions": measures.total([_count(o["collision"]) for o in outcomes]),
        "violation_steps": measures.total([o["violations"] for o in outcomes]),
        "violating_trials": measures.total([_count(o["violations"]) for o in outcomes]),
        "mean_steps_to_success": float(np.mean(steps_to_success)) if steps_to_success else None,
        "return_mean": float(np.mean([o["return"] for o in outcomes])),
        "cost_mean": float(np.mean(costs)) if costs else None,
        # Per barrier, the evaluation steps on which it gave way (every trial).
        "gave_way": gave_way_totals(outcomes),
        "unreported_contacts": sum(o["unreported_contacts"] for o in outcomes),
        "outcomes": outcomes,
    }
    Path(run, evaluation_file).write_text(json.dumps(result, indent=2))
    arrays = {k: v for r in recorders for k, v in r.arrays().items()}
    if arrays:  # what the env's recorder kept (Channel-v0: the trajectory figure's paths)
        np.savez_compressed(Path(run, trajectories_file), **arrays)
    return result


def saved_policy(
    run: Path, which: str = "kept", *, trust_pickles: bool = False
) -> Callable[[np.ndarray], np.ndarray]:
    """The trained policy ``which`` (``"kept"`` or ``"last"``) of a run folder
    (deterministic), with its observation statistics, read without running code from the
    folder (:func:`tlshield.lab.saved.load_policy`)."""
    import torch

    from tlshield.lab.saved import load_policy

    torch.set_num_threads(1)
    return load_policy(run, which, trust_pickles=trust_pickles)
