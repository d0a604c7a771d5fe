"""Channel-v0 and PointMass-v0 stepped N at a time in one core call: the SB3 VecEnv gives
exactly what SB3's DummyVecEnv over the single envs gives, and the Gymnasium VectorEnv follows
the single envs with next-step autoreset."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

import tlshield.vector
from tlshield.envs.channel import ChannelEnv
from tlshield.envs.point_mass import PointMassEnv
from tlshield.sb3 import ChannelVecEnv, PointMassVecEnv

#: env id -> (SB3 vec env, single env) of each world the core steps.
WORLDS = {
    "tlshield/Channel-v0": (ChannelVecEnv, lambda config: ChannelEnv(config=config)),
    "tlshield/PointMass-v0": (PointMassVecEnv, lambda config: PointMassEnv(config)),
}


def _actions(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random actions, half the envs driving full speed ahead and turning slowly (into walls,
    so the shield acts)."""
    a = rng.uniform(-1, 1, size=(n, 2))
    a[::2] = [1.0, 0.2]
    return a


@pytest.mark.parametrize("env_id", sorted(WORLDS))
@pytest.mark.parametrize(("config", "n"), [("rl_cbf_clf", 5), ("rl", 3), ("rl_cbf_clf", 40)])
def test_the_sb3_vec_env_equals_dummy_vec_env_bit_for_bit(env_id: str, config: str, n: int) -> None:
    vec, single = WORLDS[env_id]
    ours = vec(n, config)
    theirs = DummyVecEnv([lambda: single(config)] * n)
    ours.seed(7)
    theirs.seed(7)
    np.testing.assert_array_equal(ours.reset(), theirs.reset())
    rng = np.random.default_rng(0)
    dones_seen = gave_way = 0
    for _ in range(320):  # past PointMass-v0's horizon (300): every env ends at least once
        a = _actions(rng, n)
        ours.step_async(a)
        theirs.step_async(a)
        obs, rew, done, infos = ours.step_wait()
        obs2, rew2, done2, infos2 = theirs.step_wait()
        np.testing.assert_array_equal(obs, obs2)
        np.testing.assert_array_equal(rew, rew2)
        assert rew.dtype == rew2.dtype
        np.testing.assert_array_equal(done, done2)
        for i, (mine, want) in enumerate(zip(infos, infos2, strict=True)):
            for key in (
                "fsa_state",
                "success",
                "trap",
                "tl_reward",
                "constraints",
                "min_obstacle_distance",
                "collision",
                "violation",
                "TimeLimit.truncated",
            ):
                assert mine[key] == want[key], (i, key)
            np.testing.assert_array_equal(mine["action"], want["action"])
            assert ("shield" in mine) == ("shield" in want)
            for key in ("a_rl", "a_cbf", "a_clf", "delta", "status", "slack", "solver"):
                if "shield" in want:
                    np.testing.assert_array_equal(mine["shield"][key], want["shield"][key])
            if "shield" in want:
                # Who gave way, named as the single env names it (issue 57, item 4).
                assert mine["shield"]["gave_way"] == want["shield"]["gave_way"], i
                gave_way += want["shield"]["gave_way"] is not None
            if done[i]:
                np.testing.assert_array_equal(
                    mine["terminal_observation"], want["terminal_observation"]
                )
        dones_seen += int(done.sum())
    assert dones_seen > 0  # episodes ended and were reset along the way
    if env_id == "tlshield/Channel-v0" and n == 40:
        assert gave_way > 0  # the comparison above saw give-ways (4 in one run)


@pytest.mark.parametrize("env_id", sorted(WORLDS))
def test_the_gymnasium_vector_env_follows_the_single_envs(env_id: str) -> None:
    n = 4
    venv = tlshield.vector.make(env_id, n, config="rl_cbf_clf")
    singles = [WORLDS[env_id][1]("rl_cbf_clf") for _ in range(n)]
    obs, _ = venv.reset(seed=3)
    assert obs.shape == (n, *singles[0].observation_space.shape)
    want = np.stack([env.reset(seed=3 + i)[0] for i, env in enumerate(singles)])
    np.testing.assert_array_equal(obs, want)
    assert venv.observation_space.shape == obs.shape
    rng = np.random.default_rng(1)
    resetting = np.zeros(n, dtype=bool)
    ended = 0
    for _ in range(300):
        a = _actions(rng, n)
        obs, rew, term, trunc, infos = venv.step(a)
        for i, env in enumerate(singles):
            if resetting[i]:  # next-step autoreset: this step reset env i, reward 0
                o = env.reset()[0]
                r, t, u = 0.0, False, False
            else:
                o, r, t, u, _ = env.step(a[i])
            np.testing.assert_array_equal(obs[i], o)
            assert (rew[i], term[i], trunc[i]) == (r, t, u)
        resetting = term | trunc
        ended += int(resetting.sum())
        assert infos["constraints"].shape == (n, 2)
    assert ended > 0


def test_bad_vector_input_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="SyncVectorEnv"):
        tlshield.vector.make("tlshield/FlatWorld-v0", 2)
    # An id gymnasium does not know by name (unregistered, or "module:Env-v0" before its
    # import) is no core-stepped env: refused here (SB3's make_vec_env gives a DummyVecEnv).
    with pytest.raises(ValueError, match="SyncVectorEnv"):
        tlshield.vector.make("tlshield/Nowhere-v0", 2)
    with pytest.raises(ValueError, match="num_envs"):
        tlshield.vector.make("tlshield/Channel-v0", 0)
    venv = tlshield.vector.make("tlshield/Channel-v0", 2)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"actions\[1, 0\] is NaN"):
        venv.step(np.array([[0.0, 0.0], [np.nan, 0.0]]))
    with pytest.raises(ValueError, match="actions"):
        venv.step(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="seeds"):
        venv.reset(seed=[1, 2, 3])


def test_step_worlds_takes_one_kind_of_world() -> None:
    from tlshield._core import step_worlds

    channel, point = ChannelEnv(), PointMassEnv()
    channel.reset(seed=0)
    point.reset(seed=0)
    with pytest.raises(TypeError, match="one kind"):
        step_worlds(
            [channel._world, point._world],  # type: ignore[list-item]
            [channel.tracker.monitor, point.tracker.monitor],
            np.zeros((2, 2)),
            np.zeros((2, 24)),
        )


def test_every_bundled_env_has_a_vector_entry_point() -> None:
    """``gymnasium.make_vec`` builds every bundled env's vector form from its registration:
    the core-stepped envs' ``WorldVectorEnv`` (the same as ``tlshield.vector.make``, step for
    step), a ``SyncVectorEnv`` for the envs written in Python (FlatWorld-v0, Safety-Gym's)."""
    import gymnasium as gym

    from tlshield.envs import FLATWORLD_ID, SAFETY_GYM_IDS

    for env_id, kind in (
        ("tlshield/Channel-v0", tlshield.vector.ChannelVectorEnv),
        ("tlshield/PointMass-v0", tlshield.vector.PointMassVectorEnv),
    ):
        assert gym.spec(env_id).vector_entry_point is not None
        ours, theirs = (
            gym.make_vec(env_id, 3, config="rl_cbf_clf"),
            tlshield.vector.make(env_id, 3, config="rl_cbf_clf"),
        )
        assert isinstance(ours, kind)
        np.testing.assert_array_equal(ours.reset(seed=5)[0], theirs.reset(seed=5)[0])
        a = np.tile([0.5, 0.1], (3, 1))
        for _ in range(20):
            np.testing.assert_array_equal(ours.step(a)[0], theirs.step(a)[0])
    flat = gym.make_vec(FLATWORLD_ID, 2)
    assert isinstance(flat, gym.vector.SyncVectorEnv) and flat.num_envs == 2
    single = gym.make(FLATWORLD_ID)
    np.testing.assert_array_equal(flat.reset(seed=1)[0][0], single.reset(seed=1)[0])
    for env_id in SAFETY_GYM_IDS:
        assert gym.spec(env_id).vector_entry_point == "tlshield.vector:safety_goal_vector_env"


def test_one_sb3_make_vec_env_for_every_env() -> None:
    """``tlshield.sb3.make_vec_env`` steps a core world where the registration names one and
    runs any other env in SB3's ``DummyVecEnv``, seeded ``seed + i`` either way: the same
    observations as the single envs reset with those seeds."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    from tlshield.envs import FLATWORLD_ID
    from tlshield.sb3 import WorldVecEnv, make_vec_env

    for env_id, kind in (("tlshield/Channel-v0", WorldVecEnv), (FLATWORLD_ID, DummyVecEnv)):
        venv = make_vec_env(env_id, 3, "rl_cbf_clf", seed=40)
        assert isinstance(venv, kind) and venv.num_envs == 3
        obs = venv.reset()
        for i in range(3):
            single = gym.make(env_id, config="rl_cbf_clf")
            np.testing.assert_allclose(obs[i], single.reset(seed=40 + i)[0], rtol=0, atol=1e-6)
    with pytest.raises(gym.error.Error):
        make_vec_env("tlshield/Nowhere-v0", 2)


def test_a_safety_gym_env_vectorises_through_its_entry_point() -> None:
    import gymnasium as gym

    venv = gym.make_vec("tlshield/SafetyPointGoal1-v0", 2)
    obs, _ = venv.reset(seed=0)
    single = gym.make("tlshield/SafetyPointGoal1-v0")
    np.testing.assert_array_equal(obs[1], single.reset(seed=1)[0])
    venv.close()
    single.close()
