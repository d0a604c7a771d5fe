"""The progress-preserving safe set on FlatWorld's formulas, with the shield alone: success,
setbacks (steps into a state farther from acceptance) and mean steps, with the safe set of
Eq. 5C1 (the trap only) and the progress-preserving one (issue 22, point 4).

    python scripts/flatworld_safe_set.py [--episodes 200] [--seed 1]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

from tlshield.envs.flatworld import FORMULAS, flatworld_spec
from tlshield.lab.seeds import eval_block_seed


def measure(formula: str, preserve: bool, policy: str, seed: int, episodes: int) -> str:
    ranks = flatworld_spec(formula).automaton().ranks
    env = gym.make(
        "tlshield/FlatWorld-v0", formula=formula, config="rl_cbf_clf", preserve_progress=preserve
    )
    rng = np.random.default_rng(eval_block_seed(seed, 0))
    successes, setbacks, steps = 0, 0, []
    for k in range(episodes):
        _, info = env.reset(seed=eval_block_seed(seed, k))
        q, t = info["fsa_state"], 0
        while t < 500:
            t += 1
            a = np.zeros(2) if policy == "zero" else rng.uniform(-1, 1, 2)
            _, _, term, trunc, info = env.step(a)
            q_next = info["fsa_state"]
            if ranks[q] is not None and (ranks[q_next] is None or ranks[q_next] > ranks[q]):
                setbacks += 1
            q = q_next
            if term or trunc:
                break
        if info["success"]:
            successes += 1
            steps.append(t)
    mean = f"{np.mean(steps):.0f}" if steps else "-"
    return f"{successes / episodes:.3f} / {setbacks} / {mean}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    print(
        f"success / setbacks / mean steps; rl_cbf_clf, {args.episodes} episodes, seed {args.seed}"
    )
    print("| # | policy | Eq. 5C1 safe set (trap only) | progress-preserving (default) |")
    print("|---|---|---|---|")
    for k, f in enumerate(FORMULAS, 1):
        for policy in ("zero", "random"):
            cells = [measure(f, p, policy, args.seed, args.episodes) for p in (False, True)]
            print(f"| {k} | {policy} | {cells[0]} | {cells[1]} |", flush=True)


if __name__ == "__main__":
    main()
