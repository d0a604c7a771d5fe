"""Off-policy learners through the shield on Safety-Gymnasium: TD3 with the exact shield inside
its actor (``--algo td3_layer``, issue 45's fourth lever: the critic's gradient flows through
``tlshield.torch.ShieldLayer``, as Dalal et al. (2018) trained DDPG through a closed-form safety
layer), or SAC or TD3 with the shield in the env only (``--algo sac``, ``--algo td3``, on
``--config``, by default ``rl_cbf_clf``: the policy is a residual on the routed CLF in the
robot's units, as PPO's ``rl_cbf_clf`` row).

    .venv/bin/python scripts/safety_gym_td3_layer.py --seed 0 [--steps 200000] \\
        [--algo td3_layer|td3|sac] [--config rl_cbf_clf] \\
        [--env SafetyPointGoal1-v0] [--episodes 10] [--out results_td3]

Both off-policy learners take SB3's defaults but for 64-64 networks (as PPO's rows; a CPU
budget) and, for TD3, Gaussian action noise 0.1.

The actor maps Safety-Gymnasium's standard observation to an action in the shield's units
(thrust and turn in ``[-1, 1]``), then through the shield of ``rl_cbf`` at the privileged state
and the automaton state of that step; the env (``rl_cbf``) applies the same shield to what it
is sent, so the actor's safe action passes unchanged and TD3's exploration noise is made safe
by the env. The critic sees the standard observation and the action; the privileged state
reaches only the layer. SB3's TD3 (its defaults, 64-64 networks, Gaussian action noise 0.1,
CPU, one thread). After training, the last policy (deterministic) is evaluated on the
evaluation reset seeds of every benchmark row (``EVAL_SEED + k``); there is no validation, so
no kept policy. Writes ``OUT/<env>-td3_layer-s<seed>.json`` and prints the row.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np


class ShieldUnits(gym.Wrapper):  # type: ignore[type-arg]
    """The env in the shield's units, its observation with the privileged state and the
    automaton state appended (for the actor's layer; the networks see the first part)."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self.n_obs = env.observation_space.shape[0]
        self.n_state = env.unwrapped._state_dim
        n = self.n_obs + self.n_state + 1
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (n,), np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float64)

    def _augment(self, obs: np.ndarray) -> np.ndarray:
        inner = self.env.unwrapped
        return np.concatenate([obs, inner.monitor.state, [float(inner.monitor.q)]])

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return self._augment(obs), info

    def step(self, u: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        inner = self.env.unwrapped
        action = inner.env_action(np.clip(np.asarray(u, dtype=np.float64), -1.0, 1.0))
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._augment(obs), reward, terminated, truncated, info


def policy_class(layer: Any, n_obs: int, n_state: int) -> type:
    """A TD3 policy whose actor ends in ``layer`` and whose networks read the first ``n_obs``
    values of the observation."""
    import torch
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
    from stable_baselines3.td3.policies import Actor, TD3Policy

    class Standard(BaseFeaturesExtractor):  # type: ignore[misc]
        def __init__(self, observation_space: gym.spaces.Box) -> None:
            super().__init__(observation_space, n_obs)

        def forward(self, obs: torch.Tensor) -> torch.Tensor:
            return obs[:, :n_obs]

    class LayerActor(Actor):  # type: ignore[misc]
        def forward(self, obs: torch.Tensor) -> torch.Tensor:
            u = super().forward(obs)  # tanh: in [-1, 1]
            states = obs[:, n_obs : n_obs + n_state].detach().double()
            qs = obs[:, -1].detach().round().long()
            return layer(states, qs, u)

    class LayerPolicy(TD3Policy):  # type: ignore[misc]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            kwargs["features_extractor_class"] = Standard
            super().__init__(*args, **kwargs)

        def make_actor(self, features_extractor: Any = None) -> Actor:
            kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
            return LayerActor(**kwargs).to(self.device)

    return LayerPolicy


def evaluate(
    model: Any, env_id: str, episodes: int, config: str = "rl_cbf", layer: bool = True
) -> tuple[list[float], list[float]]:
    """Return (Safety-Gymnasium's reward) and cost of the deterministic policy per episode, in
    the env it trained in."""
    from tlshield.envs.safety_gym import SafetyGoalEnv
    from tlshield.lab.seeds import EVAL_SEED

    inner = SafetyGoalEnv(env_id, config)
    env: Any = ShieldUnits(inner) if layer else inner
    returns, costs = [], []
    for k in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED + k)
        ret = cost = 0.0
        done = False
        while not done:
            u = model.predict(obs, deterministic=True)[0]
            obs, _, terminated, truncated, info = env.step(u)
            ret += info["task_reward"]
            cost += info["cost"]
            done = terminated or truncated
        returns.append(ret)
        costs.append(cost)
    return returns, costs


def main() -> None:
    warnings.filterwarnings("ignore", category=RuntimeWarning)  # gymnasium's Box casts
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--env", default="SafetyPointGoal1-v0")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--out", default="results_td3")
    parser.add_argument("--algo", choices=("td3_layer", "td3", "sac"), default="td3_layer")
    parser.add_argument(
        "--config",
        default="rl_cbf_clf",
        help="the env's shield for --algo td3/sac (td3_layer: rl_cbf, the layer's own)",
    )
    args = parser.parse_args()
    import torch
    from stable_baselines3 import SAC, TD3
    from stable_baselines3.common.noise import NormalActionNoise

    from tlshield.envs.safety_gym import SafetyGoalEnv
    from tlshield.lab.seeds import learner_seed, train_seed
    from tlshield.torch import ShieldLayer

    torch.set_num_threads(1)
    start = time.perf_counter()
    layer = args.algo == "td3_layer"
    config = "rl_cbf" if layer else args.config
    inner = SafetyGoalEnv(args.env, config)
    env: Any = ShieldUnits(inner) if layer else inner
    env.reset(seed=train_seed(args.seed))
    common: dict[str, Any] = {
        "seed": learner_seed(args.seed),
        "device": "cpu",
        "policy_kwargs": {"net_arch": [64, 64]},
        "verbose": 0,
    }
    noise = NormalActionNoise(np.zeros(2), 0.1 * np.ones(2))
    if layer:
        assert inner.shield is not None
        policy = policy_class(ShieldLayer(inner.shield), env.n_obs, env.n_state)
        model: Any = TD3(policy, env, action_noise=noise, **common)
    elif args.algo == "td3":
        model = TD3("MlpPolicy", env, action_noise=noise, **common)
    else:
        model = SAC("MlpPolicy", env, **common)
    costs = {"train": 0.0}

    from stable_baselines3.common.callbacks import BaseCallback

    class Cost(BaseCallback):  # type: ignore[misc]
        def _on_step(self) -> bool:
            costs["train"] += float(self.locals["infos"][0]["cost"])
            return True

    model.learn(total_timesteps=args.steps, callback=Cost())
    returns, eval_costs = evaluate(model, args.env, args.episodes, config, layer)
    row = {
        "env": args.env,
        "method": f"{config}+{args.algo}",
        "seed": args.seed,
        "steps": int(model.num_timesteps),
        "last_return": float(np.mean(returns)),
        "last_cost": float(np.mean(eval_costs)),
        "train_cost": costs["train"],
        "wall_s": time.perf_counter() - start,
        "last_returns": returns,
        "last_costs": eval_costs,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "td3_layer" if layer else f"{config}+{args.algo}"
    (out / f"{args.env}-{name}-s{args.seed}.json").write_text(json.dumps(row, indent=2))
    print(json.dumps({k: v for k, v in row.items() if not isinstance(v, list)}))


if __name__ == "__main__":
    main()
