"""The shield as a differentiable PyTorch layer.

``ShieldLayer(shield)`` maps RL actions to safe actions, ``layer(states, qs, a_rl)`` or
``layer(monitors, a_rl)``. When a gradient is wanted, the forward pass asks the core for the
actions and their Jacobians in one pass (``Shield.jacobian_batch``: exact, from the active rows
of each solved QP, parallel over rows with the GIL released), and the backward pass is a
batched product with them. Gradients flow to ``a_rl`` and, when ``states`` requires them, to
the states (first-order rows and a built-in model; see ``Shield.vjp_batch``). Without a
gradient (``torch.no_grad()``, or nothing requiring one) the forward pass is ``filter_batch``.

Numbers: the core computes in float64. float32 and float64 tensors are accepted and the result
has ``a_rl``'s dtype and device. Tensors on a GPU cross to the host once each way per pass:
the forward pass packs ``a_rl``, the states, the FSA states and the drift into one float64
block on the device and copies it to pinned host memory in one transfer, and the safe actions
go back in one non-blocking copy from pinned memory; the Jacobians stay on the host until the
backward pass, which sends its upstream gradient down and the gradients (``a_rl``'s and the
states' together) back up, one transfer each.

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


def _to_host(parts: list[torch.Tensor], names: list[str]) -> list[NDArray[np.float64]]:
    """Tensors of ``B`` rows each (on one device) as float64 host arrays ``(B, k_i)``, in one
    transfer: packed side by side on the device, copied once (into pinned memory when a GPU
    is there), split on the host (views)."""
    for t, name in zip(parts, names, strict=True):
        if t.is_complex():
            raise TypeError(f"{name}: expected a real tensor, got {t.dtype}")
    rows = parts[0].shape[0]
    flat = [t.detach().reshape(rows, -1).to(torch.float64) for t in parts]
    packed = torch.cat(flat, dim=1)
    host = torch.empty(packed.shape, dtype=torch.float64, pin_memory=torch.cuda.is_available())
    host.copy_(packed, non_blocking=True)
    if packed.device.type == "cuda":
        torch.cuda.current_stream(packed.device).synchronize()
    values = host.numpy()
    out, at = [], 0
    for t in flat:
        out.append(values[:, at : at + t.shape[1]])
        at += t.shape[1]
    return out


def _to_device(values: list[NDArray[np.float64]], like: torch.Tensor) -> list[torch.Tensor]:
    """Host arrays of ``B`` rows as tensors with ``like``'s dtype and device, in one transfer
    (one block, pinned when a GPU is there, copied without blocking, split on the device)."""
    rows = values[0].shape[0]
    block = torch.from_numpy(np.concatenate([v.reshape(rows, -1) for v in values], axis=1))
    if torch.cuda.is_available():
        block = block.pin_memory()
    on_device = block.to(like.device, non_blocking=True).to(like.dtype)
    out, at = [], 0
    for v in values:
        k = v[:1].size
        out.append(on_device[:, at : at + k].reshape(v.shape))
        at += k
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
        host_a: NDArray[np.float64] | None = None,
    ) -> torch.Tensor:
        a = _host(a_rl, "a_rl") if host_a is None else host_a
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
        ctx.packed = host_a is not None
        if ctx.packed:
            return _to_device([action], a_rl)[0]
        return _like(action, a_rl)

    @staticmethod
    def backward(  # type: ignore[override]
        ctx: Any, grad: torch.Tensor
    ) -> tuple[torch.Tensor | None, ...]:
        jac_a, jac_s = ctx.jacobians
        # dL/da_rl_j = sum_k dL/da_k * da_k/da_rl_j, per row (and likewise for the states).
        g = _to_host([grad], ["grad"])[0] if ctx.packed else _host(grad, "grad")
        wanted = []
        if ctx.needs_input_grad[0]:
            wanted.append(("a_rl", np.einsum("bk,bkj->bj", g, jac_a)))
        if ctx.needs_input_grad[1] and jac_s is not None:
            wanted.append(("states", np.einsum("bk,bkj->bj", g, jac_s)))
        if not wanted:
            grads = {}
        elif ctx.packed:  # both gradients up in one transfer
            up = _to_device([v for _, v in wanted], grad)
            grads = dict(zip([k for k, _ in wanted], up, strict=True))
        else:
            grads = {k: _like(v, grad) for k, v in wanted}
        return grads.get("a_rl"), grads.get("states"), None, None, None, None, None


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
            host_states, q = None, qs
        d: Any = drift
        host_a = None
        if a_rl.device.type != "cpu" or self._pack:
            # One transfer down for every tensor on the device (see the module docs).
            host_a, host_states, q, d = self._pack_down(a_rl, states, host_states, q, drift)
        if host_states is None:
            host_states, q = _host(states, "states"), _qs(q)
        d = None if d is None else _host(d, "drift")
        return ShieldFunction.apply(a_rl, states_t, self, q, host_states, d, host_a)

    #: Packs the inputs for one transfer each way even on the CPU (the tests' way to run the
    #: GPU path's packing on a machine without a GPU).
    _pack = False

    def _pack_down(
        self, a_rl: torch.Tensor, states: Any, host_states: Any, qs: Any, drift: Any
    ) -> tuple[NDArray[np.float64], Any, Any, Any]:
        """``a_rl`` and the other inputs on ``a_rl``'s device to the host in one transfer."""
        device = a_rl.device
        parts, names = [a_rl], ["a_rl"]
        for value, name in ((states, "states"), (qs, "qs"), (drift, "drift")):
            if isinstance(value, torch.Tensor):
                if value.device != device:
                    raise ValueError(
                        f"{name} is on {value.device} and a_rl on {device}: put them on one device"
                    )
                if name == "qs" and (value.is_floating_point() or value.is_complex()):
                    raise TypeError(f"qs: expected an integer tensor, got {value.dtype}")
                if name != "qs" and not value.is_floating_point():
                    raise TypeError(f"{name}: expected a floating-point tensor, got {value.dtype}")
                parts.append(value)
                names.append(name)
        if not a_rl.is_floating_point():
            raise TypeError(f"a_rl: expected a floating-point tensor, got {a_rl.dtype}")
        host = dict(zip(names, _to_host(parts, names), strict=True))
        a = host["a_rl"].reshape(a_rl.shape)
        if "states" in host:
            host_states = host["states"].reshape(states.shape)
        if "qs" in host:  # exact: FSA states are small integers
            qs = host["qs"].reshape(-1).astype(np.int64)
        if "drift" in host:
            drift = host["drift"].reshape(drift.shape)
        return a, host_states, qs, drift

    def extra_repr(self) -> str:
        return repr(self.shield)
