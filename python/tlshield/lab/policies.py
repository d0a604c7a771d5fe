"""Policies for PPO whose actions stay inside the action box ``[-1, 1]^m``.

SB3's default continuous policy is a diagonal Gaussian whose samples are clipped to the box
before they reach the environment. Its mean can drift past the box: every sample is then
clipped to the same edge, the environment sees one action, and the gradient of the log-likelihood
keeps pushing the mean further out (measured on Channel-v0: the forward-speed mean at 1.7-1.9
and 98-100% of the actions on the edge in the runs that collapsed; see docs/learning.md).

* ``"gaussian"``: SB3's own (the mean is unbounded, samples clipped).
* ``"tanh_mean"``: the Gaussian's mean is ``tanh`` of the network's output, so the mean stays
  inside the box; samples are still clipped.
* ``"squashed"``: the sample itself is ``tanh`` of a Gaussian sample (SAC's distribution), so
  the action taken is the action whose likelihood PPO improves; nothing is clipped.

Imported by training only (it imports Stable-Baselines3 and torch).
"""

from __future__ import annotations

from typing import Any

import torch
from stable_baselines3.common.distributions import (
    DiagGaussianDistribution,
    Distribution,
    SquashedDiagGaussianDistribution,
)
from stable_baselines3.common.policies import ActorCriticPolicy

__all__ = ["POLICIES", "SquashedGaussianPolicy", "TanhMeanPolicy", "policy_class"]


class TanhMeanPolicy(ActorCriticPolicy):
    """A diagonal Gaussian with mean ``tanh(action_net(latent))``."""

    def _get_action_dist_from_latent(self, latent_pi: torch.Tensor) -> Distribution:
        assert isinstance(self.action_dist, DiagGaussianDistribution)
        return self.action_dist.proba_distribution(
            torch.tanh(self.action_net(latent_pi)), self.log_std
        )


class SquashedGaussianPolicy(ActorCriticPolicy):
    """Actions ``tanh(u)``, ``u`` a diagonal Gaussian sample; log-likelihoods include the
    ``tanh`` Jacobian, and the deterministic action is ``tanh(mean)``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)

    def _build(self, lr_schedule: Any) -> None:
        # A subclass of SB3's DiagGaussianDistribution: the base class builds the same heads.
        self.action_dist = SquashedDiagGaussianDistribution(self.action_space.shape[0])
        super()._build(lr_schedule)


#: Policy names and their classes.
POLICIES: dict[str, type[ActorCriticPolicy]] = {
    "gaussian": ActorCriticPolicy,
    "tanh_mean": TanhMeanPolicy,
    "squashed": SquashedGaussianPolicy,
}


def policy_class(name: str) -> type[ActorCriticPolicy]:
    """The policy class of ``name`` (:data:`POLICIES`), or ValueError naming the choices."""
    try:
        return POLICIES[name]
    except KeyError:
        raise ValueError(f"policy {name!r}: expected one of {', '.join(POLICIES)}") from None
