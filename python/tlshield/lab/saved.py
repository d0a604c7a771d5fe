"""A run folder's trained policy, read as data: nothing in the folder can run code.

A run folder holds the policy as SB3's ``model.zip`` and the observation statistics as
``normalization.json`` (``last_model.zip`` and ``last_normalization.json`` for the last policy
beside the kept one). ``normalization.json`` is a public format, SB3 ``VecNormalize``'s fields::

    {"obs_mean": [...], "obs_var": [...], "epsilon": 1e-8, "clip_obs": 10.0}

and an observation is normalised as ``clip((obs - obs_mean) / sqrt(obs_var + epsilon),
-clip_obs, clip_obs)``. A run trained on raw observations (a preset with ``norm_obs: False``)
also writes ``"norm_obs": false``, and its observations are used as they are.

``model.zip`` is read without unpickling anything: the policy network is rebuilt from the run's
``run.json`` (policy class, layers, activation, initial log std) and the spaces of its
environment, and only ``policy.pth`` is loaded, with ``torch.load(weights_only=True)``, which
accepts tensors and nothing else. The zip's ``data`` entry, where SB3 keeps cloudpickled
fields (spaces, schedules, the policy class), is never read.

Folders written before this format hold ``vecnormalize.pkl``, a pickle: loading one runs
whatever code it carries, so they are refused unless the caller says the folder is trusted
(``trust_pickles=True``, ``tlshield evaluate --trust-pickles``).
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tlshield.envs import ENV_ID
from tlshield.lab.envs import make
from tlshield.lab.runs import read_record

__all__ = [
    "POLICY_FILES",
    "UntrustedPickleError",
    "load_policy",
    "normalizer",
    "save_normalization",
]

#: Per policy ("kept", "last"): the model, its statistics, and the pickle older runs wrote.
POLICY_FILES = {
    "kept": ("model.zip", "normalization.json", "vecnormalize.pkl"),
    "last": ("last_model.zip", "last_normalization.json", "last_vecnormalize.pkl"),
}
_KEYS = ("obs_mean", "obs_var", "epsilon", "clip_obs")


class UntrustedPickleError(ValueError):
    """A run folder whose policy statistics are a pickle, and the caller did not trust it."""


def save_normalization(venv: Any, path: str | Path) -> Path:
    """Writes a ``VecNormalize``'s observation statistics to ``path`` as JSON (module docs)."""
    if venv.norm_obs:
        mean, var = venv.obs_rms.mean, venv.obs_rms.var
    else:  # raw observations: no statistics were kept
        mean, var = np.zeros(venv.observation_space.shape), np.ones(venv.observation_space.shape)
    record: dict[str, Any] = {
        "obs_mean": np.asarray(mean, dtype=float).tolist(),
        "obs_var": np.asarray(var, dtype=float).tolist(),
        "epsilon": float(venv.epsilon),
        "clip_obs": float(venv.clip_obs),
    }
    if not venv.norm_obs:
        record["norm_obs"] = False
    path = Path(path)
    path.write_text(json.dumps(record, indent=1))
    return path


def normalizer(path: str | Path) -> Callable[[np.ndarray], np.ndarray]:
    """The observation normalisation of a ``normalization.json``; ValueError naming the file
    and the problem when it is not one."""
    path = Path(path)
    try:
        record = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{path}: not JSON ({err})") from None
    if not isinstance(record, dict) or any(k not in record for k in _KEYS):
        raise ValueError(f"{path}: expected a JSON object with keys {', '.join(_KEYS)}")
    try:
        mean = np.asarray(record["obs_mean"], dtype=np.float64)
        var = np.asarray(record["obs_var"], dtype=np.float64)
        epsilon, clip = float(record["epsilon"]), float(record["clip_obs"])
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: statistics are not numbers ({err})") from None
    if mean.ndim != 1 or mean.shape != var.shape or not np.isfinite(mean).all():
        raise ValueError(f"{path}: obs_mean and obs_var must be finite vectors of one length")
    if not (np.isfinite(var).all() and (var >= 0).all() and epsilon > 0 and clip > 0):
        raise ValueError(f"{path}: obs_var must be >= 0, epsilon and clip_obs > 0")
    if record.get("norm_obs", True) is False:
        return lambda obs: np.asarray(obs, dtype=np.float64)
    scale = np.sqrt(var + epsilon)

    def normalize(obs: np.ndarray) -> np.ndarray:
        return np.clip((obs - mean) / scale, -clip, clip)

    return normalize


def _legacy_normalizer(path: Path) -> Callable[[np.ndarray], np.ndarray]:
    """The statistics of a trusted ``vecnormalize.pkl`` (older run folders)."""
    import pickle

    with path.open("rb") as f:
        stats = pickle.load(f)  # only ever with trust_pickles=True
    return stats.normalize_obs


def activation_class(name: str) -> Any:
    """The torch activation of ``name`` as run.json records it (``"ReLU"`` or ``"Tanh"``)."""
    import torch

    known = {"ReLU": torch.nn.ReLU, "Tanh": torch.nn.Tanh}
    if name not in known:
        raise ValueError(f"activation {name!r}: expected one of {', '.join(known)}")
    return known[name]


def _policy_network(record: dict[str, Any], model: Path) -> Any:
    """The SB3 policy of a run, built from its run.json, with the weights of ``model``."""
    import pickle

    import torch

    from tlshield.lab.policies import policy_class

    ppo = record.get("ppo", {})
    env = make(record.get("env_id", ENV_ID), record["config"], **record.get("overrides", {}))
    policy = policy_class(str(ppo.get("policy", "gaussian")))(
        env.observation_space,
        env.action_space,
        lr_schedule=lambda _: 0.0,
        net_arch=ppo.get("net_arch"),
        activation_fn=activation_class(str(ppo.get("activation", "ReLU"))),
        log_std_init=float(ppo.get("log_std_init", 0.0)),
        use_sde=bool(ppo.get("use_sde", False)),  # gSDE's noise weights are in the state dict
    )
    env.close()
    try:
        with zipfile.ZipFile(model) as archive:
            raw = archive.read("policy.pth")
    except zipfile.BadZipFile as err:
        raise ValueError(f"{model}: not a readable zip ({err})") from None
    except KeyError:
        raise ValueError(f"{model}: no policy.pth inside (not an SB3 model)") from None
    try:
        state = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise ValueError(
            f"{model}: policy.pth is not a plain tensor state dict; refused ({first})"
        ) from None
    try:
        policy.load_state_dict(state)
    except (RuntimeError, TypeError, AttributeError) as err:
        first = str(err).strip().splitlines()[0]
        raise ValueError(f"{model}: the weights do not fit the run's run.json ({first})") from None
    policy.set_training_mode(False)
    return policy


def load_policy(
    run: str | Path, which: str = "kept", *, trust_pickles: bool = False
) -> Callable[[np.ndarray], np.ndarray]:
    """The deterministic policy ``which`` (``"kept"`` or ``"last"``) of a run folder, with its
    observation statistics, read without running code from the folder (module docs)."""
    if which not in POLICY_FILES:
        raise ValueError(f"which = {which!r}: expected one of {', '.join(POLICY_FILES)}")
    run = Path(run)
    record = read_record(run)
    model_name, stats_name, pickle_name = POLICY_FILES[which]
    model = run / model_name
    if not model.is_file():
        raise FileNotFoundError(f"{run}: no {model_name} (training did not finish?)")
    normalize: Callable[[np.ndarray], np.ndarray] = lambda obs: obs  # noqa: E731
    if (run / stats_name).is_file():
        normalize = normalizer(run / stats_name)
    elif (run / pickle_name).exists():
        if not trust_pickles:
            raise UntrustedPickleError(
                f"{run}: its observation statistics are {pickle_name}, a Python pickle, and "
                "loading a pickle runs whatever code it carries, so a run folder from someone "
                "else is not safe to evaluate this way. Re-train it (runs now write "
                f"{stats_name}), or pass --trust-pickles (trust_pickles=True) for a folder you "
                "made yourself"
            )
        normalize = _legacy_normalizer(run / pickle_name)
    policy = _policy_network(record, model)

    def act(obs: np.ndarray) -> np.ndarray:
        return policy.predict(normalize(obs), deterministic=True)[0]

    return act
