"""The CLF's relaxation cost K on FlatWorld, with the shield alone (a zero policy): success and
mean steps per formula for several K, on the benchmark's evaluation seeds (issue 22, point 5).

With cost |a_clf|^2 + K delta, the single integrator's CLF correction is a_clf = -K e (e the
offset from the goal), clipped to the CLF box: a proportional controller of gain K that
saturates per axis where K |e_i| > clf_bound. A large K saturates everywhere: the correction
becomes bang-bang along the box's diagonals and can settle against a barrier. The rule used by
FlatWorld-v0: K = clf_bound / d, with d the distance (about a region's radius, 0.5) inside
which the correction stays proportional.

    python scripts/flatworld_clf_gain.py [--episodes 200] [--seed 1]
"""

from __future__ import annotations

import argparse

from tlshield.envs.flatworld import FORMULAS
from tlshield.lab.benchmark import run_episodes, zero_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--gains", type=float, nargs="+", default=[1.0, 10.0, 100.0, 1e4])
    args = parser.parse_args()
    print(f"zero policy + shield (rl_cbf_clf), {args.episodes} episodes, seed {args.seed}")
    print("| K | " + " | ".join(f"F{k}" for k in range(1, len(FORMULAS) + 1)) + " |")
    print("|---:|" + "---|" * len(FORMULAS))
    for k in args.gains:
        cells = []
        for f in FORMULAS:
            r = run_episodes(f, "rl_cbf_clf", zero_policy, args.seed, args.episodes, k=k)
            cells.append(f"{r['success_rate']:.3f} ({r['mean_steps']:.0f})")
        print(f"| {k:g} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
