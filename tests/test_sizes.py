"""No size takes the interpreter down: every public constructor and batch call
that allocates by an argument's size, given 10**12, 2**62 and sys.maxsize (as counts, lengths,
``range`` objects or broadcast numpy views, which name that many values without holding
them), raises a Python exception in a child process -- never a signal. And every batch call
takes 0 rows, giving correctly shaped empty results."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import tlshield
import tlshield.vector
from tests.fixtures import task_shield

SIZES = {"10**12": 10**12, "2**62": 2**62, "sys.maxsize": sys.maxsize}

#: Set-up every child runs first: the paper's task, its shield and monitors, and ``B(shape)``,
#: a broadcast view of zeros of that shape (numpy refuses shapes of more than sys.maxsize
#: values: then the call cannot be made, and the child says so).
PRELUDE = """
import json, sys
import numpy as np
import tlshield, tlshield.vector
from tests.fixtures import task_shield
from tlshield.envs.channel import ChannelEnv
from tlshield._core import ChannelWorld, step_worlds

shield = task_shield()
aut = shield.automaton
spec = aut.spec
batch = tlshield.MonitorBatch(aut, 3)
batch.reset(np.zeros((3, 13)))
monitor = tlshield.Monitor(aut)
env = ChannelEnv()
env.reset(seed=0)

def B(*shape, dtype=float):
    return np.broadcast_to(np.zeros((), dtype=dtype), shape)
"""

#: The calls, each a statement using N.
CALLS = {
    "MonitorBatch(automaton, N)": "tlshield.MonitorBatch(aut, N)",
    "MonitorBatch.reset(states (N, 13))": "batch.reset(B(N, 13))",
    "MonitorBatch.reset(states, rows (N,))": "batch.reset(np.zeros((3, 13)), rows=B(N, dtype=int))",
    "MonitorBatch.advance(states (N, 13))": "batch.advance(B(N, 13))",
    "Monitor.reset(s0 (N,))": "monitor.reset(B(N))",
    "Shield.filter_batch(states (N, 13), qs, a_rl)": (
        "shield.filter_batch(B(N, 13), B(N, dtype=int), B(N, 2))"
    ),
    "Shield.filter_monitors(monitors, a_rl (N, 2))": "shield.filter_monitors(batch, B(N, 2))",
    "Shield.filter(s (N,), q, a_rl)": "shield.filter(B(N), 0, np.zeros(2))",
    "Shield.filter(..., f (N,), g (N, 2))": (
        "shield.filter(np.zeros(13), 0, np.zeros(2), f=B(N), g=B(N, 2))"
    ),
    "Shield(cbf_bounds=(range(N), ...))": (
        "tlshield.Shield(spec, None, alpha=1.0, c3=1.0, k=1e4, cbf_bounds=(range(N), range(N)), "
        "clf_bounds=(-1.0, 1.0))"
    ),
    "Shield(inputs=N, scalar bounds)": (
        "tlshield.Shield(spec, None, alpha=1.0, c3=1.0, k=1e4, cbf_bounds=(-1.0, 1.0), "
        "clf_bounds=(-1.0, 1.0), inputs=N)"
    ),
    "ChannelWorld(params with horizon=N)": (
        "import dataclasses; p = env.params; "
        "tlshield._core.ChannelWorld(env.model, dataclasses.replace(p, task="
        "dataclasses.replace(p.task, horizon=N)), evaluation=True, channel_atoms=(0, 1))"
    ),
    "Automaton.step_batch(states (N, 13), qs (N,))": "aut.step_batch(B(N, 13), B(N, dtype=int))",
    "Automaton.run(traj (N, 13))": "aut.run(B(N, 13))",
    "Spec.robustness_batch(trajs (N, 2, 13))": "spec.robustness_batch(B(N, 2, 13))",
    "Spec.robustness(traj (N, 13))": "spec.robustness(B(N, 13))",
    "Spec(exclusive=range(N))": "tlshield.Spec(str(spec), spec.predicates, exclusive=range(N))",
    "Halfspace(w (N,))": "tlshield.Halfspace(B(N), 0.0)",
    "Ball(pos=range(N))": "tlshield.Ball(pos=range(N), radius=1.0, center=[0.0, 0.0])",
    "SingleIntegrator(pos=range(N))": "tlshield.SingleIntegrator(pos=range(N))",
    "DoubleIntegrator(pos=range(N), vel)": "tlshield.DoubleIntegrator(range(N), [2, 3])",
    "Automaton.progress_reward(horizon=N)": "aut.progress_reward(horizon=N)",
    "ControlAffine(state_dim=N)": (
        "tlshield.ControlAffine(lambda s: np.zeros(len(s)), lambda s: np.ones((len(s), 1)), "
        "state_dim=N, inputs=1)"
    ),
    "ControlAffine(inputs=N)": (
        "tlshield.ControlAffine(lambda s: np.zeros(2), lambda s: np.ones((2, 1)), state_dim=2, "
        "inputs=N)"
    ),
    "ControlAffine(state_dim=N, probe=(1, N))": (
        "tlshield.ControlAffine(lambda s: np.zeros(len(s)), lambda s: np.ones((len(s), 1)), "
        "state_dim=N, inputs=1, probe=B(1, N))"
    ),
    "step_worlds(actions (N, 2))": (
        "step_worlds([env._world], [env.tracker.monitor], B(N, 2), np.zeros((1, 26)))"
    ),
    "ChannelWorld.reset(s0 (N,))": "env._world.reset(B(N), np.zeros((2, 4)))",
    "gymnasium.make(Channel-v0, horizon=N)": (
        "import gymnasium; gymnasium.make('tlshield/Channel-v0', horizon=N)"
    ),
    "tlshield.vector.make(Channel-v0, N)": "tlshield.vector.make('tlshield/Channel-v0', N)",
    "tlshield.vector.make(PointMass-v0, N)": "tlshield.vector.make('tlshield/PointMass-v0', N)",
    "tlshield.sb3.make_vec_env(Channel-v0, N)": (
        "import tlshield.sb3; tlshield.sb3.make_vec_env('tlshield/Channel-v0', N)"
    ),
}

#: What a child may answer: a Python exception of these kinds, or that numpy itself could not
#: make the input (a shape of more than sys.maxsize values).
ALLOWED = ("MemoryError", "ValueError", "TypeError", "OverflowError", "numpy refuses the input")


def _child(statement: str) -> str:
    sizes = json.dumps(SIZES)
    return PRELUDE + textwrap.dedent(f"""
    out = {{}}
    for label, N in {sizes}.items():
        try:
            inputs_ok = True
            try:
                compile({statement!r}, "<call>", "exec")
                exec({statement!r}.replace("B(", "B_checked("), {{**globals(), "N": N,
                     "B_checked": B_checked}})
                out[label] = "ok"
            except _NumpyRefused:
                out[label] = "numpy refuses the input"
        except BaseException as err:  # noqa: BLE001 - every exception is an outcome
            out[label] = type(err).__name__ + ": " + str(err).splitlines()[0][:160]
    print(json.dumps(out))
    """)


# B_checked tells numpy's refusal to build the input apart from the call's own errors.
PRELUDE += """
class _NumpyRefused(Exception):
    pass

def B_checked(*shape, dtype=float):
    try:
        return B(*shape, dtype=dtype)
    except ValueError as err:
        raise _NumpyRefused(str(err)) from err
"""


def _run(name: str) -> tuple[str, subprocess.CompletedProcess[str]]:
    proc = subprocess.run(
        [sys.executable, "-c", _child(CALLS[name])],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=str(__import__("pathlib").Path(__file__).resolve().parents[1]),
    )
    return name, proc


@pytest.fixture(scope="module")
def outcomes() -> dict[str, subprocess.CompletedProcess[str]]:
    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(pool.map(_run, CALLS))


@pytest.mark.parametrize("name", CALLS)
def test_no_size_ends_the_process_with_a_signal(
    outcomes: dict[str, subprocess.CompletedProcess[str]], name: str
) -> None:
    proc = outcomes[name]
    assert proc.returncode == 0, f"{name}: exit {proc.returncode}\n{proc.stderr[-2000:]}"
    assert "panicked" not in proc.stderr and "PanicException" not in proc.stdout, proc.stderr
    answers = json.loads(proc.stdout.strip().splitlines()[-1])
    print(f"\n{name}: {answers}")
    assert set(answers) == set(SIZES)
    for label, answer in answers.items():
        assert answer.startswith(ALLOWED), f"{name} at N = {label}: {answer}"
    # The call was made at 10**12 at least (numpy can broadcast that many rows of 13).
    assert answers["10**12"] != "numpy refuses the input", name


def test_a_size_past_memory_names_the_argument() -> None:
    with pytest.raises(MemoryError, match="num: 1000000000000 items"):
        tlshield.MonitorBatch(task_shield().automaton, 10**12)
    states = np.broadcast_to(np.zeros(13), (10**12, 13))
    with pytest.raises(MemoryError, match="states: 13000000000000 items"):
        task_shield().filter_batch(states, np.zeros(10**12 // 10**12, dtype=int), np.zeros((1, 2)))
    with pytest.raises(ValueError, match=r"num_envs = 100000: at most 65536"):
        tlshield.vector.make("tlshield/Channel-v0", 100_000)


# --- empty batches ------------------------------------------------------------------------


def test_every_batch_call_takes_zero_rows() -> None:
    shield = task_shield()
    aut = shield.automaton
    out = shield.filter_batch(np.zeros((0, 13)), np.zeros(0, dtype=int), np.zeros((0, 2)))
    assert out.action.shape == out.a_cbf.shape == out.a_clf.shape == (0, 2)
    assert out.delta.shape == out.slack.shape == out.status.shape == out.solver.shape == (0,)
    assert len(out) == 0
    drift = shield.filter_batch(np.zeros((0, 13)), [], np.zeros((0, 2)), drift=np.zeros((0, 13)))
    assert drift.action.shape == (0, 2)
    # An empty batch still says how long its rows are: a wrong length is refused.
    with pytest.raises(ValueError, match="state"):
        shield.filter_batch(np.zeros((0, 1)), np.zeros(0, dtype=int), np.zeros((0, 2)))
    assert aut.step_batch(np.zeros((0, 13)), np.zeros(0, dtype=int)).shape == (0,)
    assert aut.spec.robustness_batch(np.zeros((0, 5, 13))).shape == (0,)
    empty = tlshield.MonitorBatch(aut, 0)
    assert len(empty) == 0 and empty.q.shape == (0,)
    for step in (empty.reset(np.zeros((0, 13))), empty.advance(np.zeros((0, 13)))):
        assert len(step) == 0
        assert step.q.shape == step.reward.shape == step.accepted.shape == (0,)
    assert shield.filter_monitors(empty, np.zeros((0, 2))).action.shape == (0, 2)
    rows = tlshield.MonitorBatch(aut, 2)
    rows.reset(np.zeros((2, 13)))
    assert len(rows.reset(np.zeros((0, 13)), rows=[])) == 0
    from tlshield._core import step_worlds

    out = step_worlds([], [], np.zeros((0, 2)), np.zeros((0, 26)))
    assert out.observation.shape == (0, 26) and out.reward.shape == (0,)


@pytest.mark.parametrize("n", [0, -1])
def test_a_vector_env_of_no_env_is_a_clear_value_error(n: int) -> None:
    import tlshield.sb3

    for make in (tlshield.vector.make, tlshield.sb3.make_vec_env):
        with pytest.raises(ValueError, match=f"num_envs = {n}: a vector env needs at least one"):
            make("tlshield/Channel-v0", n)
    with pytest.raises(ValueError, match="at least one environment"):
        tlshield.vector.WorldBatch([])
    with pytest.raises(TypeError, match=r"num_envs = 2\.5"):
        tlshield.vector.make("tlshield/PointMass-v0", 2.5)
