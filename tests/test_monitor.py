"""The task monitor: one call per step gives what the separate automaton calls give, and
``Shield.filter_monitor(monitor, a_rl)`` equals ``Shield.filter(s, q, a_rl)`` on the same step."""

import re
from pathlib import Path

import numpy as np
import pytest

import tlshield
from tests.fixtures import progress_step, task_shield
from tlshield.envs.channel import channel_task_spec


def _episode(rng: np.random.Generator, steps: int) -> np.ndarray:
    """States along the channel's diagonal with sideways jitter, past g1/g2 (at 4) to g3 (at 9):
    the task's FSA states all occur, and the wide-jitter episodes leave the channel (the trap)."""
    s = np.zeros((steps, 13))
    along = np.linspace(0.0, 10.0, steps)
    jitter = rng.choice([0.5, 1.8])
    off = rng.uniform(-jitter, jitter, steps)
    s[:, 0], s[:, 1] = along + off / 2, along - off / 2
    s[:, 2] = rng.uniform(-np.pi, np.pi, steps)
    s[:, 3:9] = [4.0, 4.0, 4.5, 6.5, 9.0, 9.0]
    s[:, 9:13] = [20.0, 20.0, 20.0, -20.0]
    return s


@pytest.mark.parametrize("reward", ["progress", "paper"])
def test_monitor_equals_the_separate_calls(reward):
    shield = task_shield()
    aut = shield.automaton
    progress = aut.progress_reward(gamma=0.99, horizon=200, exclusive=[["g1", "g2", "g3"]])
    if reward == "progress":
        monitor = tlshield.Monitor(aut, progress)
    else:
        monitor = tlshield.Monitor(aut, c_r=2.0, trap_penalty=-30.0)
    rng = np.random.default_rng(3)
    seen = set()
    for _ in range(20):
        traj = _episode(rng, 60)
        first = monitor.reset(traj[0])
        q, phi = aut.step(traj[0], aut.initial), 0.0
        assert (first.q, first.reward) == (q, 0.0)
        for s in traj[1:]:
            got = monitor.advance(s)
            if reward == "progress":
                q_next, r, phi = progress_step(aut, progress, q, phi, s)
            else:
                r = aut.reward(s, q, 2.0, trap_penalty=-30.0)
                q_next = aut.step(s, q)
            assert got.q == q_next == monitor.q
            assert got.reward == r
            assert got.accepted == (q_next in aut.accepting)
            assert got.trapped == (q_next == aut.trap)
            goal = aut.goal(s, q_next)
            assert (got.goal is None) == (goal is None)
            if goal is not None:
                np.testing.assert_array_equal(got.goal, goal)
                np.testing.assert_array_equal(monitor.goal, goal)
            np.testing.assert_array_equal(monitor.state, s)
            np.testing.assert_array_equal(got.atom_robustness, aut.spec.atom_robustness(s))
            a = rng.uniform([-1.0, -2.0], [1.0, 2.0])
            via_monitor, direct = shield.filter_monitor(monitor, a), shield.filter(s, q_next, a)
            np.testing.assert_array_equal(via_monitor.action, direct.action)
            assert via_monitor.delta == direct.delta
            assert via_monitor.barriers == direct.barriers
            assert via_monitor.status == direct.status
            seen.add(q_next)
            q = q_next
    # Every state of the task was reached: start, after g1/g2, accepting, trap.
    assert seen == set(range(aut.num_states))


def test_monitor_misuse_is_a_clear_error():
    shield = task_shield()
    aut = shield.automaton
    monitor = tlshield.Monitor(aut)
    with pytest.raises(tlshield.AutomatonError, match=r"call reset\(s0\)"):
        monitor.advance(np.zeros(13))
    with pytest.raises(tlshield.AutomatonError, match=r"call reset\(s0\)"):
        shield.filter_monitor(monitor, np.zeros(2))
    with pytest.raises(ValueError, match="s0"):
        monitor.reset(np.zeros(12))
    with pytest.raises(ValueError, match="NaN"):
        monitor.reset(np.full(13, np.nan))
    monitor.reset(np.zeros(13))
    with pytest.raises(TypeError, match="s is a Monitor; use filter_monitor"):
        shield.filter(monitor, np.zeros(2), np.zeros(2))
    with pytest.raises(TypeError, match="a_rl"):
        shield.filter(np.zeros(13), 0)
    with pytest.raises(ValueError, match="a_rl"):
        shield.filter_monitor(monitor, np.zeros(3))
    # An equal spec shares its automaton (copies and pickles rely on it); another task's
    # automaton is refused.
    fresh = channel_task_spec.__wrapped__()
    same = tlshield.Monitor(fresh.automaton())
    same.reset(np.zeros(13))
    assert shield.filter_monitor(same, np.zeros(2)).action.tolist() == (
        shield.filter_monitor(monitor, np.zeros(2)).action.tolist()
    )
    other = tlshield.Spec("F g1 & F g3", {k: fresh.predicates[k] for k in ("g1", "g3")})
    foreign = tlshield.Monitor(other.automaton())
    foreign.reset(np.zeros(13))
    with pytest.raises(tlshield.ShieldError, match="another automaton"):
        shield.filter_monitor(foreign, np.zeros(2))
    with pytest.raises(ValueError, match="c_r"):
        tlshield.Monitor(aut, c_r=0.0)
    with pytest.raises(ValueError, match="trap_penalty"):
        tlshield.Monitor(aut, trap_penalty=float("inf"))
    # A progress reward of another automaton is refused; one of an equal spec's is the same.
    with pytest.raises(ValueError, match="another automaton"):
        tlshield.Monitor(aut, other.automaton().progress_reward())
    assert tlshield.Monitor(aut, fresh.automaton().progress_reward()).q == aut.initial
    with pytest.raises(TypeError, match="automaton"):
        tlshield.Monitor("F a")  # type: ignore[arg-type]


def test_the_monitor_form_reads_any_layout_of_a_rl():
    shield = task_shield()
    monitor = tlshield.Monitor(shield.automaton)
    monitor.reset(_episode(np.random.default_rng(0), 2)[0])
    a = np.array([0.7, -1.5])
    want = shield.filter_monitor(monitor, a).action
    big = np.zeros(4)
    big[::2] = a
    read_only = a.copy()
    read_only.flags.writeable = False
    for layout in (a[::-1].copy()[::-1], big[::2], read_only, a.tolist()):
        np.testing.assert_array_equal(shield.filter_monitor(monitor, layout).action, want)
    single = a.astype(np.float32)
    np.testing.assert_array_equal(
        shield.filter_monitor(monitor, single).action,
        shield.filter_monitor(monitor, single.astype(float)).action,
    )
    np.testing.assert_array_equal(
        shield.filter_monitor(monitor, np.array([1, -2])).action,
        shield.filter_monitor(monitor, [1.0, -2.0]).action,
    )
    with pytest.raises(TypeError, match="a_rl"):
        shield.filter_monitor(monitor, np.array([1 + 1j, 0]))


def test_the_readme_loop_runs():
    """The docs' two-call loop (guides/own-loop.md), as printed, on Channel-v0's plant (the env's
    own shield off, its observation the 13 state values): it runs and the monitor ends in a
    task state."""
    import gymnasium as gym

    from tlshield.envs.channel import ChannelEnv

    page = Path(__file__).resolve().parent.parent / "docs" / "guides" / "own-loop.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
    (loop,) = [b for b in blocks if "shield.filter_monitor(monitor" in b]

    class StateOnly(gym.ObservationWrapper):
        def observation(self, obs):
            return obs[:13]

    env = StateOnly(ChannelEnv(config="rl", observation="paper"))
    added = []

    class Buffer:
        def add(self, *row):
            added.append(row)

    scope = {
        "spec": channel_task_spec(),
        "env": env,
        "policy": lambda obs: np.array([0.5, 0.0]),
        "obstacle_motion": lambda s: np.zeros(13),
        "buffer": Buffer(),
    }
    exec(compile(loop, "own-loop.md", "exec"), scope)
    assert len(added) >= 1
    assert all(isinstance(r, float) for _, r, _ in added)
    assert scope["t"] >= 0 and scope["task"].q == scope["monitor"].q


def test_the_readme_automaton_loops_run_and_agree():
    """The docs' spec and automaton blocks (guides/your-task.md), as printed: the per-query loop
    (state first) and the monitor's one call per step end in the same FSA state."""
    page = Path(__file__).resolve().parent.parent / "docs" / "guides" / "your-task.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
    (spec_block,) = [b for b in blocks if "tlshield.Spec(" in b and "robustness_batch" in b]
    (aut_block,) = [b for b in blocks if "aut.step(traj[0], aut.initial)" in b]
    scope: dict = {}
    exec(compile(spec_block + aut_block, "your-task.md", "exec"), scope)
    assert scope["task"].q == scope["q"] == scope["monitor"].q


@pytest.mark.parametrize("rows", [5, 40])  # 40: past the parallel threshold
def test_monitor_batch_equals_single_monitors_and_the_state_batch(rows):
    shield = task_shield()
    aut = shield.automaton
    progress = aut.progress_reward(gamma=0.99, horizon=200, exclusive=[["g1", "g2", "g3"]])
    batch = tlshield.MonitorBatch(aut, rows, progress)
    singles = [tlshield.Monitor(aut, progress) for _ in range(rows)]
    rng = np.random.default_rng(11)
    episodes = np.stack([_episode(rng, 40) for _ in range(rows)])  # (rows, T, 13)
    for t in range(episodes.shape[1]):
        states = episodes[:, t]
        got = batch.reset(states) if t == 0 else batch.advance(states)
        want = [
            m.reset(s) if t == 0 else m.advance(s) for m, s in zip(singles, states, strict=True)
        ]
        np.testing.assert_array_equal(got.q, [w.q for w in want])
        np.testing.assert_array_equal(got.reward, [w.reward for w in want])
        np.testing.assert_array_equal(got.accepted, [w.accepted for w in want])
        np.testing.assert_array_equal(got.trapped, [w.trapped for w in want])
        np.testing.assert_array_equal(batch.q, got.q)
        a = rng.uniform([-1.0, -2.0], [1.0, 2.0], size=(rows, 2))
        via_monitors = shield.filter_monitors(batch, a)
        via_states = shield.filter_batch(states, got.q, a)
        np.testing.assert_array_equal(via_monitors.action, via_states.action)
        np.testing.assert_array_equal(via_monitors.status, via_states.status)
        for i in (0, rows - 1):
            np.testing.assert_array_equal(
                via_monitors.action[i], shield.filter_monitor(singles[i], a[i]).action
            )
    # Restarting some rows: the others go on.
    again = batch.reset(episodes[[3, 1], 0], rows=[3, 1])
    assert len(again) == 2 and list(again.reward) == [0.0, 0.0]


def test_monitor_batch_misuse_is_a_clear_error():
    shield = task_shield()
    batch = tlshield.MonitorBatch(shield.automaton, 3)
    states = np.zeros((3, 13))
    with pytest.raises(ValueError, match="row 0"):
        batch.advance(states)
    with pytest.raises(ValueError, match="monitors row 0"):
        shield.filter_monitors(batch, np.zeros((3, 2)))
    batch.reset(states)
    with pytest.raises(ValueError, match="states"):
        batch.advance(np.zeros((2, 13)))
    with pytest.raises(ValueError, match=r"states\[1, 4\]"):
        bad = states.copy()
        bad[1, 4] = np.nan
        batch.advance(bad)
    with pytest.raises(ValueError, match=r"rows\[1\]"):
        batch.reset(np.zeros((2, 13)), rows=[2, 2])
    with pytest.raises(ValueError, match=r"rows\[0\]"):
        batch.reset(np.zeros((1, 13)), rows=[3])
    with pytest.raises(ValueError, match=r"rows\[0\] = -1"):
        batch.reset(np.zeros((1, 13)), rows=[-1])
    with pytest.raises(TypeError, match="rows"):
        batch.reset(np.zeros((1, 13)), rows=[0.5])
    with pytest.raises(ValueError, match="a_rl"):
        shield.filter_monitors(batch, np.zeros((2, 2)))
    with pytest.raises(TypeError, match="states is a MonitorBatch; use filter_monitors"):
        shield.filter_batch(batch, np.zeros((3, 2)), np.zeros((3, 2)))
    with pytest.raises(TypeError, match="a_rl"):
        shield.filter_batch(states, np.zeros(3, dtype=int))
    # An equal spec shares the automaton (so copies and pickles do); a different one is refused.
    spec = channel_task_spec()
    equal = tlshield.Spec(str(spec), spec.predicates, spec.exclusive)
    assert tlshield.MonitorBatch(equal.automaton(), 3).reset(states).q.tolist() == (
        batch.reset(states).q.tolist()
    )
    other_spec = tlshield.Spec("F g1 & F g2", {k: spec.predicates[k] for k in ("g1", "g2")})
    other = tlshield.MonitorBatch(other_spec.automaton(), 3)
    other.reset(states)
    with pytest.raises(tlshield.ShieldError, match="another automaton"):
        shield.filter_monitors(other, np.zeros((3, 2)))


def test_one_error_for_a_monitor_without_an_episode() -> None:
    """Wherever a monitor is read before its episode starts (one monitor, a batch's rows, the
    batch's states), the error is the same kind, AutomatonError (a ValueError), and names the
    row of a batch."""
    shield = task_shield()
    monitor = tlshield.Monitor(shield.automaton)
    with pytest.raises(tlshield.AutomatonError, match=r"call reset\(s0\)"):
        shield.filter_monitor(monitor, np.zeros(2))
    batch = tlshield.MonitorBatch(shield.automaton, 2)
    for call in (lambda: shield.filter_monitors(batch, np.zeros((2, 2))), lambda: batch.states):
        with pytest.raises(tlshield.AutomatonError, match="monitors row 0 has no episode yet"):
            call()
    assert issubclass(tlshield.AutomatonError, ValueError)
