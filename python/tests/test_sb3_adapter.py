"""dhrl.sb3's conventions without Stable-Baselines3: where SB3 (and torch) are not installed,
as in CI, its ``VecEnv`` base class is stood in for by a minimal one with the attributes the
adapter uses, so ``DhrlVecEnv`` itself runs here. test_sb3.py runs it against real SB3 where
that is installed."""

import importlib
import sys
import types

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import dhrl


class StandInVecEnv:
    """What ``DhrlVecEnv`` takes from SB3's ``VecEnv``."""

    def __init__(self, num_envs, observation_space, action_space):
        self.num_envs = num_envs
        self.observation_space = observation_space
        self.action_space = action_space
        self._reset_seeds()
        self._reset_options()

    def _reset_seeds(self):
        self._seeds = [None] * self.num_envs

    def _reset_options(self):
        self._options = [{}] * self.num_envs

    def _get_indices(self, indices):
        return range(self.num_envs) if indices is None else indices


@pytest.fixture
def sb3_adapter(monkeypatch):
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        vec_env = types.ModuleType("stable_baselines3.common.vec_env")
        vec_env.VecEnv = StandInVecEnv
        monkeypatch.setitem(sys.modules, "stable_baselines3", types.ModuleType("stable_baselines3"))
        monkeypatch.setitem(sys.modules, "stable_baselines3.common", types.ModuleType("stable_baselines3.common"))
        monkeypatch.setitem(sys.modules, "stable_baselines3.common.vec_env", vec_env)
    monkeypatch.delitem(sys.modules, "dhrl.sb3", raising=False)
    yield importlib.import_module("dhrl.sb3")
    sys.modules.pop("dhrl.sb3", None)


class Scripted:
    """A same-step env whose one step returns what the test says."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}
    episode_statistics = True
    num_envs = 3
    single_observation_space = gym.spaces.Box(-1, 1, (2,), np.float32)
    single_action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

    def __init__(self, terminated, truncated):
        self.flags = np.array(terminated), np.array(truncated)

    def step(self, actions):
        terminated, truncated = self.flags
        done = terminated | truncated
        info = {
            "state": np.zeros((3, 2), np.float32),
            "ready": np.ones(3, bool),
            "final_obs": np.array([np.full(2, i, np.float32) for i in range(3)], dtype=object),
            "episode": {"r": np.array([1.0, 2.0, 3.0]), "l": np.array([10, 20, 30]), "t": np.zeros(3)},
            "_episode": done,
        }
        return np.zeros((3, 2), np.float32), np.ones(3), terminated, truncated, info


def test_time_limit_flag_is_set_only_for_time_limit_ends(sb3_adapter):
    # Copy 0 terminates, copy 1 is cut by the time limit, copy 2 terminates on the step the
    # limit also falls on: SB3 must bootstrap copy 1 only.
    env = sb3_adapter.DhrlVecEnv(Scripted([True, False, True], [False, True, True]))
    env.step_async(np.zeros((3, 1), np.float32))
    obs, rewards, dones, infos = env.step_wait()
    assert dones.tolist() == [True, True, True]
    assert [info["TimeLimit.truncated"] for info in infos] == [False, True, False]
    for i, info in enumerate(infos):
        np.testing.assert_array_equal(info["terminal_observation"], np.full(2, i))
        assert info["episode"] == {"r": float(i + 1), "l": 10 * (i + 1), "t": 0.0}
    assert rewards.dtype == np.float32


def test_steps_follow_the_same_step_env_they_wrap(sb3_adapter):
    env = sb3_adapter.make_vec("hopper", 4, delay=2, seed=0)
    twin = dhrl.make_vec("hopper", 4, delay=2, seed=0, autoreset_mode="same_step", episode_statistics=True)
    np.testing.assert_array_equal(env.reset(), twin.reset()[0])
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(300):
        a = rng.uniform(-1, 1, (4, 3)).astype(np.float32)
        env.step_async(a)
        obs, rewards, dones, infos = env.step_wait()
        o, r, term, trunc, info = twin.step(a)
        np.testing.assert_array_equal(obs, o)
        np.testing.assert_array_equal(rewards, r.astype(np.float32))
        assert dones.tolist() == (term | trunc).tolist()
        for i in range(4):
            np.testing.assert_array_equal(infos[i]["state"], info["state"][i])
            if dones[i]:
                ends += 1
                np.testing.assert_array_equal(infos[i]["terminal_observation"], info["final_obs"][i])
                assert infos[i]["TimeLimit.truncated"] == bool(trunc[i] and not term[i])
                assert infos[i]["episode"]["l"] == info["episode"]["l"][i]
                assert infos[i]["episode"]["r"] == float(info["episode"]["r"][i])
            else:
                assert "terminal_observation" not in infos[i]
    assert ends > 0
    with pytest.raises(RuntimeError, match="without step_async"):
        env.step_wait()


def test_the_adapter_needs_the_envs_own_episode_statistics(sb3_adapter):
    """SB3's Monitor form comes from the env's statistics: an env without them is refused by
    name, and make_vec turns them on (and refuses to turn them off)."""
    plain = dhrl.make_vec("hopper", 2, autoreset_mode="same_step")
    assert plain.episode_statistics is False
    with pytest.raises(ValueError, match="episode_statistics=True"):
        sb3_adapter.DhrlVecEnv(plain)
    with pytest.raises(ValueError, match="autoreset_mode='same_step'"):
        sb3_adapter.DhrlVecEnv(dhrl.make_vec("hopper", 2, episode_statistics=True))
    assert sb3_adapter.make_vec("hopper", 2).env.episode_statistics is True
    with pytest.raises(ValueError, match="episode_statistics must be True"):
        sb3_adapter.make_vec("hopper", 2, episode_statistics=False)
