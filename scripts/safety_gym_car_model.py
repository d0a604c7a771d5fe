"""Identifies Safety-Gymnasium's Car robot (issue 45, point 4) and measures the one-step error of
the candidate models against MuJoCo, as ``scripts/safety_gym_model.py`` does for the Point
(docs/guides/safety-gym.md, "The Car robot").

    .venv/bin/python scripts/safety_gym_car_model.py [--episodes 6] [--steps 500]

The Car is a differential drive: two wheel motors (``left``, ``right``) whose force MuJoCo
clips at ``±0.02``, on a free joint. Its state here is the centre ``x, y``, the heading ``psi``
it drives along when both wheels push forward (the body's ``-y`` axis, measured), the forward
speed ``v`` and the yaw rate ``omega``; the inputs are the saturated wheel commands
``u = clip(a / 0.02, -1, 1)``. Two models are fitted by least squares on random rollouts
(piecewise-constant actions, half of them within the saturation):

* second order: ``dv/dt = a_v (uL + uR) - d_v v``, ``domega/dt = a_w (uR - uL) - d_w omega``;
* kinematic (what ``tlshield.Unicycle`` takes): ``v = k_v (uL + uR)``, ``omega = k_w (uR - uL)``,
  the steady state of the first;

and the first as a lag over one step (``v' = keep v + push (uL + uR)``), whose fit of the next
value says how much of the rates' misfit is the fast lag rather than missing physics.

The one-step error of each model is ``|(s_{t+1} - s_t) / dt - (f(s_t) + g(s_t) u_t)|`` per
state dimension, the bound a shield's ``disturbance`` setting would need.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

#: Safety-Gymnasium's step for the Car: 10 MuJoCo steps of 0.004 s (the Point's are 0.002 s;
#: the first version of this script took 0.02 s, which doubled every rate), checked against
#: the model in :func:`rollouts`.
DT = 0.04
#: The wheel motors' force limit (MuJoCo's ``forcerange``).
SATURATION = 0.02


def car_state(env: object) -> np.ndarray:
    """``[x, y, psi, v, omega]`` of the Car: what the shield reads
    (:meth:`tlshield.envs.safety_gym.CarModel.read`: the point ``pivot`` behind the free
    joint's origin, the heading, the speed along it), then the yaw rate (the free joint's
    angular velocity about the vertical, in the body frame)."""
    from tlshield.envs.safety_gym import CAR

    model, data = env.task.model, env.task.data  # type: ignore[attr-defined]
    s = np.zeros(5)
    CAR.read(data, CAR.locate(model), s)
    s[4] = data.qvel[int(model.joint("agent").dofadr[0]) + 5]
    return s


def rollouts(episodes: int, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States before and after each step and the saturated wheel commands, over random
    rollouts of the unshielded SafetyCarGoal1-v0 (seeds 500, 501, ...)."""
    from tlshield.envs.safety_gym import make_builder

    env = make_builder("SafetyCarGoal1-v0")
    env.reset(seed=500)
    conf = env.task.sim_conf
    step = env.task.model.opt.timestep * conf.frameskip_binom_n
    if conf.frameskip_binom_p != 1.0 or abs(step - DT) > 1e-12:
        raise RuntimeError(f"the Car's step is {step} s (p {conf.frameskip_binom_p}), not {DT}")
    rng = np.random.default_rng(0)
    before, after, inputs = [], [], []
    for ep in range(episodes):
        env.reset(seed=500 + ep)
        action = np.zeros(2)
        for t in range(steps):
            if t % 10 == 0:
                action = rng.uniform(-1, 1, 2) * rng.choice([0.01, 1.0])
            s = car_state(env)
            _, _, _, terminated, truncated, info = env.step(action)
            if info.get("goal_met"):  # a new world: the next state is not this one's successor
                break
            before.append(s)
            after.append(car_state(env))
            inputs.append(np.clip(action / SATURATION, -1.0, 1.0))
            if terminated or truncated:
                break
    return np.array(before), np.array(after), np.array(inputs)


def wrapped(angle: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * angle))


def fit(s: np.ndarray, s2: np.ndarray, u: np.ndarray) -> dict[str, float]:
    """Both models' gains and the second-order fit's R^2 per rate."""
    total, diff = u[:, 0] + u[:, 1], u[:, 1] - u[:, 0]
    out: dict[str, float] = {}
    for name, command, k in (("v", total, 3), ("w", diff, 4)):
        rate = (s2[:, k] - s[:, k]) / DT
        x = np.stack([command, -s[:, k]], 1)
        (gain, drag), *_ = np.linalg.lstsq(x, rate, rcond=None)
        out[f"a_{name}"], out[f"d_{name}"] = float(gain), float(drag)
        out[f"r2_{name}"] = float(1.0 - np.var(rate - x @ [gain, drag]) / np.var(rate))
        out[f"k_{name}"] = float(gain / drag)
        # The same first-order lag over one 0.02 s step: next = keep * now + push * command.
        x = np.stack([s[:, k], command], 1)
        (keep, push), *_ = np.linalg.lstsq(x, s2[:, k], rcond=None)
        out[f"keep_{name}"], out[f"push_{name}"] = float(keep), float(push)
        out[f"r2d_{name}"] = float(1.0 - np.var(s2[:, k] - x @ [keep, push]) / np.var(s2[:, k]))
    return out


def kinematic_errors(
    s: np.ndarray, s2: np.ndarray, u: np.ndarray, k_v: float, k_w: float
) -> np.ndarray:
    """``|rate - model|`` on ``x, y, psi`` per step for the kinematic model."""
    v = k_v * (u[:, 0] + u[:, 1])
    w = k_w * (u[:, 1] - u[:, 0])
    rate = (s2[:, :3] - s[:, :3]) / DT
    rate[:, 2] = wrapped(s2[:, 2] - s[:, 2]) / DT
    model = np.stack([v * np.cos(s[:, 2]), v * np.sin(s[:, 2]), w], 1)
    return np.abs(rate - model)


def second_order_errors(
    s: np.ndarray, s2: np.ndarray, u: np.ndarray, g: dict[str, float]
) -> np.ndarray:
    """``|rate - model|`` on ``x, y, psi, v, omega`` per step for the second-order model
    (``dx/dt = v cos psi``, ``dpsi/dt = omega``, and the fitted lags)."""
    rate = (s2 - s) / DT
    rate[:, 2] = wrapped(s2[:, 2] - s[:, 2]) / DT
    v, w = s[:, 3], s[:, 4]
    model = np.stack(
        [
            v * np.cos(s[:, 2]),
            v * np.sin(s[:, 2]),
            w,
            g["a_v"] * (u[:, 0] + u[:, 1]) - g["d_v"] * v,
            g["a_w"] * (u[:, 1] - u[:, 0]) - g["d_w"] * w,
        ],
        1,
    )
    return np.abs(rate - model)


def shield_errors(s: np.ndarray, s2: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``|rate - model|`` on ``x, y, psi, v`` per step for the shield's model
    (:class:`tlshield.envs.safety_gym.CarModel`: the speed's lag, the turn as a rate), with
    its inputs ``u0 = (uL + uR) / 2``, ``u1 = (uL - uR) / 2``."""
    from tlshield.envs.safety_gym import CAR

    model = CAR.model(4)
    rate = (s2[:, :4] - s[:, :4]) / DT
    rate[:, 2] = wrapped(s2[:, 2] - s[:, 2]) / DT
    inputs = np.stack([(u[:, 0] + u[:, 1]) / 2.0, (u[:, 0] - u[:, 1]) / 2.0], 1)
    predicted = []
    for state, a in zip(s[:, :4], inputs, strict=True):
        f, g = model.eval(state)
        predicted.append(f + g @ a)
    return np.abs(rate - np.array(predicted))


def main() -> None:
    warnings.filterwarnings("ignore", category=RuntimeWarning)  # gymnasium's Box casts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=6)
    parser.add_argument("--steps", type=int, default=500)
    args = parser.parse_args()
    s, s2, u = rollouts(args.episodes, args.steps)
    g = fit(s, s2, u)
    print(f"{len(s)} steps of random rollouts")
    print(
        f"second order: dv/dt = {g['a_v']:.3f} (uL + uR) - {g['d_v']:.3f} v (R^2 {g['r2_v']:.2f}); "
        f"domega/dt = {g['a_w']:.3f} (uR - uL) - {g['d_w']:.3f} omega (R^2 {g['r2_w']:.2f})"
    )
    print(
        f"per step: v' = {g['keep_v']:.3f} v + {g['push_v']:.4f} (uL + uR) (R^2 {g['r2d_v']:.2f}); "
        f"omega' = {g['keep_w']:.3f} omega + {g['push_w']:.4f} (uR - uL) (R^2 {g['r2d_w']:.2f})"
    )
    print(f"kinematic: v = {g['k_v']:.3f} (uL + uR), omega = {g['k_w']:.3f} (uR - uL)")
    print(f"largest forward speed seen: {np.abs(s[:, 3]).max():.2f} m/s")
    names = (
        "dx/dt (m/s)",
        "dy/dt (m/s)",
        "dpsi/dt (rad/s)",
        "dv/dt (m/s^2)",
        "domega/dt (rad/s^2)",
    )
    print("\n| model | state rate | p50 | p90 | p99 | max |")
    print("|---|---|---:|---:|---:|---:|")
    for model, e in (
        ("kinematic", kinematic_errors(s, s2, u, g["k_v"], g["k_w"])),
        ("second order", second_order_errors(s, s2, u, g)),
        ("shield (CarModel)", shield_errors(s, s2, u)),
    ):
        for d in range(e.shape[1]):
            p = np.percentile(e[:, d], [50, 90, 99, 100])
            print(f"| {model} | {names[d]} | " + " | ".join(f"{x:.3f}" for x in p) + " |")


if __name__ == "__main__":
    main()
