"""Environment steps per second of tlshield/Channel-v0 with and without the shield, single and
vectorised (SB3 ``DummyVecEnv`` of 8 and 64 environments, and the core's vector envs that step
all environments in one call), in one run.

The vectorised shield is :class:`tlshield.wrappers.ShieldedVecEnv`: one ``filter_batch`` call
shields every sub-environment. For comparison the table also shows each sub-environment
shielding itself (one ``filter`` call per environment). Target: the vectorised shield adds at
most 30% to the step time of the vectorised environment.

Run: ``.venv/bin/python benches/env_speed.py [--quick]``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from functools import partial

import numpy as np

TARGET_OVERHEAD = 0.30


def steps_per_second(steps: Sequence[Callable[[], object]], seconds: float) -> list[float]:
    """Median rate of each stepper over 5 rounds; within a round the steppers take turns
    (blocks of about ``seconds / 5``), so a slow phase of a shared machine hits all of them
    alike and the ratios stay meaningful."""
    for step in steps:
        step()
    rates: list[list[float]] = [[] for _ in steps]
    for _ in range(5):
        for i, step in enumerate(steps):
            count, start = 0, time.perf_counter()
            while (elapsed := time.perf_counter() - start) < seconds / 5:
                step()
                count += 1
            rates[i].append(count / elapsed)
    return [float(np.median(r)) for r in rates]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    seconds = 1.0 if args.quick else 5.0

    from stable_baselines3.common.vec_env import DummyVecEnv

    import tlshield.vector
    from tlshield.envs import ChannelEnv, ChannelParams, channel_shield
    from tlshield.sb3 import ChannelVecEnv
    from tlshield.wrappers import ShieldedVecEnv

    rng = np.random.default_rng(0)
    print("| environment | env steps/s | us per env step | shield overhead |")
    print("|---|---:|---:|---:|")

    def single(config: str) -> Callable[[], object]:
        env = ChannelEnv(config=config)
        env.reset(seed=0)
        actions = rng.uniform(-1, 1, size=(4096, 2))
        k = [0]

        def step() -> None:
            k[0] += 1
            _, _, term, trunc, _ = env.step(actions[k[0] % 4096])
            if term or trunc:
                env.reset()

        return step

    base, shielded = steps_per_second([single("rl"), single("rl_cbf_clf")], seconds)
    print(f"| single, no shield | {base:,.0f} | {1e6 / base:.1f} | |")
    print(
        f"| single, shield in the env | {shielded:,.0f} | {1e6 / shielded:.1f} | "
        f"{base / shielded - 1:+.0%} |"
    )

    verdicts = []
    for n in (8, 64):
        actions = rng.uniform(-1, 1, size=(256, n, 2))

        def stepper(venv: object, actions: np.ndarray = actions) -> Callable[[], object]:
            venv.seed(0)  # type: ignore[attr-defined]
            venv.reset()  # type: ignore[attr-defined]
            k = [0]

            def step() -> None:
                k[0] += 1
                venv.step(actions[k[0] % 256])  # type: ignore[attr-defined]

            return step

        # The vector shield reads the state from the observation [s, one-hot(q)]: the paper's
        # observation layout, used by all three vector rows so they compare like with like.
        template = ChannelEnv(shield_in_env=False, observation="paper")
        venvs = [
            DummyVecEnv([partial(ChannelEnv, config="rl", observation="paper")] * n),
            DummyVecEnv([partial(ChannelEnv, config="rl_cbf_clf", observation="paper")] * n),
            ShieldedVecEnv(
                DummyVecEnv([partial(ChannelEnv, shield_in_env=False, observation="paper")] * n),
                channel_shield(ChannelParams(), "rl_cbf_clf"),
                action_fn=template.rl_action,
            ),
        ]
        plain, each, batched = (
            r * n for r in steps_per_second([stepper(v) for v in venvs], seconds)
        )
        overhead = plain / batched - 1
        verdicts.append(overhead <= TARGET_OVERHEAD)
        print(f"| DummyVecEnv x{n}, no shield | {plain:,.0f} | {1e6 / plain:.1f} | |")
        print(
            f"| DummyVecEnv x{n}, each env shields itself | {each:,.0f} | {1e6 / each:.1f} | "
            f"{plain / each - 1:+.0%} |"
        )
        print(
            f"| DummyVecEnv x{n} + ShieldedVecEnv (one `filter_batch`) | {batched:,.0f} | "
            f"{1e6 / batched:.1f} | {overhead:+.0%} (target <= +{TARGET_OVERHEAD:.0%}"
            f"{'' if verdicts[-1] else ', MISSED'}) |"
        )
        # The core's vector envs (every env's step in one call) against SB3's DummyVecEnv over
        # the same single envs, default settings (relative observation, shield in the env).
        dummy, core_sb3, core_gym = steps_per_second(
            [
                stepper(DummyVecEnv([partial(ChannelEnv, config="rl_cbf_clf")] * n)),
                stepper(ChannelVecEnv(n, "rl_cbf_clf")),
                gym_stepper(tlshield.vector.make("tlshield/Channel-v0", n), actions),
            ],
            seconds,
        )
        dummy, core_sb3, core_gym = dummy * n, core_sb3 * n, core_gym * n
        print(f"| DummyVecEnv x{n}, default settings | {dummy:,.0f} | {1e6 / dummy:.1f} | |")
        print(
            f"| tlshield.sb3.ChannelVecEnv x{n} (one core call per step) | {core_sb3:,.0f} | "
            f"{1e6 / core_sb3:.1f} | {core_sb3 / dummy:.1f}x DummyVecEnv |"
        )
        print(
            f"| tlshield.vector.make x{n} (Gymnasium, one core call per step) | {core_gym:,.0f} | "
            f"{1e6 / core_gym:.1f} | {core_gym / dummy:.1f}x DummyVecEnv |"
        )
    return 0 if all(verdicts) else 2


def gym_stepper(venv: object, actions: np.ndarray) -> Callable[[], object]:
    """Steps a Gymnasium vector env through ``actions`` (it resets its own finished envs)."""
    venv.reset(seed=0)  # type: ignore[attr-defined]
    k = [0]

    def step() -> None:
        k[0] += 1
        venv.step(actions[k[0] % len(actions)])  # type: ignore[attr-defined]

    return step


if __name__ == "__main__":
    raise SystemExit(main())
