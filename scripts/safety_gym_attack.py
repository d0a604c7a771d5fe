"""The shield alone on Safety-Gymnasium: scripted policies against ``tlshield/SafetyPointGoal*``
and ``tlshield/SafetyCarGoal1-v0`` in every configuration (docs/guides/safety-gym.md).

    .venv/bin/python scripts/safety_gym_attack.py [--episodes 10]

Policies: ``zero`` (no action: with ``rl_cbf_clf`` the shield alone drives, by its CLF), the
lidar hazard attacker (:func:`hazard_attacker`, here: it sees
what a policy sees, steers at the nearest hazard and brakes inside it), uniform random actions,
and two goal-seekers that read the lidars as a policy does: ``seeker`` turns to the goal and
thrusts, ``navigator`` also steers away from hazards and vases within 0.9 m (a potential field:
the goal's direction minus 3 (0.9 - d) / 0.9 times each near bin's). Per (env, policy,
configuration): Safety-Gymnasium's cost summed over the episodes, per episode, the goals met,
the return per episode, and the steps whose QP had to be relaxed.
"""

from __future__ import annotations

import argparse
import math
import warnings

import numpy as np
from numpy.typing import NDArray

from tlshield.envs.safety_gym import SafetyGoalEnv


def hazard_attacker(env: SafetyGoalEnv, obs: NDArray[np.float64]) -> NDArray[np.float64]:
    """An attacker that sees what a policy sees: it steers at the nearest hazard on the hazard
    lidar and, from the velocimeter, drives at a speed that falls with the distance to it, so
    that it stops at the centre and stays there (full thrust ahead when no hazard is in
    range)."""
    robot = env.robot
    bins = env.lidar(obs, "hazards")
    if bins.max() <= 0.0:
        return env.drive(1.0, 0.0)
    i = int(np.argmax(bins))
    angle = (i + 0.5) * 2.0 * np.pi / bins.size - robot.ahead  # from the heading
    angle = (angle + np.pi) % (2.0 * np.pi) - np.pi  # (-pi, pi]: left is positive
    distance = env.lidar_range * (1.0 - bins[i])
    speed = min(1.0, 2.0 * distance)  # wanted, towards the hazard
    forward = robot.forward_speed(env.sensor(obs, "velocimeter"))
    thrust = float(np.clip(5.0 * (speed * math.cos(angle) - forward), -1.0, 1.0))
    return env.drive(thrust, float(np.clip(3.0 * angle, -1.0, 1.0)))


def goal_seeker(
    env: SafetyGoalEnv, obs: np.ndarray, repel: float, reach: float = 0.9
) -> np.ndarray:
    """Turn to the goal lidar's nearest bin (pushed away from the hazard and vase bins nearer
    than ``reach``, with gain ``repel``) and thrust as far as the heading allows."""
    goal = env.lidar(obs, "goal")
    # Bin angles from the heading (the Car's lidar reads its body frame, whose x is not ahead).
    angles = (np.arange(goal.size) + 0.5) * 2.0 * np.pi / goal.size - env.robot.ahead
    i = int(np.argmax(goal))
    v = np.array([math.cos(angles[i]), math.sin(angles[i])])
    for name in ("hazards", "vases"):
        try:
            bins = env.lidar(obs, name)
        except KeyError:  # Goal1 has no vases
            continue
        d = env.lidar_range * (1.0 - bins)
        for j in np.flatnonzero((bins > 0.0) & (d < reach)):
            v -= (
                repel
                * (reach - d[j])
                / reach
                * np.array([math.cos(angles[j]), math.sin(angles[j])])
            )
    heading = math.atan2(v[1], v[0])
    return env.drive(max(0.0, math.cos(heading)), float(np.clip(3.0 * heading, -1, 1)))


def main() -> None:
    warnings.filterwarnings("ignore", category=RuntimeWarning)  # gymnasium's Box casts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument(
        "--first-seed",
        type=int,
        default=700,
        help="episode k resets with seed FIRST_SEED + k (700: the evaluation seeds; 900: tuning)",
    )
    parser.add_argument("--tasks", nargs="+", help="default: both")
    parser.add_argument(
        "--policies",
        nargs="+",
        default=["attacker", "random"],
        choices=["zero", "attacker", "random", "seeker", "navigator"],
    )
    parser.add_argument("--configs", nargs="+", default=["rl", "rl_cbf", "rl_cbf_clf"])
    parser.add_argument(
        "--sensing",
        default="state",
        choices=["state", "lidar"],
        help="what the shield reads: MuJoCo's state (default) or the observation alone",
    )
    parser.add_argument(
        "--velocity-error", type=float, help="the env's velocity_error override (m/s^2)"
    )
    parser.add_argument(
        "--set",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="overrides of the env's settings (SafetyGoalParams), e.g. route_clearance=1.0",
    )
    args = parser.parse_args()
    from tlshield import Status
    from tlshield.envs.safety_gym import TASKS

    print(
        "| env | policy | config | episodes | cost | cost / episode | goals met | return / "
        "episode | relaxed steps |"
    )
    print("|---|---|---|---:|---:|---:|---:|---:|---:|")
    overrides: dict[str, float] = {}
    if args.velocity_error is not None:
        overrides["velocity_error"] = args.velocity_error
    for item in args.set:
        name, sep, value = item.partition("=")
        if not sep:
            parser.error(f"--set {item!r}: expected NAME=VALUE")
        overrides[name] = float(value)
    for task in args.tasks or TASKS:
        for policy in args.policies:
            for config in args.configs:
                env = SafetyGoalEnv(task, config, sensing=args.sensing, **overrides)
                rng = np.random.default_rng(3)
                cost, goals, relaxed, ret = 0.0, 0, 0, 0.0
                for ep in range(args.episodes):
                    obs, _ = env.reset(seed=args.first_seed + ep)
                    done = False
                    while not done:
                        if policy == "zero":
                            action = np.zeros(2)
                        elif policy == "attacker":
                            action = hazard_attacker(env, obs)
                        elif policy == "random":
                            action = rng.uniform(-1.0, 1.0, 2)
                        else:
                            action = goal_seeker(env, obs, 3.0 if policy == "navigator" else 0.0)
                        obs, reward, terminated, truncated, info = env.step(action)
                        ret += reward
                        cost += info["cost"]
                        goals += info["goal_met"]
                        shield = info.get("shield")
                        relaxed += shield is not None and shield["status"] != Status.SOLVED
                        done = terminated or truncated
                print(
                    f"| {task} | {policy} | {config} | {args.episodes} | {cost:.0f} | "
                    f"{cost / args.episodes:.1f} | {goals} | {ret / args.episodes:.2f} | "
                    f"{relaxed} |"
                )


if __name__ == "__main__":
    main()
