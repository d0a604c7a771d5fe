"""How often an untrained policy reaches g1 or g2 on Channel-v0 within an episode, per
configuration (docs/learning.md): the exploration each configuration starts from.

    .venv/bin/python scripts/exploration_reach.py --episodes 200

Two untrained policies: actions uniform in the action box, and PPO's starting policy as
tlshield's default preset samples it (a Gaussian of mean 0 and std 1, clipped to the box).
Training episodes (no evaluation rules), reset seeds 50,000 and up (never used for training
or evaluation). Prints, per configuration and policy, the fraction of episodes whose automaton
left its initial state (g1 or g2 reached), the fraction in the trap, and the mean distance the
reference point ends from where it started.
"""

from __future__ import annotations

import argparse

import numpy as np

from tlshield.envs.channel import ChannelEnv
from tlshield.envs.params import CONFIGS

FIRST_RESET_SEED = 50_000
POLICIES = ("uniform", "gaussian")


def run(config: str, policy: str, episodes: int, **overrides: float) -> tuple[float, float, float]:
    """``(reached g1/g2, trapped, mean end displacement)`` over ``episodes`` episodes."""
    env = ChannelEnv(config=config, **overrides)
    rng = np.random.default_rng(0)
    reached = trapped = 0
    moved = 0.0
    for k in range(episodes):
        env.reset(seed=FIRST_RESET_SEED + k)
        start, q0 = env.state[:2].copy(), env.tracker.q
        left = in_trap = False
        for _ in range(env.params.horizon):
            if policy == "uniform":
                action = rng.uniform(-1.0, 1.0, size=2)
            else:
                action = np.clip(rng.normal(0.0, 1.0, size=2), -1.0, 1.0)
            _, _, terminated, truncated, info = env.step(action)
            in_trap |= bool(info["trap"])
            left |= info["fsa_state"] != q0 and not info["trap"]
            if terminated or truncated:
                break
        reached += left
        trapped += in_trap
        moved += float(np.linalg.norm(env.state[:2] - start))
    return reached / episodes, trapped / episodes, moved / episodes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=200)
    args = parser.parse_args()
    print("| config | policy | reached g1/g2 | entered the trap | mean end displacement (m) |")
    print("|---|---|---:|---:|---:|")
    for config in sorted(CONFIGS):
        for policy in POLICIES:
            reached, trapped, moved = run(config, policy, args.episodes)
            print(f"| {config} | {policy} | {reached:.2f} | {trapped:.2f} | {moved:.2f} |")


if __name__ == "__main__":
    main()
