"""The shield as a differentiable PyTorch layer.

``ShieldLayer(shield)`` maps RL actions to safe actions, ``layer(states, qs, a_rl)`` or
``layer(monitors, a_rl)``. When a gradient is wanted, the forward pass asks the core for the
actions and their Jacobians in one pass (``Shield.jacobian_batch``: exact, from the active rows
of each solved QP, parallel over rows with the GIL released), and the backward pass is a
batched product with them. Gradients flow to ``a_rl`` and, when ``states`` requires them, to
the states (first-order rows and a built-in model; see ``Shield.vjp_batch``). Without a
gradient (``torch.no_grad()``, or nothing requiring one) the forward pass is ``filter_batch``.

Numbers: the core computes in float64. float32 and float64 tensors are accepted and the result
has ``a_rl``'s dtype and device. CUDA tensors are copied to the host for the solve and the
result is copied back (a device-to-host and a host-to-device copy per call, each way).

The forward pass keeps the Jacobians of the rows it solved, so a backward pass after the
monitors have moved on still differentiates the step taken.

This module imports torch; ``import tlshield`` does not import it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from tlshield._core import MonitorBatch, Shield

__all__ = ["ShieldFunction", "ShieldLayer"]


def _host(t: torch.Tensor | NDArray[Any] | Any, name: str) -> NDArray[np.float64]:
    """Float64 host values of a tensor (a view when it already is one), or an array as given."""
    if isinstance(t, torch.Tensor):
        if not t.is_floating_point():
            raise TypeError(f"{name}: expected a floating-point tensor, got {t.dtype}")
        if t.dtype != torch.float64 or t.device.type != "cpu":
            t = t.detach().to("cpu", torch.float64)
        return t.detach().numpy()
    return np.asarray(t, dtype=np.float64)


def _like(values: NDArray[np.float64], like: torch.Tensor) -> torch.Tensor:
    """``values`` as a tensor with ``like``'s dtype and device (no copy when they match)."""
    out = torch.from_numpy(values)
    if like.dtype != torch.float64 or like.device.type != "cpu":
        out = out.to(like.device, like.dtype)
    return out


def _qs(qs: Any) -> NDArray[np.int64]:
    if isinstance(qs, torch.Tensor):
        if qs.is_floating_point() or qs.is_complex():
            raise TypeError(f"qs: expected an integer tensor, got {qs.dtype}")
        return qs.detach().cpu().numpy().astype(np.int64)
    return np.asarray(qs)


class ShieldFunction(torch.autograd.Function):
    """``safe = ShieldFunction.apply(a_rl, states, layer, qs, host_states, drift)``: the
    autograd function behind :class:`ShieldLayer` (``states`` a float tensor, or None for
    monitors' rows; ``host_states`` their float64 host copy)."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: Any,
        a_rl: torch.Tensor,
        states: torch.Tensor | None,
        layer: ShieldLayer,
        qs: NDArray[np.int64],
        host_states: NDArray[np.float64],
        drift: NDArray[np.float64] | None,
    ) -> torch.Tensor:
        a = _host(a_rl, "a_rl")
        want_states = states is not None and states.requires_grad
        if a_rl.requires_grad or want_states:
            action, jac_a, jac_s, flags = layer.shield.jacobian_batch(
                host_states, qs, a, drift, state_grad=want_states
            )
            layer.last_flags = flags
            ctx.jacobians = (jac_a, jac_s)
        else:
            action = layer.shield.filter_batch(host_states, qs, a, drift).action
            ctx.jacobians = None
        return _like(action, a_rl)

    @staticmethod
    def backward(  # type: ignore[override]
        ctx: Any, grad: torch.Tensor
    ) -> tuple[torch.Tensor | None, ...]:
        jac_a, jac_s = ctx.jacobians
        # dL/da_rl_j = sum_k dL/da_k * da_k/da_rl_j, per row (and likewise for the states).
        g = _host(grad, "grad")
        a_rl_grad = None
        if ctx.needs_input_grad[0]:
            a_rl_grad = _like(np.einsum("bk,bkj->bj", g, jac_a), grad)
        states_grad = None
        if ctx.needs_input_grad[1] and jac_s is not None:
            states_grad = _like(np.einsum("bk,bkj->bj", g, jac_s), grad)
        return a_rl_grad, states_grad, None, None, None, None


class ShieldLayer(torch.nn.Module):
    """A :class:`tlshield.Shield` as a layer: ``layer(states, qs, a_rl)`` (``states`` ``(B, n)``,
    ``qs`` ``(B,)``, ``a_rl`` ``(B, m)``) or ``layer(monitors, a_rl)`` with a
    :class:`tlshield.MonitorBatch`, returning the safe actions ``(B, m)``.

    After a forward pass that computed gradients, ``layer.last_flags`` holds the per-row
    ``tlshield.GradFlag`` bits (0: an exact two-sided gradient of a step solved as posed).
    """

    def __init__(self, shield: Shield) -> None:
        super().__init__()
        if not isinstance(shield, Shield):
            raise TypeError(f"shield: expected a tlshield.Shield, got {type(shield).__name__}")
        self.shield = shield
        #: The per-row gradient flags of the last forward pass that computed gradients.
        self.last_flags: NDArray[np.uint8] | None = None

    def forward(
        self,
        states: torch.Tensor | MonitorBatch,
        qs: Any,
        a_rl: torch.Tensor | None = None,
        drift: torch.Tensor | NDArray[Any] | None = None,
    ) -> torch.Tensor:
        if isinstance(states, MonitorBatch):
            if a_rl is not None:
                raise TypeError(
                    "ShieldLayer(monitors, a_rl): the monitors hold the states and the FSA "
                    "states; pass the RL actions second"
                )
            monitors, a_rl = states, qs
            if not isinstance(a_rl, torch.Tensor):
                raise TypeError(f"a_rl: expected a tensor, got {type(a_rl).__name__}")
            host_states, q = monitors.states, np.asarray(monitors.q)
            states_t = None
        else:
            if a_rl is None:
                raise TypeError("ShieldLayer(states, qs, a_rl): missing the RL actions a_rl")
            if not isinstance(a_rl, torch.Tensor):
                raise TypeError(f"a_rl: expected a tensor, got {type(a_rl).__name__}")
            states_t = states if isinstance(states, torch.Tensor) else None
            host_states, q = _host(states, "states"), _qs(qs)
        d = None if drift is None else _host(drift, "drift")
        return ShieldFunction.apply(a_rl, states_t, self, q, host_states, d)

    def extra_repr(self) -> str:
        return repr(self.shield)
