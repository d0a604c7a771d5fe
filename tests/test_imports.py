"""`import tlshield` loads only what the shield needs: the training stack (torch, SB3, Ray,
matplotlib, Optuna, TensorBoard) loads when its feature is first used."""

import json
import subprocess
import sys

HEAVY = ("torch", "stable_baselines3", "ray", "matplotlib", "optuna", "tensorboard", "pandas")


def _loaded_after(code: str) -> set[str]:
    """The heavy top-level packages in ``sys.modules`` after running ``code`` in a fresh
    interpreter (a fresh one: this test process has loaded them all already)."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(m for m in sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", probe], check=True, capture_output=True, text=True
    ).stdout
    modules = json.loads(out.splitlines()[-1])
    return {m.split(".")[0] for m in modules} & set(HEAVY)


def test_import_tlshield_loads_no_training_stack():
    assert _loaded_after("import tlshield") == set()


def test_the_shield_and_the_bundled_envs_load_no_training_stack():
    code = (
        "import gymnasium as gym, numpy as np, tlshield, tlshield.wrappers\n"
        "env = gym.make('tlshield/Channel-v0', config='rl_cbf_clf')\n"
        "env.reset(seed=0); env.step(np.zeros(2))"
    )
    assert _loaded_after(code) == set()


def test_the_sb3_wrapper_loads_sb3_when_used():
    loaded = _loaded_after("from tlshield.wrappers import ShieldedVecEnv")
    assert {"stable_baselines3", "torch"} <= loaded


def _modules_after(code: str) -> list[str]:
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(m for m in sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", probe], check=True, capture_output=True, text=True
    ).stdout
    return list(json.loads(out.splitlines()[-1]))


def test_the_library_never_imports_the_lab():
    """Issue 36: the library (every module outside tlshield/lab, every bundled env stepped and
    rendered) loads nothing from tlshield.lab."""
    code = (
        "import gymnasium as gym, numpy as np, tlshield\n"
        "import tlshield.envs, tlshield.wrappers, tlshield.tracking, tlshield.vector\n"
        "import tlshield.sb3, tlshield.copying, tlshield.codes\n"
        "env = gym.make('tlshield/PointMass-v0', config='rl_cbf_clf')\n"
        "env.reset(seed=0); env.step(np.zeros(2))\n"
        "for env_id in ('tlshield/Channel-v0', 'tlshield/FlatWorld-v0'):\n"
        "    env = gym.make(env_id, config='rl_cbf_clf', render_mode='rgb_array')\n"
        "    env.reset(seed=0); env.step(np.zeros(2)); assert env.render() is not None\n"
    )
    loaded = _modules_after(code)
    assert "tlshield.envs.flatworld_map" in loaded  # the render ran
    assert [m for m in loaded if m.startswith("tlshield.lab")] == []
