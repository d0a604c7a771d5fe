"""OmniSafe's PPO-Lag on Safety-Gymnasium at tlshield's budget, for a like-for-like baseline
(issue 45, point 3; docs/guides/safety-gym.md, "OmniSafe's PPO-Lag, here"). It runs in its own
virtual environment, because omnisafe 0.5.0 needs safety-gymnasium's own gymnasium (0.28.1):

    python3 -m venv /tmp/omni
    /tmp/omni/bin/pip install --no-deps omnisafe==0.5.0 safety-gymnasium==1.0.0 \
        gymnasium-robotics==1.2.2 pettingzoo==1.23.1
    /tmp/omni/bin/pip install "numpy<2" gymnasium==0.28.1 mujoco==2.3.7 xmltodict imageio \\
        pyyaml pandas==2.0.3 torch tensorboard wandb moviepy typing-extensions "typer[all]" \\
        seaborn matplotlib gdown
    /tmp/omni/bin/python scripts/omnisafe_baseline.py [--env SafetyPointGoal1-v0] \\
        [--steps 200000] [--seed 0] [--out /tmp/omnisafe-runs]

``pip install omnisafe==0.5.0`` as published fails on Python 3.11. safety-gymnasium 1.0.0 pins
pygame 2.1.0, whose C source includes ``longintrepr.h`` (gone in 3.11), and a MuJoCo without a
3.11 wheel. So both are installed without their pins, and MuJoCo 2.3.7, tlshield's version, is
used. Rendering (pygame) is not needed. Before OmniSafe imports safety-gymnasium, this script
makes the package's colour arrays hashable, as tlshield's adapter does; without that, Python 3.11
refuses them as dataclass defaults. Nothing else is patched. It prints the last epoch's mean
episode return and cost. These are training episodes, the numbers OmniSafe's benchmark tables
report. OmniSafe's ``progress.csv`` under ``--out`` has every epoch's.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import types

import numpy as np


class _HashableArray(np.ndarray):
    __hash__ = object.__hash__  # type: ignore[assignment]


def patch_colours() -> None:
    """Imports safety-gymnasium's colour table without its package ``__init__`` and makes the
    arrays hashable, then lets the real package import on top of it."""
    spec = importlib.util.find_spec("safety_gymnasium")
    assert spec is not None and spec.submodule_search_locations is not None
    root = next(iter(spec.submodule_search_locations))
    shell = types.ModuleType("safety_gymnasium")
    shell.__path__ = [root]
    sys.modules["safety_gymnasium"] = shell
    from safety_gymnasium.assets import color  # type: ignore[import-not-found]

    for name, value in list(color.COLOR.items()):
        color.COLOR[name] = np.asarray(value).view(_HashableArray)
    del sys.modules["safety_gymnasium"]
    import safety_gymnasium  # noqa: F401  (the real package, on the patched colours)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="SafetyPointGoal1-v0")
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="/tmp/omnisafe-runs")
    args = parser.parse_args()
    patch_colours()
    import omnisafe  # type: ignore[import-not-found]

    cfgs = {
        "seed": args.seed,
        "train_cfgs": {"total_steps": args.steps, "device": "cpu", "torch_threads": 1},
        "logger_cfgs": {"use_wandb": False, "use_tensorboard": False, "log_dir": args.out},
    }
    os.makedirs(args.out, exist_ok=True)
    agent = omnisafe.Agent("PPOLag", args.env, custom_cfgs=cfgs)
    ep_ret, ep_cost, ep_len = agent.learn()
    print(f"last epoch: return {ep_ret:.2f}, cost {ep_cost:.2f}, length {ep_len:.0f}")


if __name__ == "__main__":
    main()
