"""Run folders are data, never code (issue 20, point 5): the statistics are JSON, the model is
read weights-only, and a crafted folder runs nothing and gets a clear error."""

from __future__ import annotations

import io
import json
import os
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from tlshield.envs.channel import ChannelEnv
from tlshield.lab import cli
from tlshield.lab.saved import UntrustedPickleError, load_policy, normalizer
from tlshield.lab.training import train


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train("rl_cbf_clf", 0, 2, tmp_path_factory.mktemp("runs") / "r", progress=False)


class Payload:
    """Unpickling this creates ``marker``: proof that a pickle ran code."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (os.system, (f"touch {self.marker}",))


def _observations(count: int = 16) -> np.ndarray:
    env = ChannelEnv(config="rl_cbf_clf")
    obs = [env.reset(seed=s)[0] for s in range(count)]
    return np.array(obs)


def test_a_run_folder_holds_no_pickle(run: Path) -> None:
    names = {p.name for p in run.iterdir()}
    assert {"normalization.json", "last_normalization.json"} <= names
    assert not [n for n in names if n.endswith((".pkl", ".pickle"))]
    record = json.loads((run / "normalization.json").read_text())
    assert set(record) == {"obs_mean", "obs_var", "epsilon", "clip_obs"}
    assert len(record["obs_mean"]) == len(record["obs_var"]) == _observations(1).shape[1]


def test_the_pickle_free_policy_acts_as_sb3_loads_it(run: Path) -> None:
    """Reference: SB3's own loader (it unpickles, fine for our own fresh folder) with the
    statistics applied by hand from the JSON."""
    from stable_baselines3 import PPO

    obs = _observations()
    for which, model_name, stats_name in (
        ("kept", "model.zip", "normalization.json"),
        ("last", "last_model.zip", "last_normalization.json"),
    ):
        stats = json.loads((run / stats_name).read_text())
        scaled = np.clip(
            (obs - np.array(stats["obs_mean"])) / np.sqrt(np.array(stats["obs_var"]) + 1e-8),
            -stats["clip_obs"],
            stats["clip_obs"],
        )
        reference = PPO.load(run / model_name, device="cpu").predict(scaled, deterministic=True)[0]
        np.testing.assert_array_equal(load_policy(run, which)(obs), reference)


def _crafted(run: Path, tmp_path: Path, marker: Path) -> Path:
    """A copy of ``run`` whose statistics are a pickle carrying a payload (an older layout)."""
    folder = tmp_path / "shared"
    shutil.copytree(run, folder)
    (folder / "normalization.json").unlink()
    (folder / "vecnormalize.pkl").write_bytes(pickle.dumps(Payload(marker)))
    return folder


def test_a_crafted_pickle_is_refused_and_runs_nothing(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    marker = tmp_path / "pwned"
    folder = _crafted(run, tmp_path, marker)
    with pytest.raises(UntrustedPickleError, match=r"pickle.*--trust-pickles"):
        load_policy(folder)
    assert cli.main(["evaluate", str(folder), "--trials", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tlshield evaluate: error: ")
    assert "vecnormalize.pkl" in err[0] and "--trust-pickles" in err[0]
    assert not marker.exists()


def _rezip(model: Path, replace: dict[str, bytes]) -> None:
    with zipfile.ZipFile(model) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    entries.update(replace)
    with zipfile.ZipFile(model, "w") as archive:
        for name, data in entries.items():
            archive.writestr(name, data)


def test_a_crafted_model_zip_runs_nothing(run: Path, tmp_path: Path) -> None:
    marker = tmp_path / "pwned"
    folder = tmp_path / "shared"
    shutil.copytree(run, folder)
    model = folder / "model.zip"
    # SB3 keeps unserialisable fields as base64 cloudpickles in the zip's data JSON.
    with zipfile.ZipFile(model) as archive:
        data = json.loads(archive.read("data"))
    import base64

    payload = base64.b64encode(pickle.dumps(Payload(marker))).decode()
    data["observation_space"] = {":type:": "<class 'x'>", ":serialized:": payload}
    data["policy_class"] = {":type:": "<class 'x'>", ":serialized:": payload}
    _rezip(model, {"data": json.dumps(data).encode()})
    load_policy(folder)(_observations(2))  # the data entry is never read
    assert not marker.exists()
    # A policy.pth that is a pickle of code, not tensors: refused by the weights-only load.
    buffer = io.BytesIO()
    torch.save({"w": Payload(marker)}, buffer)
    _rezip(model, {"policy.pth": buffer.getvalue()})
    with pytest.raises(ValueError, match=r"policy\.pth is not a plain tensor state dict"):
        load_policy(folder)
    assert not marker.exists()


def test_trusted_old_folders_still_load(run: Path, tmp_path: Path) -> None:
    """``trust_pickles=True`` reads an older folder's real VecNormalize pickle."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    folder = tmp_path / "old"
    shutil.copytree(run, folder)
    stats = json.loads((folder / "normalization.json").read_text())
    (folder / "normalization.json").unlink()
    venv = VecNormalize(DummyVecEnv([lambda: ChannelEnv(config="rl_cbf_clf")]))
    venv.obs_rms.mean = np.array(stats["obs_mean"])
    venv.obs_rms.var = np.array(stats["obs_var"])
    venv.save(str(folder / "vecnormalize.pkl"))
    obs = _observations()
    with pytest.raises(UntrustedPickleError, match=r"vecnormalize\.pkl, a Python pickle"):
        load_policy(folder)
    np.testing.assert_array_equal(
        load_policy(folder, trust_pickles=True)(obs), load_policy(run)(obs)
    )


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"{not json", "not JSON"),
        (b'{"obs_mean": [0.0]}', "expected a JSON object with keys"),
        (b'{"obs_mean": [0.0], "obs_var": [-1.0], "epsilon": 1e-8, "clip_obs": 10}', ">= 0"),
        (b'{"obs_mean": [0.0, 1.0], "obs_var": [1.0], "epsilon": 1e-8, "clip_obs": 10}', "one"),
    ],
)
def test_bad_statistics_are_named(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "normalization.json"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=message) as err:
        normalizer(path)
    assert str(path) in str(err.value)
