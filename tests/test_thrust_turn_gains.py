"""A body that slides (``ThrustTurn``) with ``alpha <= drag <= alpha + alpha2`` (own-robot.md,
"alpha, alpha2"): with the thrust off, the drag alone keeps the sampled second-order row among
still discs, so the shield's QP has a solution at every heading, the heading across the
barrier (where the thrust has no hold on it) included. At the routing lab's earlier
``alpha = alpha2 = 2`` the same states make the shield give way."""

from __future__ import annotations

import numpy as np
import pytest

import tlshield
from tlshield.lab import routing

CENTRE, RADIUS = np.array([0.0, 0.0]), 0.5
THRUST, TURN = 2.0, 3.0


def _shield(alpha: float, alpha2: float, goal: np.ndarray) -> tlshield.Shield:
    """The routing lab's ThrustTurn shield with these gains, one disc, the goal behind it and
    no routing: the CLF pushes into the disc."""
    gains = routing.robot("thrust_turn").shield_kwargs | {"alpha": alpha, "alpha2": alpha2}
    spec = tlshield.Spec("F g", {"g": tlshield.Ball([0, 1], 0.2, center=list(goal))})
    barriers = {"disc": tlshield.Avoid(tlshield.Ball([0, 1], RADIUS, center=list(CENTRE)))}
    model = tlshield.ThrustTurn(THRUST, TURN, routing.DRAG)
    return tlshield.Shield(spec, model, barriers=barriers, dt=routing.DT, route=False, **gains)


def _h(p: np.ndarray) -> float:
    return float(np.linalg.norm(p - CENTRE)) - RADIUS


def _states(alpha: float, rng: np.random.Generator, count: int) -> list[np.ndarray]:
    """States of the barrier's safe set at ``alpha`` (``h >= 0`` and the sampled first-order
    condition ``psi = (h(y) - h(s)) / dt + alpha h(s) >= 0``, ``y = s + dt f(s)``), each with
    its heading across the barrier's gradient and its velocity into the disc as fast as
    ``psi >= 0`` lets it be."""
    dt = routing.DT
    out: list[np.ndarray] = []
    while len(out) < count:
        bearing = rng.uniform(-np.pi, np.pi)
        normal = np.array([np.cos(bearing), np.sin(bearing)])
        tangent = np.array([-normal[1], normal[0]])
        h = rng.uniform(0.005, 0.5)
        p = CENTRE + (RADIUS + h) * normal
        heading = bearing + rng.choice([-1.0, 1.0]) * np.pi / 2
        v_t = rng.uniform(-1.0, 1.0)
        for share in np.linspace(1.0, 0.0, 21):
            v = -share * alpha * h * normal + v_t * tangent
            psi = (_h(p + dt * v) - h) / dt + alpha * h
            if psi >= 0.0:
                out.append(np.array([p[0], p[1], heading, v[0], v[1]]))
                break
    return out


def _relaxed(alpha: float, alpha2: float, seed: int, count: int = 60) -> int:
    """How many of ``count`` such states, each under a random RL action, the QP relaxes."""
    rng = np.random.default_rng(seed)
    relaxed = 0
    for s in _states(alpha, rng, count):
        behind = CENTRE - (s[:2] - CENTRE)
        shield = _shield(alpha, alpha2, behind)
        out = shield.filter(s, shield.automaton.initial, rng.uniform(-1.0, 1.0, 2))
        relaxed += out.status != tlshield.Status.SOLVED
    return relaxed


@pytest.mark.parametrize("seed", range(4))
def test_at_alpha_up_to_the_drag_the_qp_has_a_solution_at_any_heading(seed: int) -> None:
    assert _relaxed(routing.DRAG, routing.DRAG, seed) == 0


def test_past_the_drag_the_same_states_make_it_give_way() -> None:
    # The contrast: the rule is what keeps the QP feasible, not the states being easy.
    assert _relaxed(2.0, 2.0, 0) > 5


def test_an_attack_across_the_barrier_never_gets_in() -> None:
    """Closed loop from 1.5-2.5 m out: full thrust at the disc, then, 0.3 m from its rim, the
    heading turned across it with the thrust still pushing in."""
    model = tlshield.ThrustTurn(THRUST, TURN, routing.DRAG)
    for seed in range(6):
        rng = np.random.default_rng(seed)
        bearing = rng.uniform(-np.pi, np.pi)
        out_there = np.array([np.cos(bearing), np.sin(bearing)])
        p = CENTRE + rng.uniform(1.5, 2.5) * out_there
        shield = _shield(routing.DRAG, routing.DRAG, CENTRE - out_there)
        s = np.array([p[0], p[1], rng.uniform(-np.pi, np.pi), 0.0, 0.0])
        turned = False
        for _ in range(300):
            to_disc = CENTRE - s[:2]
            heading = np.array([np.cos(s[2]), np.sin(s[2])])
            along = float(heading @ to_disc) / np.linalg.norm(to_disc)
            turned = turned or _h(s[:2]) < 0.3
            if turned:
                turn = -5.0 * along
            else:
                turn = 3.0 * float(heading[0] * to_disc[1] - heading[1] * to_disc[0])
            a_rl = np.array([np.sign(along) or 1.0, np.clip(turn, -1.0, 1.0)])
            out = shield.filter(s, shield.automaton.initial, a_rl)
            assert out.status == tlshield.Status.SOLVED
            s = model.step(s, out.action, routing.DT)
            assert _h(s[:2]) >= 0.0
