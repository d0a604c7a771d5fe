"""Python-to-Rust crossings and time per step of ``tlshield/Channel-v0``, per configuration.

A crossing is a call into ``tlshield._core`` (a method or function of the native module),
counted with ``sys.setprofile`` over ``--steps`` random steps; the time per step is measured
separately, without the profiler. Usage: ``python benches/step_crossings.py [--steps N]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter

import numpy as np

from tlshield.envs.channel import CONFIGS, ChannelEnv


def _native(frame_arg: object) -> str | None:
    """The qualified name of a native callable of ``tlshield._core``, else None."""
    owner = getattr(frame_arg, "__self__", None)
    module = getattr(frame_arg, "__module__", None) or getattr(type(owner), "__module__", None)
    if module != "tlshield._core":
        return None
    cls = type(owner).__name__ if owner is not None and not isinstance(owner, type) else ""
    return f"{cls}.{getattr(frame_arg, '__name__', '?')}".lstrip(".")


def crossings(config: str, steps: int) -> Counter[str]:
    env = ChannelEnv(config=config)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    actions = rng.uniform(-1, 1, size=(steps, 2))
    counts: Counter[str] = Counter()

    def profile(frame: object, event: str, arg: object) -> None:
        if event == "c_call":
            name = _native(arg)
            if name is not None:
                counts[name] += 1

    resets = 0
    sys.setprofile(profile)
    try:
        for a in actions:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                sys.setprofile(None)
                env.reset(seed=int(rng.integers(1 << 30)))
                resets += 1
                sys.setprofile(profile)
    finally:
        sys.setprofile(None)
    return counts


def us_per_step(config: str, steps: int) -> float:
    env = ChannelEnv(config=config)
    rng = np.random.default_rng(1)
    env.reset(seed=1)
    actions = rng.uniform(-1, 1, size=(steps, 2))
    t0 = time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset(seed=int(rng.integers(1 << 30)))
    return (time.perf_counter() - t0) / steps * 1e6


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=20_000)
    args = parser.parse_args(argv)
    print("| config | crossings per step | which (per step) | us per step |")
    print("|---|---:|---|---:|")
    for config in CONFIGS:
        counts = crossings(config, max(args.steps // 10, 100))
        n = max(args.steps // 10, 100)
        total = sum(counts.values()) / n
        which = ", ".join(f"{k} {v / n:.2f}" for k, v in counts.most_common())
        print(f"| {config} | {total:.2f} | {which} | {us_per_step(config, args.steps):.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
