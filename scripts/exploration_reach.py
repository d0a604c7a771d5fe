"""How often an untrained policy reaches g1 or g2 on Channel-v0 within an episode, per
configuration (docs/learning.md): the exploration each configuration starts from.

    .venv/bin/python scripts/exploration_reach.py --episodes 200 [--variants]

Two untrained policies: actions uniform in the action box, and PPO's starting policy as
tlshield's default preset samples it (a Gaussian of mean 0 and std 1, clipped to the box).
Training episodes (no evaluation rules), reset seeds 50,000 and up (never used for training
or evaluation). Prints, per configuration and policy, the fraction of episodes whose automaton
left its initial state (g1 or g2 reached), the fraction in the trap, and the mean distance the
reference point ends from where it started. With ``--variants``: PPO's starting policy
without a shield (``rl``) under each setting that differs from the paper's (goal size and
placement, the horizon, the trap's reward; docs/reproduction.md).
"""

from __future__ import annotations

import argparse

import numpy as np

from tlshield.envs.channel import ChannelEnv
from tlshield.envs.params import CONFIGS

FIRST_RESET_SEED = 50_000
POLICIES = ("uniform", "gaussian")

#: Each ``--variants`` row: a name and the Channel-v0 settings it changes (``--set``'s names).
VARIANTS: dict[str, dict[str, object]] = {
    "defaults": {},
    "the paper's env (Eq. 5A1, its observation, no goal term, no obstacle barrier)": {
        "reward": "paper",
        "observation": "paper",
        "obstacle_barrier": False,
        "goal_weight": 0.0,
        "end_on_trap": False,
    },
    "episodes go on in the trap (no lump)": {"end_on_trap": False},
    "goals always inside the channel": {"outside_goal_probability": 0.0},
    "goal radius 0.8 (0.5)": {"goal_radius": 0.8, "outside_goal_v": (1.9, 2.7)},
    "g1, g2 at u 1.0-2.0 (2.5-5.5)": {"near_goal_u": (1.0, 2.0)},
    "horizon 1000 (200)": {"horizon": 1000},
}


def run(config: str, policy: str, episodes: int, **overrides: object) -> tuple[float, float, float]:
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
    parser.add_argument("--variants", action="store_true", help="rl under each paper difference")
    args = parser.parse_args()
    if args.variants:
        print(
            "| rl, gaussian: setting | reached g1/g2 | entered the trap "
            "| mean end displacement (m) |"
        )
        print("|---|---:|---:|---:|")
        for name, overrides in VARIANTS.items():
            reached, trapped, moved = run("rl", "gaussian", args.episodes, **overrides)
            print(f"| {name} | {reached:.2f} | {trapped:.2f} | {moved:.2f} |")
        return
    print("| config | policy | reached g1/g2 | entered the trap | mean end displacement (m) |")
    print("|---|---|---:|---:|---:|")
    for config in sorted(CONFIGS):
        for policy in POLICIES:
            reached, trapped, moved = run(config, policy, args.episodes)
            print(f"| {config} | {policy} | {reached:.2f} | {trapped:.2f} | {moved:.2f} |")


if __name__ == "__main__":
    main()
