"""What an untrained policy finds on Channel-v0 (docs/reproduction.md, "Why rl and rl_clf end
where they do"): the share of episodes in which PPO's initial policy (i.i.d. Gaussian actions,
std 1, clipped to the box) reaches the first goal (g1 or g2), finishes the task, or enters the
trap (leaves the channel before g3), under each setting that differs from the paper's: goal
size and placement, the horizon, and the episode's end in the trap.

    python scripts/channel_exploration.py [--episodes 200]

Every setting with ``rl`` (no shield), then the defaults with each shield.

Reset seeds 30,000 on (never used in training or evaluation). Prints a markdown table.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import tlshield  # noqa: F401  (registers the envs)

#: Each row: a name and the Channel-v0 settings it changes (flat names, ``--set``'s).
VARIANTS: dict[str, dict[str, object]] = {
    "defaults": {},
    "paper env (Eq. 5A1, no goal term)": {
        "reward": "paper",
        "observation": "paper",
        "obstacle_barrier": False,
        "goal_weight": 0.0,
        "end_on_trap": False,
    },
    "goals always inside the channel": {"outside_goal_probability": 0.0},
    "goal radius 0.8 (0.5)": {"goal_radius": 0.8, "outside_goal_v": (1.9, 2.7)},
    "near goals at u 1.5-3.0 (2.5-5.5)": {"near_goal_u": (1.5, 3.0)},
    "horizon 1000 (200)": {"horizon": 1000},
    "episodes go on in the trap": {"end_on_trap": False},
}


def measure(config: str, overrides: dict[str, object], episodes: int) -> dict[str, float]:
    env = gym.make("tlshield/Channel-v0", config=config, **overrides)
    aut = env.unwrapped.tracker.automaton
    start = {aut.initial}
    rng = np.random.default_rng(0)
    first = done = trapped = 0
    steps, reach = [], []
    for i in range(episodes):
        _, info = env.reset(seed=30_000 + i)
        start = {info["fsa_state"]}
        reached = entered = False
        x0 = env.unwrapped.state[:2].copy()
        far = 0.0
        n_steps = 0
        while True:
            n_steps += 1
            a = np.clip(rng.normal(size=2), -1.0, 1.0)
            _, _, terminated, truncated, info = env.step(a)
            far = max(far, float(np.linalg.norm(env.unwrapped.state[:2] - x0)))
            entered |= bool(info["trap"])
            reached |= info["fsa_state"] not in start and not info["trap"]
            if terminated or truncated:
                break
        first += reached
        done += bool(info["success"])
        trapped += entered
        steps.append(n_steps)
        reach.append(far)
    env.close()
    n = float(episodes)
    return {
        "first goal": first / n,
        "success": done / n,
        "trap": trapped / n,
        "steps": float(np.mean(steps)),
        "reach": float(np.median(reach)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=200)
    args = parser.parse_args()
    print(f"{args.episodes} episodes per row, reset seeds 30,000 on\n")
    print(
        "| config | setting | reaches g1 or g2 | finishes | enters the trap | mean steps "
        "| median farthest from start (m) |"
    )
    print("|---|---|---:|---:|---:|---:|---:|")
    rows = [("rl", name, overrides) for name, overrides in VARIANTS.items()]
    rows += [(config, "defaults", {}) for config in ("rl_clf", "rl_cbf", "rl_cbf_clf")]
    for config, name, overrides in rows:
        m = measure(config, overrides, args.episodes)
        print(
            f"| {config} | {name} | {m['first goal']:.3f} | {m['success']:.3f} "
            f"| {m['trap']:.3f} | {m['steps']:.0f} | {m['reach']:.2f} |"
        )


if __name__ == "__main__":
    main()
