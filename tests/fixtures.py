"""What several test modules share, once: the paper's task shield with the reference
parameters (the task formula itself lives once, in :mod:`tlshield.envs.channel`)."""

from __future__ import annotations

import tlshield
from tests.shield_reference import Params
from tlshield.envs.channel import channel_task_spec

PARAMS = Params()


def task_shield(model: object | None = None, **overrides: object) -> tlshield.Shield:
    """A shield of the paper's task (unicycle eps = 0.1 unless ``model`` is given) with the
    reference parameters of :class:`tests.shield_reference.Params`; keywords override. Without
    routing, so that its QP is Eq. 5D2's as the references build it (routing is tested in
    tests/lab/test_routing.py)."""
    kwargs: dict[str, object] = {
        "route": False,
        "alpha": PARAMS.alpha,
        "c3": PARAMS.c3,
        "k": PARAMS.k,
        "cbf_bounds": PARAMS.cbf,
        "clf_bounds": PARAMS.clf,
        **overrides,
    }
    model = tlshield.Unicycle(0.1) if model is None else model
    return tlshield.Shield(channel_task_spec(), model, **kwargs)  # type: ignore[arg-type]


def progress_step(
    aut: tlshield.Automaton, progress: tlshield.ProgressReward, q: int, phi: float, s: object
) -> tuple[int, float, float]:
    """One step of the progress reward from ``(q, phi)`` into ``s``, ``(q_next, reward,
    phi_next)``, written from its definition (the trap pays its penalty, an accepted task
    nothing more, the step into acceptance ``-phi - step_cost + bonus``, any other
    ``phi_next - phi - step_cost``): the reference ``Monitor`` is checked against."""
    q_next = aut.step(s, q)
    phi_next = progress.potential(s, q_next)
    if q_next == aut.trap:
        reward = progress.trap_penalty
    elif q in aut.accepting:
        reward = 0.0
    elif q_next in aut.accepting:
        reward = -phi - progress.step_cost + progress.bonus
    else:
        reward = phi_next - phi - progress.step_cost
    return q_next, reward, phi_next
