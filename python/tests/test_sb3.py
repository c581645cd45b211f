"""The Stable-Baselines3 adapter: SB3's VecEnv conventions (same-step reset,
terminal_observation, TimeLimit.truncated, Monitor-style episode info), its wrappers, and
SAC training on it unchanged. Skipped where SB3 is not installed (CI: torch is too large)."""

import numpy as np
import pytest

sb3 = pytest.importorskip("stable_baselines3", reason="Stable-Baselines3 (and torch) not installed")

import dhrl.sb3  # noqa: E402
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize  # noqa: E402


def test_vecenv_conventions():
    env = dhrl.sb3.make_vec("hopper", 4, delay=2, seed=0)
    assert env.num_envs == 4
    assert env.observation_space.shape == (11 + 2 * 3,)
    assert env.action_space.shape == (3,)
    env.seed(7)
    obs = env.reset()
    assert obs.shape == (4, 17) and obs.dtype == np.float32
    again = dhrl.sb3.make_vec("hopper", 4, delay=2, seed=7).reset()
    np.testing.assert_array_equal(obs, again)
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(300):
        env.step_async(rng.uniform(-1, 1, (4, 3)).astype(np.float32))
        obs, rewards, dones, infos = env.step_wait()
        assert obs.shape == (4, 17) and rewards.shape == (4,) and dones.dtype == np.bool_
        assert isinstance(infos, list) and len(infos) == 4
        for i in np.flatnonzero(dones):
            ends += 1
            assert infos[i]["terminal_observation"].shape == (17,)
            assert isinstance(infos[i]["TimeLimit.truncated"], bool)
            assert set(infos[i]["episode"]) == {"r", "l", "t"}
            # Same-step: the next episode's x_0 (Δ = 2: no observation yet).
            assert not obs[i, 11:].any()
    assert ends > 0
    assert env.get_attr("delay") == [2] * 4
    assert env.env_is_wrapped(VecMonitor) == [False] * 4
    with pytest.raises(ValueError, match="same_step"):
        dhrl.sb3.make_vec("hopper", 2, autoreset_mode="next_step")


def test_sb3_wrappers_and_sac_run_unchanged():
    env = VecNormalize(VecMonitor(dhrl.sb3.make_vec("inverted-pendulum", 2, delay=3, seed=1)))
    model = sb3.SAC("MlpPolicy", env, learning_starts=100, batch_size=32, device="cpu", seed=0)
    model.learn(400)
    assert model.num_timesteps >= 400
    assert len(model.ep_info_buffer) > 0, "episode returns reached SB3's logger"
