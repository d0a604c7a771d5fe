"""The shield alone on Safety-Gymnasium: scripted policies against ``tlshield/SafetyPointGoal*``
in every configuration (docs/guides/safety-gym.md).

    .venv/bin/python scripts/safety_gym_attack.py [--episodes 10]

Policies: the lidar hazard attacker (:func:`tlshield.envs.safety_gym.hazard_attacker`: it
sees what a policy sees, steers at the nearest hazard and brakes inside it) and uniform random
actions. Per (env, policy, configuration): Safety-Gymnasium's cost summed over the episodes,
per episode, the goals met, and the steps whose QP had to be relaxed.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np


def main() -> None:
    warnings.filterwarnings("ignore", category=RuntimeWarning)  # gymnasium's Box casts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--tasks", nargs="+", help="default: both")
    parser.add_argument("--policies", nargs="+", default=["attacker", "random"])
    parser.add_argument("--configs", nargs="+", default=["rl", "rl_cbf", "rl_cbf_clf"])
    parser.add_argument(
        "--velocity-error", type=float, help="the env's velocity_error override (m/s^2)"
    )
    args = parser.parse_args()
    from tlshield import Status
    from tlshield.envs.safety_gym import TASKS, SafetyGoalEnv, hazard_attacker

    print(
        "| env | policy | config | episodes | cost | cost / episode | goals met | relaxed steps |"
    )
    print("|---|---|---|---:|---:|---:|---:|---:|")
    overrides = {} if args.velocity_error is None else {"velocity_error": args.velocity_error}
    for task in args.tasks or TASKS:
        for policy in args.policies:
            for config in args.configs:
                env = SafetyGoalEnv(task, config, **overrides)
                rng = np.random.default_rng(3)
                cost, goals, relaxed = 0.0, 0, 0
                for ep in range(args.episodes):
                    obs, _ = env.reset(seed=700 + ep)
                    done = False
                    while not done:
                        if policy == "attacker":
                            action = hazard_attacker(env, obs)
                        else:
                            action = rng.uniform(-1.0, 1.0, 2)
                        obs, _, terminated, truncated, info = env.step(action)
                        cost += info["cost"]
                        goals += info["goal_met"]
                        shield = info.get("shield")
                        relaxed += shield is not None and shield["status"] != Status.SOLVED
                        done = terminated or truncated
                print(
                    f"| {task} | {policy} | {config} | {args.episodes} | {cost:.0f} | "
                    f"{cost / args.episodes:.1f} | {goals} | {relaxed} |"
                )


if __name__ == "__main__":
    main()
