"""A goal the robot cannot reach is reported (``FilterResult.goal_unreachable``,
``info["shield"]["goal_unreachable"]``): inside a disc the shield avoids, outside a region it
keeps the robot in, or walled in by discs. A reachable goal, and a shield that does not route,
report nothing."""

from __future__ import annotations

import math

import numpy as np

import tlshield

GAINS = {"alpha": 1.0, "c3": 1.0, "k": 1e4, "cbf_bounds": (-1.0, 1.0), "clf_bounds": (-1.0, 1.0)}
GOAL = [2.0, 0.0]


def _shield(barriers: dict, route: bool = True, formula: str = "F g", atoms: dict | None = None):
    spec = tlshield.Spec(formula, {"g": tlshield.Ball([0, 1], 0.2, center=GOAL), **(atoms or {})})
    model = tlshield.SingleIntegrator([0, 1])
    return tlshield.Shield(spec, model, barriers=barriers, route=route, **GAINS)


def _unreachable(shield: tlshield.Shield, s: list[float] | None = None) -> bool:
    out = shield.filter(np.array(s or [-2.0, 0.0]), shield.automaton.initial, [0.0, 0.0])
    return bool(out.goal_unreachable)


def test_a_goal_behind_a_disc_is_reachable() -> None:
    disc = tlshield.Avoid(tlshield.Ball([0, 1], 0.5, center=[0.0, 0.0]))
    assert not _unreachable(_shield({"o": disc}))
    assert not _unreachable(_shield({}))


def test_a_goal_inside_an_avoided_disc_is_unreachable() -> None:
    shelf = tlshield.Avoid(tlshield.Ball([0, 1], 0.5, center=[2.1, 0.0]))
    assert _unreachable(_shield({"shelf": shelf}))
    # The same disc in the formula, (!o U g): the safe set keeps the robot out of it.
    o = tlshield.Ball([0, 1], 0.5, center=[2.1, 0.0])
    assert _unreachable(_shield({}, formula="!o U g", atoms={"o": o}))
    # Routing off: the shield does not tell.
    assert not _unreachable(_shield({"shelf": shelf}, route=False))


def test_a_goal_outside_the_region_the_robot_is_kept_in_is_unreachable() -> None:
    room = tlshield.Inside(tlshield.Halfspace([-1.0, 0.0], 1.0))  # x < 1: the goal at x = 2
    assert _unreachable(_shield({"room": room}))
    wider = tlshield.Inside(tlshield.Halfspace([-1.0, 0.0], 3.0))  # x < 3
    assert not _unreachable(_shield({"room": wider}))


def test_a_goal_walled_in_by_discs_is_unreachable() -> None:
    ring = {
        f"w{k}": tlshield.Avoid(
            tlshield.Ball(
                [0, 1],
                0.6,
                center=[
                    GOAL[0] + 1.2 * math.cos(2 * math.pi * k / 10),
                    1.2 * math.sin(2 * math.pi * k / 10),
                ],
            )
        )
        for k in range(10)
    }
    assert _unreachable(_shield(ring))
    half = {k: v for i, (k, v) in enumerate(ring.items()) if i not in (4, 5, 6)}
    assert not _unreachable(_shield(half))  # open on the robot's side


def test_the_flag_reaches_info_and_names_the_parked_robot() -> None:
    """Through ``Shielded`` (``info["shield"]``): a goal inside an avoided disc is reported at
    every step, the shield holds the robot out of the disc (parked, safe), and the same env
    with the disc off the goal reaches it without a report."""
    import gymnasium as gym

    from tlshield.wrappers import FsaAugmented, Shielded

    class Plane(gym.Env[np.ndarray, np.ndarray]):
        observation_space = gym.spaces.Box(-5.0, 5.0, (2,), dtype=np.float64)
        action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float64)

        def reset(self, *, seed=None, options=None):  # type: ignore[no-untyped-def]
            super().reset(seed=seed)
            self.s = np.array([-2.0, 0.0])
            return self.s.copy(), {}

        def step(self, a):  # type: ignore[no-untyped-def]
            self.s = self.s + 0.05 * np.clip(a, -1.0, 1.0)
            return self.s.copy(), 0.0, False, False, {}

    for centre, covered in (([2.1, 0.0], True), ([0.0, 0.6], False)):
        shelf = tlshield.Ball([0, 1], 0.5, center=centre)
        spec = tlshield.Spec("F g", {"g": tlshield.Ball([0, 1], 0.2, center=GOAL)})
        shield = tlshield.Shield(
            spec,
            tlshield.SingleIntegrator([0, 1]),
            barriers={"shelf": tlshield.Avoid(shelf)},
            dt=0.05,
            **GAINS,
        )
        env = Shielded(FsaAugmented(Plane(), spec), shield)
        env.reset(seed=0)
        flags, inside = [], 0
        for _ in range(400):
            obs, _, terminated, _, info = env.step(np.zeros(2))
            flags.append(info["shield"]["goal_unreachable"])
            inside += np.linalg.norm(obs[:2] - centre) < 0.5
            if terminated:
                break
        assert inside == 0
        assert all(flags) if covered else (info["success"] and not any(flags))


def test_the_guidance_takes_another_goal_that_can_be_reached() -> None:
    """Eq. 5B1's choice restricted to goals that can be reached: of ``F a | F b``, the more
    robust ``a`` lies under a shelf, so the CLF leads to ``b`` and nothing is reported; with
    both covered, it leads to ``a`` (Eq. 5B1's) and says so; without routing, to ``a``."""
    a = tlshield.Ball([0, 1], 0.2, center=[2.0, 0.0])
    b = tlshield.Ball([0, 1], 0.2, center=[-1.0, 3.0])
    over_a = tlshield.Avoid(tlshield.Ball([0, 1], 0.5, center=[2.0, 0.0]))
    over_b = tlshield.Avoid(tlshield.Ball([0, 1], 0.5, center=[-1.0, 3.0]))
    model = tlshield.SingleIntegrator([0, 1])
    spec = tlshield.Spec("F a | F b", {"a": a, "b": b})
    s = np.zeros(2)

    def lead(barriers: dict, route: bool = True) -> tuple[np.ndarray, bool, list[float]]:
        shield = tlshield.Shield(spec, model, barriers=barriers, route=route, **GAINS)
        out = shield.filter(s, shield.automaton.initial, [0.0, 0.0])
        monitor = tlshield.Monitor(shield.automaton, routed_by=shield)
        monitor.reset(s)
        via_monitor = shield.filter_monitor(monitor, [0.0, 0.0])
        np.testing.assert_array_equal(via_monitor.action, out.action)
        assert via_monitor.goal_unreachable == out.goal_unreachable
        return np.asarray(out.action), bool(out.goal_unreachable), list(monitor.goal)

    def towards(action: np.ndarray, goal: list[float]) -> bool:
        # The action is clipped to the CLF's box: it heads into the goal's quadrant.
        return bool(np.all(np.sign(action) == np.sign(np.round(goal))))

    action, unreachable, goal = lead({"!shelf": over_a})
    assert towards(action, [-1.0, 3.0]) and not unreachable and goal == [-1.0, 3.0]
    action, unreachable, goal = lead({"!shelf": over_a, "!other": over_b})
    assert towards(action, [2.0, 0.0]) and unreachable and goal == [2.0, 0.0]
    action, unreachable, _ = lead({"!shelf": over_a}, route=False)
    assert towards(action, [2.0, 0.0]) and not unreachable
