"""One family of errors (issue 57, item 5): every input problem of a shield's call is a
``tlshield.ShieldError`` (a ValueError), as its docstring promises, whether the core finds it
or the bindings find it while converting the arguments; a wrong type stays a TypeError, and a
monitor without an episode an AutomatonError wherever it is read."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import tlshield

SPEC = tlshield.Spec("F g", {"g": tlshield.Ball([0, 1], 0.3, center=[3.0, 0.0])})
SHIELD = tlshield.Shield(
    SPEC,
    tlshield.SingleIntegrator([0, 1]),
    alpha=1.0,
    c3=1.0,
    k=1e4,
    cbf_bounds=(-1.0, 1.0),
    clf_bounds=(-1.0, 1.0),
)
S, A = np.zeros(2), np.zeros(2)
ROWS, QS, AS = np.zeros((3, 2)), np.zeros(3, dtype=int), np.zeros((3, 2))


def monitor() -> tlshield.Monitor:
    m = tlshield.Monitor(SPEC.automaton())
    m.reset(S)
    return m


CASES: list[tuple[str, Any]] = [
    ("filter: q out of range", lambda: SHIELD.filter(S, 9, A)),
    ("filter: negative q", lambda: SHIELD.filter(S, -1, A)),
    ("filter: s of rank 2", lambda: SHIELD.filter(ROWS, 0, A)),
    ("filter: s too short", lambda: SHIELD.filter(np.zeros(1), 0, A)),
    ("filter: NaN in s", lambda: SHIELD.filter(np.array([np.nan, 0.0]), 0, A)),
    ("filter: a_rl too long", lambda: SHIELD.filter(S, 0, np.zeros(3))),
    ("filter: drift of the wrong length", lambda: SHIELD.filter(S, 0, A, drift=np.zeros(5))),
    ("filter_monitor: a_rl of rank 2", lambda: SHIELD.filter_monitor(monitor(), AS)),
    ("filter_batch: qs out of range", lambda: SHIELD.filter_batch(ROWS, QS + 7, AS)),
    ("filter_batch: a_rl rows", lambda: SHIELD.filter_batch(ROWS, QS, np.zeros((2, 2)))),
    ("filter_batch: qs rows", lambda: SHIELD.filter_batch(ROWS, QS[:2], AS)),
    (
        "filter_monitors: a_rl rows",
        lambda: SHIELD.filter_monitors(tlshield.MonitorBatch(SPEC.automaton(), 2), AS),
    ),
    ("vjp_batch: grad rows", lambda: SHIELD.vjp_batch(ROWS, QS, AS, np.zeros((2, 2)))),
    ("jacobian_batch: states rank", lambda: SHIELD.jacobian_batch(np.zeros(3), QS, AS)),
    ("barrier_values: s too short", lambda: SHIELD.barrier_values(np.zeros(1))),
]


@pytest.mark.parametrize(("case", "call"), CASES, ids=[c for c, _ in CASES])
def test_every_input_problem_of_a_call_is_a_shield_error(case: str, call: Any) -> None:
    with pytest.raises(tlshield.ShieldError) as err:
        call()
    assert type(err.value) is tlshield.ShieldError and str(err.value), case


def test_a_monitor_without_an_episode_is_one_error_wherever_it_is_read() -> None:
    # The monitor's own problem, not the call's: AutomatonError from every call that reads it
    # (tests/test_monitor.py has the batch's).
    with pytest.raises(tlshield.AutomatonError, match=r"call reset\(s0\)"):
        SHIELD.filter_monitor(tlshield.Monitor(SPEC.automaton()), A)


def test_a_wrong_type_stays_a_type_error() -> None:
    with pytest.raises(TypeError, match="q: expected an integer FSA state"):
        SHIELD.filter(S, 0.5, A)
    with pytest.raises(TypeError, match="a_rl"):
        SHIELD.filter(S, 0, "x")
