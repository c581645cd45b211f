"""dhrl's env under Gymnasium's own vector wrappers, stacked as CleanRL-style scripts stack them
(RecordEpisodeStatistics innermost, so it sums the env's rewards before NormalizeReward scales
them; ClipAction; NormalizeObservation; NormalizeReward), over ``dhrl.make_vec`` and over the
registered id through ``gymnasium.make_vec``.

Each wrapped env runs beside an unwrapped twin (same task, delay and seed, its own episode
statistics on) that is given the clipped actions by hand: everything a wrapper reports is
checked against what the twin produced. The twin's statistics are the library's own true
return and length, a source independent of the wrapper's bookkeeping."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers.vector import ClipAction, NormalizeObservation, NormalizeReward, RecordEpisodeStatistics

import dhrl

DELAY = 3


def build_dhrl(task, num_envs, **options):
    return dhrl.make_vec(task, num_envs, **options)


def build_registered(task, num_envs, **options):
    return gym.make_vec(dhrl.GYMNASIUM_IDS[task], num_envs=num_envs, **options)


BUILDERS = [pytest.param(build_dhrl, id="dhrl.make_vec"), pytest.param(build_registered, id="gymnasium.make_vec")]


def expected_running_stats(rows: np.ndarray, prior: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of ``rows`` as Gymnasium's RunningMeanStd holds them: its start (mean
    0, variance 1, weight ``prior``) pooled with every row it was updated with."""
    n = len(rows)
    mean = rows.sum(axis=0) / (n + prior)
    m2 = np.square(rows - mean).sum(axis=0) + prior * (1.0 + np.square(mean))
    return mean, m2 / (n + prior)


def clipping_actions(rng, space, num_envs):
    """Uniform in twice the bounds: about half of the values need clipping."""
    return rng.uniform(2 * space.low, 2 * space.high, (num_envs, space.low.size))


@pytest.mark.parametrize("build", BUILDERS)
@pytest.mark.parametrize(
    "task,num_envs,steps,min_episodes",
    [
        # Falls within tens of steps under random pushes: many terminated episodes.
        ("inverted-pendulum", 4, 300, 20),
        # Never terminates: each copy's one episode is truncated at 1000 true steps, and its
        # reward has a control cost, so an unclipped action would change it.
        ("half-cheetah", 2, 1001, 2),
    ],
)
def test_cleanrl_wrapper_stack_next_step(build, task, num_envs, steps, min_episodes):
    seed = 11
    base = build(task, num_envs, delay=DELAY, seed=seed)
    assert isinstance(base, dhrl.DelayedVectorEnv) and base.episode_statistics is False
    stats = RecordEpisodeStatistics(base)
    clip = ClipAction(stats)
    norm_obs = NormalizeObservation(clip)
    env = NormalizeReward(norm_obs, gamma=0.99)
    twin = dhrl.make_vec(task, num_envs, delay=DELAY, seed=seed, episode_statistics=True)
    space = twin.single_action_space

    obs, info = env.reset(seed=seed)
    twin_obs, twin_info = twin.reset(seed=seed)
    np.testing.assert_array_equal(info["state"], twin_info["state"])
    seen = [twin_obs]
    rng = np.random.default_rng(0)
    returns = np.zeros(num_envs)  # the raw rewards of each copy's current episode, summed here
    lengths = np.zeros(num_envs, int)
    ended = np.zeros(num_envs, bool)
    ready = info["ready"]
    episodes = clipped_values = 0
    for _ in range(steps):
        actions = clipping_actions(rng, space, num_envs)
        clipped = np.clip(actions, space.low, space.high).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(actions)
        twin_obs, raw, twin_terminated, twin_truncated, twin_info = twin.step(clipped)
        seen.append(twin_obs)

        # ClipAction: the env applied exactly the clipped actions (warm-up rows aside, which
        # both replace alike); outside the warm-up they differ from what the agent asked for.
        np.testing.assert_array_equal(info["action"], twin_info["action"])
        assert (info["action"] >= space.low).all() and (info["action"] <= space.high).all()
        # A copy acts once an observation has arrived (it was ready before this step).
        acting = ready & ~ended
        np.testing.assert_array_equal(info["action"][acting], clipped[acting])
        clipped_values += int((actions[acting] != clipped[acting]).sum())
        ready = info["ready"]

        np.testing.assert_array_equal(terminated, twin_terminated)
        np.testing.assert_array_equal(truncated, twin_truncated)
        # NormalizeObservation: the twin's observation under the wrapper's running statistics.
        rms = norm_obs.obs_rms
        np.testing.assert_allclose(
            obs, (twin_obs - rms.mean) / np.sqrt(rms.var + norm_obs.epsilon), rtol=1e-5, atol=1e-5
        )
        assert obs.dtype == np.float32
        # NormalizeReward: the raw reward scaled by the wrapper's return statistics.
        scale = np.sqrt(env.return_rms.var + env.epsilon)
        np.testing.assert_allclose(reward, raw / scale, rtol=1e-6)

        # Next-step autoreset: the call after an end only shows the new episode (reward 0).
        assert (raw[ended] == 0).all()
        returns[ended] = 0
        lengths[ended] = 0
        returns[~ended] += raw[~ended]
        lengths[~ended] += 1
        done = terminated | truncated
        if done.any():
            # RecordEpisodeStatistics' episode: the sums and lengths of the raw rewards, which
            # are the library's own true return and length of each finished episode.
            assert info["_episode"].tolist() == done.tolist()
            episode = info["episode"]
            np.testing.assert_allclose(episode["r"][done], returns[done], rtol=1e-12)
            np.testing.assert_array_equal(episode["l"][done], lengths[done])
            np.testing.assert_allclose(episode["r"][done], twin_info["episode"]["r"][done], rtol=1e-5)
            np.testing.assert_array_equal(episode["l"][done], twin_info["episode"]["l"][done])
            assert (episode["r"][~done] == 0).all() and (episode["l"][~done] == 0).all()
            assert (episode["t"][done] >= 0).all()
            episodes += int(done.sum())
        else:
            assert "episode" not in info
        ended = done

    assert episodes >= min_episodes, episodes
    assert stats.episode_count == episodes and len(stats.return_queue) == min(episodes, 100)
    if task == "half-cheetah":
        assert list(stats.length_queue) == [1000] * num_envs, "truncated at 1000 true steps"
    assert clipped_values > steps // 2, "the agent's actions were clipped, not passed through"
    assert env.return_rms.var != 1.0, "the rewards were scaled by statistics that moved"
    # NormalizeObservation's running statistics are those of every observation the env
    # produced (resets and the steps that show a new episode included), nothing else.
    mean, var = expected_running_stats(np.concatenate(seen).astype(np.float64))
    np.testing.assert_allclose(norm_obs.obs_rms.mean, mean, rtol=1e-3, atol=1e-4)
    np.testing.assert_allclose(norm_obs.obs_rms.var, var, rtol=1e-3, atol=1e-6)
    env.close()
    assert base.closed


@pytest.mark.parametrize("build", BUILDERS)
def test_record_episode_statistics_and_normalize_reward_same_step(build):
    """Same-step autoreset: every call is a step of some episode; the finished episode's last
    observation goes to ``final_obs``. NormalizeObservation only takes next-step envs."""
    num_envs, seed = 3, 5
    base = build("inverted-pendulum", num_envs, delay=DELAY, seed=seed, autoreset_mode="same_step")
    with pytest.raises(ValueError, match="NEXT_STEP"):
        NormalizeObservation(base)
    stats = RecordEpisodeStatistics(base)
    env = NormalizeReward(ClipAction(stats))
    twin = dhrl.make_vec(
        "inverted-pendulum", num_envs, delay=DELAY, seed=seed, autoreset_mode="same_step", episode_statistics=True
    )
    space = twin.single_action_space
    env.reset(seed=seed)
    twin.reset(seed=seed)
    rng = np.random.default_rng(1)
    returns, lengths = np.zeros(num_envs), np.zeros(num_envs, int)
    episodes = 0
    for _ in range(200):
        actions = clipping_actions(rng, space, num_envs)
        obs, reward, terminated, truncated, info = env.step(actions)
        twin_obs, raw, *_, twin_info = twin.step(np.clip(actions, space.low, space.high).astype(np.float32))
        np.testing.assert_array_equal(obs, twin_obs)
        np.testing.assert_allclose(reward, raw / np.sqrt(env.return_rms.var + env.epsilon), rtol=1e-6)
        returns += raw
        lengths += 1
        done = terminated | truncated
        if done.any():
            np.testing.assert_allclose(info["episode"]["r"][done], returns[done], rtol=1e-12)
            np.testing.assert_array_equal(info["episode"]["l"][done], lengths[done])
            np.testing.assert_array_equal(info["episode"]["l"][done], twin_info["episode"]["l"][done])
            assert "episode" not in info["final_info"], "the env's own statistics are off"
            for i in np.flatnonzero(done):
                np.testing.assert_array_equal(info["final_obs"][i], twin_info["final_obs"][i])
            returns[done], lengths[done] = 0, 0
            episodes += int(done.sum())
    assert episodes >= 10, episodes


def test_the_envs_own_statistics_collide_with_the_wrapper_by_design():
    """``episode_statistics=True`` writes the key RecordEpisodeStatistics writes: the wrapper
    refuses to overwrite it (the reason the env's own statistics are off by default)."""
    env = RecordEpisodeStatistics(dhrl.make_vec("inverted-pendulum", 2, seed=0, episode_statistics=True))
    env.reset()
    push = np.full((2, 1), 3.0, np.float32)
    with pytest.raises(ValueError, match="key 'episode' but this key already exists"):
        for _ in range(200):
            env.step(push)
    # Under another key of the wrapper's, the two agree.
    env = RecordEpisodeStatistics(
        dhrl.make_vec("inverted-pendulum", 2, seed=0, episode_statistics=True), stats_key="wrapper_episode"
    )
    env.reset()
    for _ in range(200):
        *_, terminated, truncated, info = env.step(push)
        done = terminated | truncated
        if done.any():
            break
    assert done.any()
    np.testing.assert_array_equal(info["wrapper_episode"]["l"][done], info["episode"]["l"][done])
    np.testing.assert_allclose(info["wrapper_episode"]["r"][done], info["episode"]["r"][done], rtol=1e-5)
