"""``SafetyGoalEnv(sensing="lidar")``: the shield reads only the agent's observation
(``tlshield.envs.safety_gym.sensing``). No MuJoCo position is read (the env's privileged
readers are made to fail), the state written from an observation is a function of that
observation alone, and the shield alone and under the lidar hazard attacker keeps
Safety-Gymnasium's cost at 0 on a short, seeded budget. Its obstacle points stand for every
centre the lidar may hide (checked against MuJoCo's positions, read by the test only)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_safety_gym import attack, shield_alone
from tlshield.envs.safety_gym import SafetyGoalEnv
from tlshield.envs.safety_gym import lidar as L

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # gymnasium's Box casts
TASKS = ["SafetyPointGoal1-v0", "SafetyPointGoal2-v0", "SafetyCarGoal1-v0"]


def _blind(env: SafetyGoalEnv) -> SafetyGoalEnv:
    """The env with every reader of MuJoCo's positions made to fail."""

    def refuse(*_: object) -> None:
        raise AssertionError("sensing='lidar' read MuJoCo's state")

    env.true_state = refuse  # type: ignore[method-assign]
    env._find_agent = refuse  # type: ignore[method-assign]
    return env


@pytest.mark.parametrize("task", TASKS)
def test_the_lidar_mode_reads_no_mujoco_position_and_keeps_cost_at_zero(task: str) -> None:
    env = _blind(SafetyGoalEnv(task, config="rl_cbf_clf", evaluation=True, sensing="lidar"))
    try:
        assert attack(env, episodes=2, steps=250, seed=700) == 0.0
        assert shield_alone(env, steps=250, seed=710)[1] == 0.0
    finally:
        env.close()


def test_the_state_is_the_observations_alone() -> None:
    env = SafetyGoalEnv("SafetyPointGoal2-v0", config="rl_cbf_clf", sensing="lidar")
    try:
        obs, info = env.reset(seed=3)
        for _ in range(20):
            obs, *_, info = env.step(np.array([0.5, 0.3]))
        sensing = env._sensing
        assert sensing is not None
        # The same observation, written again by a reader that never saw the env's MuJoCo
        # world, gives the same obstacles and robot (the goal carries odometry of its own).
        before = info["state"]
        again = sensing.read(obs)
        agent = env.robot.agent_dim
        np.testing.assert_array_equal(again[:agent], before[:agent])
        np.testing.assert_array_equal(again[agent + 2 :], before[agent + 2 :])
    finally:
        env.close()


@pytest.mark.parametrize("task", TASKS)
def test_each_obstacle_point_stands_for_the_centres_its_bin_may_hold(task: str) -> None:
    """Against MuJoCo's positions (read here only): from anywhere within the step's bound on
    the robot's motion (``delta``) of where the lidar read, every hazard or vase within the
    lidar's range is no nearer, less its kind's barrier radius, than its bin's point less the
    shared radius: the barrier never reads more clearance than there is."""
    env = SafetyGoalEnv(task, config="rl_cbf_clf", sensing="lidar")
    rng = np.random.default_rng(0)
    try:
        sensing = env._sensing
        assert sensing is not None
        env.reset(seed=5)
        turns = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
        ring = np.column_stack([np.cos(turns), np.sin(turns)])
        checked = 0
        for _ in range(60):
            *_, info = env.step(rng.uniform(-1.0, 1.0, 2))
            state = info["state"]
            data = env._env.task.data
            body = data.body("agent")
            rot = body.xmat.reshape(3, 3)
            points = state[env.robot.agent_dim + 2 :].reshape(-1, 2)
            for kind, radius in sensing.radii.items():
                count = getattr(env._env.task, kind).num
                for i in range(count):
                    c = data.body(f"{kind[:-1]}{i}").xpos
                    ego = (rot.T @ (np.array([c[0], c[1], 0.0]) - body.xpos))[:2]
                    d = float(np.hypot(*ego))
                    if d >= L.MAX_DIST:
                        continue
                    b = int((np.arctan2(ego[1], ego[0]) % (2 * np.pi)) / (2 * np.pi / L.BINS))
                    b %= L.BINS
                    # The robot anywhere on the circle of radius delta, and at the origin.
                    p = np.vstack([[0.0, 0.0], sensing.delta * ring])
                    true = np.hypot(*(ego - p).T) - radius
                    barrier = np.hypot(*(points[b] - p).T) - sensing.shared
                    assert np.all(true >= barrier - 1e-9), (kind, i, b, true - barrier)
                    checked += 1
        assert checked > 100
    finally:
        env.close()


def test_a_bad_sensing_is_refused() -> None:
    with pytest.raises(ValueError, match=r"sensing = 'camera': expected one of state, lidar"):
        SafetyGoalEnv("SafetyPointGoal1-v0", sensing="camera")
