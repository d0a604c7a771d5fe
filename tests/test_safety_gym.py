"""Safety-Gymnasium (issue 33): the adapter makes safety-gymnasium 1.0.0 run on tlshield's stack
and says what to install when it cannot; the shielded envs keep Safety-Gymnasium's spaces,
reward and cost and pass Gymnasium's checker; under an attacker that steers at the nearest
hazard from the lidar they cost 0 where the same attacker unshielded costs plenty; a start
inside a hazard is driven out and stays out; the ThrustTurn model and the shield's
disturbance bounds hold their equations; and TD3 trains through the shield layer. The benchmark,
validation and the command line: tests/lab/test_safety_gym_benchmark.py.

``make test`` installs the stack (scripts/setup-safety-gym.sh), so these tests run in CI."""

from __future__ import annotations

import importlib
import importlib.metadata
import json
import pickle
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tlshield
from tlshield.envs import safety_gym as sg

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # gymnasium's Box casts
ROOT = Path(__file__).resolve().parents[1]


def _script(name: str) -> Any:
    """``scripts/<name>.py`` as a module."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(ROOT / "scripts"))


#: The lidar hazard attacker of scripts/safety_gym_attack.py.
hazard_attacker = _script("safety_gym_attack").hazard_attacker


def attack(env: sg.SafetyGoalEnv, episodes: int, steps: int, seed: int) -> float:
    cost = 0.0
    for ep in range(episodes):
        obs, _ = env.reset(seed=seed + ep)
        for _ in range(steps):
            obs, _, terminated, truncated, info = env.step(hazard_attacker(env, obs))
            cost += info["cost"]
            if terminated or truncated:
                break
    return cost


def shield_alone(env: Any, steps: int, seed: int) -> tuple[int, float]:
    """(goals met, cost) over one episode of zero actions from ``seed`` (the shield drives)."""
    env.reset(seed=seed)
    goals, cost = 0, 0.0
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(np.zeros(2))
        goals += info["goal_met"]
        cost += info["cost"]
        if terminated or truncated:
            break
    return goals, cost


def test_the_adapter_checks_versions_and_says_what_to_install(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    assert sg.installed()
    assert sg.load_builder().__name__ == "Builder"
    real = importlib.metadata.version
    sg.load_builder.cache_clear()
    try:
        monkeypatch.setattr(
            importlib.metadata,
            "version",
            lambda p: "3.1.0" if p == "mujoco" else real(p),
        )
        with pytest.raises(sg.MissingStack, match=r"mujoco 3\.1\.0 .* make safety-gym"):
            sg.load_builder()
        assert not sg.installed()
    finally:
        sg.load_builder.cache_clear()
        monkeypatch.undo()
    with pytest.raises(ValueError, match="SafetyCarGoal1-v0"):
        sg.make_builder("SafetyCarGoal3-v0")
    with pytest.raises(ValueError, match="the shielded envs are"):
        sg.SafetyGoalEnv("SafetyCarGoal3-v0")


@pytest.mark.parametrize("halted", ["safety_gymnasium.assets.color", "safety_gymnasium.builder"])
def test_a_failure_inside_the_adapter_takes_its_patches_back(
    monkeypatch: pytest.MonkeyPatch, halted: str
) -> None:
    """load_builder patches the process (a module shell in sys.modules, hashable colours,
    MjModel.jnt); when anything in it raises, sys.modules and MjModel.jnt are as they were on
    entry and the error propagates. The import of ``halted`` fails: the colours' (the shell in
    place, MjModel.jnt not patched yet) or the Builder's (every patch in place)."""
    sg.load_builder()  # every third-party module the adapter imports is loaded once
    for name in [n for n in sys.modules if n.split(".")[0] == "safety_gymnasium"]:
        monkeypatch.delitem(sys.modules, name)

    def unpatched(self: Any, *args: Any, **kwargs: Any) -> Any:  # stands in for MuJoCo's
        raise AssertionError("not called")

    monkeypatch.setattr(mujoco.MjModel, "jnt", unpatched)
    seen: list[tuple[Any, Any, Any]] = []

    class Halt:  # an import finder that fails the import of `halted`
        def find_spec(self, name: str, path: Any = None, target: Any = None) -> None:
            if name == halted:
                color = sys.modules.get("safety_gymnasium.assets.color")
                seen.append((sys.modules.get("safety_gymnasium"), mujoco.MjModel.jnt, color))
                raise ImportError(f"halted at {name}")

    monkeypatch.setattr(sys, "meta_path", [Halt(), *sys.meta_path])
    before = dict(sys.modules)
    with pytest.raises(ImportError, match=f"halted at {halted}"):
        sg.load_builder.__wrapped__()  # uncached
    shell, jnt, color = seen[0]  # the patches were in place when the import failed
    assert shell is not None and shell.__path__
    if halted == "safety_gymnasium.builder":
        assert getattr(jnt, "_tlshield_patched", False)
        assert all(type(c).__hash__ is object.__hash__ for c in color.COLOR.values())
    else:
        assert jnt is unpatched
    assert sys.modules.keys() == before.keys()
    assert all(sys.modules[name] is module for name, module in before.items())
    assert mujoco.MjModel.jnt is unpatched


def test_both_robots_are_what_the_env_reads_of_a_robot() -> None:
    """PointModel and CarModel satisfy the Robot protocol, and the protocol declares exactly
    what SafetyGoalEnv reads of ``self.robot``."""
    import re

    point: sg.Robot = sg.POINT  # a static check too: mypy holds both to the protocol
    car: sg.Robot = sg.CAR
    assert isinstance(point, sg.Robot) and isinstance(car, sg.Robot)
    assert not isinstance(object(), sg.Robot)
    declared = {name for name in vars(sg.Robot) if not name.startswith("_")}
    source = (ROOT / "python" / "tlshield" / "envs" / "safety_gym" / "env.py").read_text()
    assert declared == set(re.findall(r"\brobot\.(\w+)", source))


def test_the_package_keeps_the_modules_names_and_names_where_the_attacker_went() -> None:
    """tlshield.envs.safety_gym was one module: the package gives every name it had; the
    attacker, a scripted policy of the scripts, is refused with its new place."""
    for name in (
        "VERSIONS INSTALL TASKS BUILDER_TASKS ACTIONS MissingStack installed load_builder "
        "make_builder PointModel POINT CarModel CAR ROBOTS robot_of SafetyGoalParams goal_spec "
        "SafetyGoalEnv make_safety_goal"
    ).split():
        assert getattr(sg, name) is not None, name
    assert gym.spec("tlshield/SafetyPointGoal1-v0").entry_point == (
        "tlshield.envs.safety_gym:make_safety_goal"
    )
    moved = r"hazard_attacker was removed in tlshield 0\.4: use scripts/safety_gym_attack\.py"
    with pytest.raises(ImportError, match=moved):
        from tlshield.envs.safety_gym import hazard_attacker  # noqa: F401
    with pytest.raises(ImportError, match=moved):
        sg.hazard_attacker  # noqa: B018
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        sg.nothing  # noqa: B018


def test_the_car_robot_builds_and_steps_under_numpy_2() -> None:
    """safety-gymnasium's Car reads a joint by a sensor's one-element id array, which
    MuJoCo 2.3.7 refuses under numpy 2 unless the adapter's patch is in place; the patch
    passes every other argument on as it was."""
    env = sg.make_builder("SafetyCarGoal1-v0")
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape
    assert env.action_space.shape == (2,)
    model = env.task.model
    assert [model.actuator(i).name for i in range(model.nu)] == ["left", "right"]
    total = 0.0
    for _ in range(50):
        obs, reward, cost, *_ = env.step(np.ones(2))
        total += reward
        assert np.isfinite(reward) and cost >= 0.0
    assert total != 0.0  # the wheels moved it
    joint = model.jnt(np.array([1], dtype=np.int32))
    assert joint.id == model.jnt(1).id == 1
    assert model.jnt("left").id == model.joint("left").id
    with pytest.raises(TypeError):
        model.jnt(np.array([1.5]))


@pytest.mark.parametrize("actions", sg.ACTIONS)
@pytest.mark.parametrize("task", sg.TASKS)
def test_spaces_reward_and_cost_are_safety_gymnasiums(task: str, actions: str) -> None:
    """``actions="native"`` is Safety-Gymnasium's box; ``"robot"`` (the default) is each
    actuator's working range as [-1, 1]: the same env, stepped with the action scaled."""
    env = gym.make(f"tlshield/{task}", config="rl", actions=actions)
    raw = sg.make_builder(task)
    scale = env.unwrapped.robot.scale if actions == "robot" else np.ones(2)
    assert env.observation_space == raw.observation_space
    if actions == "native":
        assert env.action_space == raw.action_space
    else:
        assert env.action_space == gym.spaces.Box(-1.0, 1.0, (2,), raw.action_space.dtype)
        assert np.all(scale * env.action_space.high <= raw.action_space.high)
    obs, _ = env.reset(seed=3)
    raw_obs, _ = raw.reset(seed=3)
    np.testing.assert_array_equal(obs, raw_obs)
    rng = np.random.default_rng(0)
    for _ in range(200):
        a = rng.uniform(-1, 1, 2)
        obs, r, terminated, truncated, info = env.step(a)
        np.testing.assert_array_equal(info["action"], a)  # in the env's own space
        raw_obs, raw_r, raw_cost, raw_term, raw_trunc, _ = raw.step(scale * a)
        np.testing.assert_array_equal(obs, raw_obs)
        assert (r, info["cost"], terminated, truncated) == (raw_r, raw_cost, raw_term, raw_trunc)
        # The privileged state is MuJoCo's: the agent where Safety-Gymnasium reads it (the
        # Car's state is the point ``pivot`` behind it, along the heading).
        state = info["state"]
        body = state[:2] + env.unwrapped.robot.pivot * np.array(
            [np.cos(state[2]), np.sin(state[2])]
        )
        np.testing.assert_allclose(body, raw.task.agent.pos[:2], atol=1e-9)


@pytest.mark.parametrize("config", ["rl_cbf", "rl_cbf_clf"])
def test_check_env(config: str) -> None:
    env = sg.SafetyGoalEnv("SafetyPointGoal1-v0", config)
    check_env(env, skip_render_check=True)
    env.reset(seed=1)
    _, _, _, _, info = env.step(np.array([1.0, 0.2]))
    assert {"a_rl", "a_cbf", "a_clf", "status"} <= set(info["shield"])


@pytest.mark.parametrize("task", sg.TASKS)
def test_the_lidar_attacker_costs_nothing_shielded(task: str) -> None:
    unshielded = attack(sg.SafetyGoalEnv(task, "rl"), 2, 400, seed=40)
    assert unshielded > 50  # the attack works: the shield has something to stop
    for config in ("rl_cbf", "rl_cbf_clf"):
        assert attack(sg.SafetyGoalEnv(task, config), 2, 400, seed=40) == 0.0


@pytest.mark.parametrize("task", sg.TASKS)
def test_the_robots_units_drive_as_safety_gymnasiums_do(task: str) -> None:
    """The attacker (which drives through ``env.drive``) makes the same steps, bit for bit,
    through the shield in either action space, and ``info["action"]`` is the executed action
    in each env's own space."""
    robot, native = (sg.SafetyGoalEnv(task, "rl_cbf", actions=a) for a in ("robot", "native"))
    a, b = robot.reset(seed=21)[0], native.reset(seed=21)[0]
    scale = robot.robot.scale
    for _ in range(150):
        a, _, _, _, info_a = robot.step(hazard_attacker(robot, a))
        b, _, _, _, info_b = native.step(hazard_attacker(native, b))
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(info_a["state"], info_b["state"])
        np.testing.assert_array_equal(scale * info_a["action"], info_b["action"])
        assert np.all(np.abs(info_a["action"]) <= 1.0 + 1e-12)


def test_a_bad_action_space_is_named() -> None:
    for bad in ("Robot", "raw", None, 1):
        with pytest.raises(ValueError, match=r"actions = .*expected one of robot, native"):
            sg.SafetyGoalEnv("SafetyPointGoal1-v0", "rl", actions=bad)


def test_the_defaults_route_the_shield_alone_to_goals() -> None:
    """``gym.make(..., config="rl_cbf_clf")`` with no settings is the routed CLF at the
    settings that drive best alone (docs/guides/safety-gym.md: 6.1 goals per episode on reset
    seeds 700-709): with no action it meets goals, at cost 0. The settings before (a CLF at
    half thrust, routes that grazed the hazards) met 1 in this episode, these 8."""
    env = gym.make("tlshield/SafetyPointGoal1-v0", config="rl_cbf_clf")
    goals, cost = shield_alone(env, steps=1000, seed=702)
    assert cost == 0.0
    assert goals >= 4


def test_the_reward_reads_the_way_the_shield_drives() -> None:
    """Under a routing shield PPO's reward pays per metre of the routed way left: Safety-
    Gymnasium's reward plus ``reward_distance`` per metre the detour (routed way minus straight
    line, from a monitor the shield routes) shrinks, restarted at each goal, so over each goal
    the extra return is the detour at its start less the detour at its end (no loophole in
    dawdling on a detour). ``info["task_reward"]`` stays Safety-Gymnasium's; without routing
    the reward is Safety-Gymnasium's, bit for bit."""
    env = sg.SafetyGoalEnv("SafetyPointGoal2-v0", "rl_cbf_clf")
    unit = env._env.task.goal.reward_distance
    env.reset(seed=703)
    check = tlshield.Monitor(env.shield.automaton, routed_by=env.shield)
    start, extra, detours = env.detour(), 0.0, []
    end = start
    for _ in range(600):
        _, reward, terminated, truncated, info = env.step(np.zeros(2))
        extra += reward - info["task_reward"]
        check.reset(info["state"])
        way, goal = check.goal_distance, check.goal
        assert info["detour"] == pytest.approx(
            max(0.0, way - np.hypot(*(info["state"][:2] - goal))), abs=1e-12
        )
        detours.append(info["detour"])
        if info["goal_met"]:
            assert extra == pytest.approx(unit * start - unit * end, abs=1e-9)
            start, extra = info["detour"], 0.0
        end = info["detour"]
        if terminated or truncated:
            break
    assert extra == pytest.approx(unit * (start - end), abs=1e-9)
    assert max(detours) > 0.1  # the hazards stood in the way
    plain = sg.SafetyGoalEnv("SafetyPointGoal2-v0", "rl_cbf")
    assert not plain.shield.routes
    plain.reset(seed=703)
    for _ in range(50):
        _, reward, _, _, info = plain.step(np.zeros(2))
        assert reward == info["task_reward"] and info["detour"] == 0.0


def test_a_start_inside_a_hazard_is_driven_out_and_stays_out() -> None:
    env = sg.SafetyGoalEnv("SafetyPointGoal1-v0", "rl_cbf")
    env.reset(seed=7)
    task = env.unwrapped._env.task
    hazard = np.asarray(task.hazards.pos[0][:2])
    # Put the agent 0.1 m from the hazard's centre (its cost radius is 0.2), at rest.
    state = env.true_state()
    offset = hazard + np.array([0.1, 0.0]) - state[:2]
    c, s = env._at.rot0
    qx, qy = env._at.qpos[:2]
    task.data.qpos[qx] += c * offset[0] + s * offset[1]
    task.data.qpos[qy] += -s * offset[0] + c * offset[1]
    task.data.qvel[:] = 0.0
    mujoco.mj_forward(task.model, task.data)
    env._state = env.true_state()
    env.monitor.reset(env._state)
    assert np.linalg.norm(env._state[:2] - hazard) < 0.2
    rng = np.random.default_rng(0)
    costs = []
    for _ in range(300):  # random actions: only the shield drives out
        *_, info = env.step(rng.uniform(-1, 1, 2))
        costs.append(info["cost"])
    out = next(i for i, c in enumerate(costs) if c == 0.0)
    assert out < 50, costs[:60]
    assert sum(costs[out:]) == 0.0  # and it stays out


def test_the_car_model_is_its_equations_and_its_inputs_fit_the_wheels() -> None:
    car = sg.CAR
    rng = np.random.default_rng(5)
    model = car.model(8)
    for _ in range(50):
        s = rng.uniform(-2, 2, 8)
        u = rng.uniform(-1, 1, 2)
        f, g = model.eval(s)
        psi, v = s[2], s[3]
        want = np.zeros(8)
        want[:4] = [
            v * np.cos(psi),
            v * np.sin(psi),
            car.turn * u[1],
            car.push * u[0] - car.drag * v,
        ]
        np.testing.assert_allclose(f + g @ u, want, atol=1e-12)
        jac = model.drift_jacobian(s)
        eps = 1e-6
        for d in range(8):
            e = np.zeros(8)
            e[d] = eps
            fd = (model.eval(s + e)[0] - model.eval(s - e)[0]) / (2 * eps)
            np.testing.assert_allclose(jac[:, d], fd, atol=1e-7)
        # Wheels -> (drive, turn) -> wheels: the diamond |u0| + |u1| <= 1, back exactly.
        wheels = rng.uniform(-1, 1, 2) * car.saturation
        u = car.shield_input(wheels)
        assert abs(u[0]) + abs(u[1]) <= 1.0 + 1e-12
        np.testing.assert_allclose(car.env_action(u), wheels, atol=1e-15)
    # The shield's box is inside the diamond: what it sends, the wheels do.
    (lo0, lo1), (hi0, hi1) = car.input_box()
    assert hi0 + hi1 <= 1.0 and lo0 + lo1 >= -1.0
    assert np.all(np.abs(car.drive(1.0, 1.0)) <= 1.0 + 1e-15)


def test_the_car_holds_its_body_origin_out_of_the_hazards() -> None:
    """The cost is measured at the Car's body origin, ``pivot`` ahead of the state's point:
    the barriers hold that point (a turn alone swings it), read from the state."""
    env = sg.SafetyGoalEnv("SafetyCarGoal1-v0", "rl_cbf")
    env.reset(seed=11)
    ball = env.automaton.spec.predicates["h1"]
    assert ball.heading == 2 and ball.offset == (sg.CAR.pivot, 0.0)
    state = env.true_state()
    origin = state[:2] + sg.CAR.pivot * np.array([np.cos(state[2]), np.sin(state[2])])
    centre = state[6:8]
    assert ball.robustness(state) == pytest.approx(
        ball.radius - np.linalg.norm(origin - centre), abs=1e-12
    )


def test_thrust_turn_is_its_equations() -> None:
    model = tlshield.ThrustTurn(2.0, 3.0, 0.5)
    rng = np.random.default_rng(1)
    for _ in range(50):
        s = rng.uniform(-2, 2, 7)
        a = rng.uniform(-1, 1, 2)
        f, g = model.eval(s)
        th, vx, vy = s[2:5]
        want = [vx, vy, 3.0 * a[1], 2.0 * a[0] * np.cos(th) - 0.5 * vx]
        want += [2.0 * a[0] * np.sin(th) - 0.5 * vy, 0.0, 0.0]
        np.testing.assert_allclose(f + g @ a, want, atol=1e-12)
        np.testing.assert_allclose(model.step(s, a, 0.1), s + 0.1 * np.array(want), atol=1e-12)
    assert pickle.loads(pickle.dumps(model)).gains == (2.0, 3.0, 0.5)
    for bad in [(0.0, 1.0, 1.0), (1.0, -1.0, 1.0), (1.0, 1.0, -0.5), (1.0, 1.0, float("nan"))]:
        with pytest.raises(ValueError, match="ThrustTurn"):
            tlshield.ThrustTurn(*bad)


def wall_shield(**kw: Any) -> tlshield.Shield:
    wall = tlshield.Halfspace([-1.0, 0, 0, 0, 0], 1.0)  # x <= 1
    spec = tlshield.Spec("F g", {"g": tlshield.Halfspace([0, 1.0, 0, 0, 0], -5.0)})
    return tlshield.Shield(
        spec,
        tlshield.ThrustTurn(2.0, 3.0, 0.5),
        alpha=1.0,
        alpha2=2.0,
        c3=1.0,
        k=1e4,
        cbf_bounds=(-2.0, 2.0),
        clf_bounds=(-0.5, 0.5),
        barriers={"wall": tlshield.Inside(wall)},
        use_clf=False,
        **kw,
    )


def test_disturbance_bounds_tighten_the_rows_and_survive_a_pickle() -> None:
    # Heading along x, moving at the wall: the HOCBF row caps the thrust. psi_1 = -vx +
    # alpha (1 - x - margin); the row: -2 a0 cos(theta) + 0.5 vx - alpha vx + alpha2 psi_1 >=
    # sum_d |dpsi_1/ds_d| w_d, and dpsi_1/dvx = -1, dpsi_1/dx = -alpha.
    s = np.array([0.3, 0.0, 0.0, 0.4, 0.0])
    margin = 1e-6
    psi = -0.4 + (1 - 0.3 - margin)
    nominal = (0.5 * 0.4 - 0.4 + 2.0 * psi) / 2.0
    for bounds, extra in [(None, 0.0), ({3: 0.3}, 0.3), ({0: 0.1, 3: 0.3}, 0.4)]:
        shield = wall_shield(disturbance=bounds)
        a0 = shield.filter(s, 0, np.array([1.0, 0.0])).action[0]
        assert a0 == pytest.approx(nominal - extra / 2.0, abs=1e-7)
        again = pickle.loads(pickle.dumps(shield))
        assert again.filter(s, 0, np.array([1.0, 0.0])).action[0] == a0
    with pytest.raises(TypeError, match="disturbance: expected a dict"):
        wall_shield(disturbance=[0.1, 0.2])
    with pytest.raises(ValueError, match="disturbance: key -1"):
        wall_shield(disturbance={-1: 0.1})
    with pytest.raises(ValueError, match=r"dimension 3 = -0\.1"):
        wall_shield(disturbance={3: -0.1})


def test_the_correction_penalty_comes_off_the_reward_only() -> None:
    plain = sg.SafetyGoalEnv("SafetyPointGoal1-v0", "rl_cbf")
    paid = sg.SafetyGoalEnv("SafetyPointGoal1-v0", "rl_cbf", correction_penalty=0.5)
    a, b = plain.reset(seed=4)[0], paid.reset(seed=4)[0]
    corrected = 0
    for _ in range(300):
        action = hazard_attacker(plain, a)
        a, r_plain, *_, info_plain = plain.step(action)
        b, r_paid, *_, info_paid = paid.step(action)
        np.testing.assert_array_equal(a, b)  # the same steps: only the reward differs
        assert info_paid["task_reward"] == r_plain == info_plain["task_reward"]
        shield = info_paid["shield"]
        correction = np.linalg.norm(paid.shield_input(info_paid["action"]) - shield["a_rl"])
        assert r_paid == pytest.approx(r_plain - 0.5 * correction, abs=1e-12)
        corrected += correction > 1e-6
        assert info_paid["success"] == info_paid["goal_met"] and not info_paid["trap"]
    assert corrected > 10  # the attacker was corrected, so the penalty was paid
    with pytest.raises(ValueError, match="correction_penalty = -1"):
        sg.SafetyGoalEnv("SafetyPointGoal1-v0", "rl_cbf", correction_penalty=-1.0)


def _off_policy_script(out: Path, name: str, *args: str) -> dict[str, Any]:
    """Runs scripts/safety_gym_td3_layer.py for 300 steps and 1 evaluation episode; returns
    the row it wrote as ``out/SafetyPointGoal1-v0-<name>-s0.json``."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [
            sys.executable,
            str(root / "scripts" / "safety_gym_td3_layer.py"),
            *args,
            *("--steps", "300", "--episodes", "1", "--out", str(out)),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return dict(json.loads((out / f"SafetyPointGoal1-v0-{name}-s0.json").read_text()))


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_off_policy_learners_train_with_the_shield_in_the_env(algo: str, tmp_path: Path) -> None:
    """The off-policy levers: SAC and TD3 learn a residual on the routed CLF through the env's
    shield (rl_cbf_clf), at cost 0 in training and in evaluation."""
    row = _off_policy_script(tmp_path, f"rl_cbf_clf+{algo}", "--algo", algo)
    assert row["method"] == f"rl_cbf_clf+{algo}" and row["steps"] == 300
    assert row["train_cost"] == 0.0 and row["last_cost"] == 0.0
    assert len(row["last_returns"]) == 1 and np.isfinite(row["last_return"])


def test_td3_trains_through_the_shield_layer(tmp_path: Path) -> None:
    """The fourth lever's script: TD3 whose actor ends in the exact shield trains, costs 0 in
    training and evaluation, and its actor's gradient reaches the network through the layer."""
    import sys

    import torch

    root = Path(__file__).resolve().parents[1]
    row = _off_policy_script(tmp_path, "td3_layer")
    assert row["steps"] == 300 and row["train_cost"] == 0.0 and row["last_cost"] == 0.0
    # The actor's output is the layer's: safe at the state, and differentiable to the weights.
    sys.path.insert(0, str(root / "scripts"))
    try:
        from safety_gym_td3_layer import ShieldUnits, policy_class
    finally:
        sys.path.pop(0)
    from tlshield.torch import ShieldLayer

    inner = sg.SafetyGoalEnv("SafetyPointGoal1-v0", "rl_cbf")
    env = ShieldUnits(inner)
    obs, _ = env.reset(seed=2)
    assert inner.shield is not None
    policy = policy_class(ShieldLayer(inner.shield), env.n_obs, env.n_state)(
        env.observation_space, env.action_space, lambda _: 1e-3, net_arch=[16]
    )
    batch = torch.as_tensor(np.stack([obs] * 4), dtype=torch.float32)
    out = policy.actor(batch)
    out.sum().backward()
    assert all(p.grad is not None for p in policy.actor.mu.parameters())
    s, q = inner.monitor.state, inner.monitor.q
    raw = policy.actor.mu(policy.actor.extract_features(batch, policy.actor.features_extractor))
    want = inner.shield.filter(s, q, raw[0].detach().double().numpy()).action
    np.testing.assert_allclose(out[0].detach().numpy(), want, atol=1e-6)


@pytest.mark.parametrize("task", sorted(sg.TASKS))
def test_making_a_shielded_env_warns_of_nothing(task: str) -> None:
    # Safety-Gymnasium's action Box cast used to print "RuntimeWarning: overflow encountered in
    # cast" at every make (issue 57); the adapter now silences that one harmless warning.
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(f"tlshield/{task}")
        env.reset(seed=0)
        env.step(env.action_space.sample())
