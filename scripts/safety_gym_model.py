"""Identifies Safety-Gymnasium's Point robot as tlshield.ThrustTurn and measures the model's
one-step error against MuJoCo, over random and attacking rollouts (docs/guides/safety-gym.md).

    .venv/bin/python scripts/safety_gym_model.py [--episodes 6] [--steps 500]

Per step the privileged state before and after (``SafetyGoalEnv.true_state``) and the action
sent are recorded. The gains are least-squares fits of the velocity's and the heading's rates;
the error is ``(s_{t+1} - s_t) / dt`` against the model's ``f(s_t) + g(s_t) u_t`` per state
dimension, reported as percentiles of its absolute value. The shield's ``disturbance`` setting
is a bound on exactly this error.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

DT = 0.02  # Safety-Gymnasium's step: 10 MuJoCo steps of 0.002 s


def rollouts(policy: str, episodes: int, steps: int) -> tuple[np.ndarray, ...]:
    """States before and after and the shield-unit inputs of ``episodes`` rollouts of the
    unshielded env under ``policy`` ("random": piecewise-constant uniform actions, half of
    them within the thrust's saturation; "attack": the lidar hazard attacker)."""
    from safety_gym_attack import hazard_attacker

    from tlshield.envs.safety_gym import SafetyGoalEnv

    env = SafetyGoalEnv("SafetyPointGoal1-v0", "rl", actions="native")
    rng = np.random.default_rng(0 if policy == "random" else 1)
    before, after, inputs = [], [], []
    for ep in range(episodes):
        obs, _ = env.reset(seed=500 + ep)
        action = np.zeros(2)
        for t in range(steps):
            if policy == "attack":
                action = hazard_attacker(env, obs)
            elif t % 10 == 0:
                action = rng.uniform(-1, 1, 2) * rng.choice([0.03, 1.0])
            s = env.true_state()
            obs, _, terminated, truncated, info = env.step(action)
            if info["goal_met"]:  # a new world: the next state is not this one's successor
                break
            before.append(s[:5])
            after.append(env.true_state()[:5])
            inputs.append(env.shield_input(action))
            if terminated or truncated:
                break
    return np.array(before), np.array(after), np.array(inputs)


def fit(s: np.ndarray, s2: np.ndarray, u: np.ndarray) -> tuple[float, float, float]:
    """``(thrust, turn, drag)`` by least squares."""
    theta = s[:, 2]
    dv = (s2[:, 3:5] - s[:, 3:5]) / DT
    x = np.concatenate(
        [
            np.stack([u[:, 0] * np.cos(theta), -s[:, 3]], 1),
            np.stack([u[:, 0] * np.sin(theta), -s[:, 4]], 1),
        ]
    )
    (thrust, drag), *_ = np.linalg.lstsq(x, np.concatenate([dv[:, 0], dv[:, 1]]), rcond=None)
    dtheta = np.angle(np.exp(1j * (s2[:, 2] - theta))) / DT
    (turn,), *_ = np.linalg.lstsq(u[:, 1:2], dtheta, rcond=None)
    return float(thrust), float(turn), float(drag)


def errors(s: np.ndarray, s2: np.ndarray, u: np.ndarray, gains: tuple[float, ...]) -> np.ndarray:
    """``|(s2 - s) / dt - (f(s) + g(s) u)|`` per step and dimension (heading wrapped)."""
    from tlshield import ThrustTurn

    model = ThrustTurn(*gains)
    out = []
    for a, b, ui in zip(s, s2, u, strict=True):
        f, g = model.eval(a)
        rate = (b - a) / DT
        rate[2] = np.angle(np.exp(1j * (b[2] - a[2]))) / DT
        out.append(np.abs(rate - (f + g @ ui)))
    return np.array(out)


def reference_point_model(d: float) -> object:
    """The paper's answer for the unicycle, on the Point: the shield's position is a point
    ``d`` ahead of the centre, ``p = c + d (cos theta, sin theta)``, so
    ``dp/dt = v + d turn a1 (-sin theta, cos theta)``: a barrier on ``p`` is first order in
    the turn alone (the thrust enters only through ``v``, one integration further)."""
    from tlshield import ControlAffine
    from tlshield.envs.safety_gym import POINT

    def f(s: np.ndarray) -> np.ndarray:
        out = np.zeros_like(s)
        out[0:2] = s[3:5]
        out[3:5] = -POINT.drag * s[3:5]
        return out

    def g(s: np.ndarray) -> np.ndarray:
        out = np.zeros((s.size, 2))
        c, sn = np.cos(s[2]), np.sin(s[2])
        out[0, 1], out[1, 1] = -d * POINT.turn * sn, d * POINT.turn * c
        out[2, 1] = POINT.turn
        out[3, 0], out[4, 0] = POINT.thrust * c, POINT.thrust * sn
        return out

    return ControlAffine(f, g, state_dim=5 + 2 + 2 * 8, inputs=2)  # Goal1: goal, 8 hazards


def compare_models(episodes: int, d: float) -> None:
    """The lidar attacker against the shield (hazards in the formula, ``rl_cbf``) with each
    model: cost, and steps whose QP had to be relaxed."""
    from safety_gym_attack import hazard_attacker

    from tlshield import Monitor, Shield, Status
    from tlshield.envs.safety_gym import POINT, SafetyGoalEnv

    print("\n| shield model | attacker episodes | cost | relaxed steps |")
    print("|---|---:|---:|---:|")
    names = ("ThrustTurn (HOCBF rows, heading in the state)", f"reference point {d} m ahead")
    for name in names:
        env = SafetyGoalEnv("SafetyPointGoal1-v0", "rl_cbf", actions="native")
        reference = name.startswith("reference")
        if reference:  # the env steps unshielded; this loop shields the point ahead
            p = env.params
            shield = Shield(
                env.automaton,
                reference_point_model(d),
                alpha=p.alpha,
                c3=p.c3,
                k=p.k,
                cbf_bounds=(-2.0, 2.0),
                clf_bounds=(-p.clf_bound, p.clf_bound),
                action_bounds=(-1.0, 1.0),
                rl_bounds=(-1.0, 1.0),
                margin=p.margin,
                use_clf=False,
            )
            env.shield = None
        monitor = Monitor(env.automaton)
        cost, relaxed = 0.0, 0
        for ep in range(episodes):
            obs, _ = env.reset(seed=900 + ep)
            monitor.reset(ahead(env.true_state(), d))
            for _ in range(1000):
                action = hazard_attacker(env, obs)
                if reference:
                    out = shield.filter_monitor(monitor, env.shield_input(action))
                    action = np.array([POINT.saturation * out.action[0], out.action[1]])
                    relaxed += out.status != Status.SOLVED
                obs, _, term, trunc, info = env.step(action)
                if not reference:
                    relaxed += info["shield"]["status"] != Status.SOLVED
                s = ahead(env.true_state(), d)
                _ = monitor.reset(s) if info["goal_met"] else monitor.advance(s)
                cost += info["cost"]
                if term or trunc:
                    break
        print(f"| {name} | {episodes} | {cost:.0f} | {relaxed} |")


def ahead(s: np.ndarray, d: float) -> np.ndarray:
    out = s.copy()
    out[0] += d * np.cos(s[2])
    out[1] += d * np.sin(s[2])
    return out


def main() -> None:
    warnings.filterwarnings("ignore", category=RuntimeWarning)  # gymnasium's Box casts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=6)
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--ahead", type=float, default=0.1, help="the reference point (m)")
    args = parser.parse_args()
    data = {p: rollouts(p, args.episodes, args.steps) for p in ("random", "attack")}
    gains = fit(*data["random"])
    print(
        f"fit on random rollouts: thrust {gains[0]:.3f}, turn {gains[1]:.3f}, drag {gains[2]:.3f}"
    )
    from tlshield.envs.safety_gym import POINT

    used = (POINT.thrust, POINT.turn, POINT.drag)
    print(f"PointModel (the shield's): thrust {used[0]}, turn {used[1]}, drag {used[2]}")
    names = ("dx/dt (m/s)", "dy/dt (m/s)", "dtheta/dt (rad/s)", "dvx/dt (m/s^2)", "dvy/dt (m/s^2)")
    print("\n| rollouts | steps | state rate | p50 | p90 | p99 | max |")
    print("|---|---:|---|---:|---:|---:|---:|")
    for policy, (s, s2, u) in data.items():
        e = errors(s, s2, u, used)
        for d, name in enumerate(names):
            p = np.percentile(e[:, d], [50, 90, 99, 100])
            print(f"| {policy} | {len(s)} | {name} | " + " | ".join(f"{v:.3f}" for v in p) + " |")
    compare_models(args.episodes, args.ahead)


if __name__ == "__main__":
    main()
