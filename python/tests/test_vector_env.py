"""The vector-env contract: spaces, dtypes, seeding, autoreset in every mode, reset masks,
episode statistics (opt-in), and the delayed channels as documented in dhrl.vector."""

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import dhrl


def random_actions(env, rng):
    return rng.uniform(-1, 1, (env.num_envs, env.act_dim)).astype(np.float32)


def run(env, steps, seed=0):
    rng = np.random.default_rng(seed)
    log = [env.reset(seed=seed)]
    for _ in range(steps):
        log.append(env.step(random_actions(env, rng)))
    return log


@pytest.mark.parametrize("task,obs,act", [("hopper", 11, 3), ("HalfCheetah-v4", 17, 6), ("humanoid", 376, 17)])
@pytest.mark.parametrize("delay", [0, 4])
def test_spaces_and_dtypes(task, obs, act, delay):
    env = dhrl.make_vec(task, 3, delay=delay)
    aug = obs + delay * act
    assert env.single_observation_space.shape == (aug,)
    assert env.observation_space.shape == (3, aug)
    assert env.single_action_space.shape == (act,)
    assert env.action_space.shape == (3, act)
    assert env.single_observation_space.dtype == np.float32
    assert env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert env.delay == delay
    o, info = env.reset(seed=1)
    assert o.dtype == np.float32 and o.shape == (3, aug)
    assert info["state"].shape == (3, obs) and info["ready"].dtype == np.bool_
    assert o in env.observation_space
    env.action_space.seed(0)
    for _ in range(6):
        o, r, term, trunc, info = env.step(env.action_space.sample())
        assert o.dtype == np.float32 and o.shape == (3, aug) and o in env.observation_space
        assert r.dtype == np.float32 and r.shape == (3,)
        assert term.dtype == np.bool_ and trunc.dtype == np.bool_
        assert info["action"].shape == (3, act)
    env.close()


def test_seeding_is_deterministic_and_independent_of_threads():
    a = run(dhrl.make_vec("hopper", 8, delay=3, num_threads=1), 120, seed=5)
    b = run(dhrl.make_vec("hopper", 8, delay=3, num_threads=2, seed=99), 120, seed=5)
    c = run(dhrl.make_vec("hopper", 8, delay=3), 120, seed=6)
    for x, y in zip(a[1:], b[1:]):
        for u, v in zip(x[:4], y[:4]):
            np.testing.assert_array_equal(u, v)
    assert not np.array_equal(a[0][1]["state"], c[0][1]["state"]), "another seed, other initial states"
    # A fresh env's first reset() is the reset of its own seed.
    _, fresh = dhrl.make_vec("hopper", 8, delay=3, seed=5).reset()
    np.testing.assert_array_equal(fresh["state"], a[0][1]["state"])


def test_warmup_zeros_observations_and_rewards_before_delta():
    delay = 5
    env = dhrl.make_vec("inverted-pendulum", 4, delay=delay, warmup="zeros")
    obs, info = env.reset(seed=0)
    assert not info["ready"].any() and not obs.any()
    rng = np.random.default_rng(1)
    for t in range(1, delay + 3):
        chosen = random_actions(env, rng)
        obs, reward, term, trunc, info = env.step(chosen)
        applied = info["action"]
        if t <= delay:
            # The action chosen at t-1 < Δ is replaced by the zero warm-up action.
            assert not applied.any()
            assert (reward == 0).all() and not term.any()
        else:
            np.testing.assert_array_equal(applied, chosen)
            assert (reward != 0).all(), "the reward of step t-Δ arrives with s_{t-Δ}"
        assert info["ready"].all() == (t >= delay)
        if t >= delay:
            # x_t = (s_{t-Δ}, a_{t-Δ}, …, a_{t-1}): its last action is the one just applied.
            np.testing.assert_array_equal(obs[:, -env.act_dim:], applied)


def test_next_step_autoreset_and_episode_statistics():
    env = dhrl.make_vec("hopper", 6, delay=2, episode_statistics=True)
    rng = np.random.default_rng(0)
    env.reset(seed=3)
    returns = np.zeros(6)
    ended = np.zeros(6, bool)
    checked = 0
    for _ in range(400):
        obs, reward, term, trunc, info = env.step(random_actions(env, rng))
        done = term | trunc
        # A copy that ended in the last step restarts now: reward 0, no flags, not ready.
        assert (reward[ended] == 0).all() and not done[ended].any()
        assert not info["ready"][ended].any()
        assert not obs[ended, 11:].any(), "a new episode's x_0 (Δ = 2) is zeros"
        returns += np.where(ended, 0, reward)
        if done.any():
            assert info["_episode"].tolist() == done.tolist()
            # The delivered rewards of an episode add up to its true return.
            np.testing.assert_allclose(returns[done], info["episode"]["r"][done], rtol=1e-5)
            assert (info["episode"]["l"][done] > 0).all()
            # Next-step: the end step shows the finished episode's last moment
            # x_T = (s_{T-2}, a_{T-2}, a_{T-1}), its last action the one just applied.
            long = done & (info["episode"]["l"] >= 2)
            np.testing.assert_array_equal(obs[long, -3:], info["action"][long])
            assert info["ready"][long].all()
            returns[done] = 0
            checked += int(done.sum())
        ended = done
    assert checked >= 6


def test_same_step_autoreset_final_keys():
    nxt = dhrl.make_vec("hopper", 4, delay=2, seed=1, episode_statistics=True)
    same = dhrl.make_vec("hopper", 4, delay=2, seed=1, autoreset_mode="same_step", episode_statistics=True)
    assert same.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    rng = np.random.default_rng(2)
    nxt.reset()
    same.reset()
    seen = 0
    for _ in range(200):
        a = random_actions(nxt, rng)
        # next-step holds a copy for one step after its end; same-step does not: compare only
        # until the first end.
        o1, r1, t1, u1, i1 = nxt.step(a)
        o2, r2, t2, u2, i2 = same.step(a)
        np.testing.assert_array_equal(r1, r2)
        d = t1 | u1
        if d.any():
            for i in np.flatnonzero(d):
                np.testing.assert_array_equal(i2["final_obs"][i], o1[i])
                np.testing.assert_array_equal(i2["final_observation"][i], o1[i])
                np.testing.assert_array_equal(i2["final_info"]["state"][i], i1["state"][i])
            assert i2["_final_obs"].tolist() == d.tolist()
            assert i2["final_info"]["_episode"].tolist() == d.tolist()
            np.testing.assert_array_equal(i2["final_info"]["episode"]["l"], i1["episode"]["l"])
            # The same step already shows the next episode's first observation.
            assert not o2[d, 11:].any() and not i2["ready"][d].any()
            seen += 1
            break
        np.testing.assert_array_equal(o1, o2)
    assert seen == 1


def test_reset_mask_restarts_only_the_selected_copies():
    env = dhrl.make_vec("half-cheetah", 5, delay=1)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    for _ in range(10):
        obs, *_ = env.step(random_actions(env, rng))
    mask = np.array([True, False, True, False, False])
    new, info = env.reset(options={"reset_mask": mask})
    np.testing.assert_array_equal(new[~mask], obs[~mask])
    assert not info["ready"][mask].any() and info["ready"][~mask].all()
    assert not new[mask].any(), "Δ = 1: a restarted copy has no observation yet"
    obs, reward, *_ = env.step(random_actions(env, rng))
    assert info["ready"][~mask].all() and (reward[mask] == 0).all()
    with pytest.raises(ValueError, match="at least one True"):
        env.reset(options={"reset_mask": np.zeros(5, bool)})
    with pytest.raises(TypeError, match="bool array"):
        env.reset(options={"reset_mask": np.zeros(5, int)})
    with pytest.raises(ValueError, match="shape"):
        env.reset(options={"reset_mask": np.ones(4, bool)})
    with pytest.raises(ValueError, match="seed rebuilds the whole batch"):
        env.reset(seed=1, options={"reset_mask": mask})


def test_copies_kept_by_a_reset_mask_go_on_as_if_nothing_happened():
    """The copies a partial reset keeps are held, not stepped: stepped on, they match a twin
    that was never reset, observation, reward and true state alike."""
    env = dhrl.make_vec("half-cheetah", 5, delay=1, seed=4)
    twin = dhrl.make_vec("half-cheetah", 5, delay=1, seed=4)
    rng = np.random.default_rng(0)
    env.reset()
    twin.reset()
    for _ in range(10):
        a = random_actions(env, rng)
        env.step(a)
        twin.step(a)
    keep = np.array([False, True, False, True, True])
    env.reset(options={"reset_mask": ~keep})
    for _ in range(3):
        a = random_actions(env, rng)
        o1, r1, _, _, i1 = env.step(a)
        o2, r2, _, _, i2 = twin.step(a)
        np.testing.assert_array_equal(o1[keep], o2[keep])
        np.testing.assert_array_equal(r1[keep], r2[keep])
        np.testing.assert_array_equal(i1["state"][keep], i2["state"][keep])
        assert not np.array_equal(i1["state"][~keep], i2["state"][~keep])


@pytest.mark.parametrize("mode", ["next_step", "same_step"])
@pytest.mark.parametrize("delay", [0, 2])
def test_every_step_of_an_episode_is_one_call_and_the_show_step_is_no_step(mode, delay):
    """Counting the calls in which a copy lives gives its episode length: next-step's extra
    call after an end only shows the new episode (held, reward 0); same-step has none, the
    first action of a new episode is applied on the call after the end."""
    env = dhrl.make_vec("hopper", 4, delay=delay, autoreset_mode=mode, seed=5, episode_statistics=True)
    rng = np.random.default_rng(1)
    env.reset()
    lived = np.zeros(4, int)
    ended = np.zeros(4, bool)
    episodes = 0
    for _ in range(300):
        obs, reward, term, trunc, info = env.step(random_actions(env, rng))
        done = term | trunc
        if mode == "next_step":
            assert (reward[ended] == 0).all() and not done[ended].any()
            lived[~ended] += 1
        else:
            lived += 1
        if done.any():
            np.testing.assert_array_equal(lived[done], info["episode"]["l"][done])
            lived[done] = 0
            episodes += int(done.sum())
        ended = done
    assert episodes >= 8, episodes


def test_disabled_autoreset_waits_for_a_reset_mask():
    env = dhrl.make_vec("inverted-pendulum", 3, autoreset_mode="disabled")
    env.reset(seed=0)
    big = np.full((3, 1), 3.0, np.float32)
    for _ in range(200):
        obs, reward, term, trunc, info = env.step(big)
        if (term | trunc).any():
            break
    done = term | trunc
    assert done.any()
    with pytest.raises(ValueError, match="reset them first"):
        env.step(big)
    obs, info = env.reset(options={"reset_mask": done})
    env.step(np.zeros((3, 1), np.float32))


def test_transitions_are_time_aligned():
    delay = 3
    env = dhrl.make_vec("hopper", 3, delay=delay)
    rng = np.random.default_rng(4)
    obs, info = env.reset(seed=2)
    shown = {0: (obs.copy(), info["state"].copy())}
    applied = {}
    t = 0
    total = 0
    for _ in range(60):
        o, r, term, trunc, info = env.step(random_actions(env, rng))
        applied[t] = info["action"].copy()
        t += 1
        if (term | trunc).any():
            break
        shown[t] = (o.copy(), info["state"].copy())
        tr = info["transitions"]
        for k in range(len(tr["env"])):
            i, tau = tr["env"][k], tr["tau"][k]
            total += 1
            np.testing.assert_array_equal(tr["augmented"][k], shown[tau][0][i])
            np.testing.assert_array_equal(tr["state"][k], shown[tau][1][i])
            np.testing.assert_array_equal(tr["action"][k], applied[tau][i])
            np.testing.assert_array_equal(tr["next_augmented"][k], shown[tau + 1][0][i])
            np.testing.assert_array_equal(tr["next_state"][k], shown[tau + 1][1][i])
            # The transition of step τ completes when s_{τ+1} reaches the agent: t = τ + 1 + Δ.
            assert t == tau + 1 + delay
    assert total > 0


@pytest.mark.parametrize("mode", ["next_step", "same_step", "disabled"])
def test_episode_statistics_are_off_by_default(mode):
    """Without ``episode_statistics=True`` the env writes no ``episode`` key anywhere (Gymnasium's
    RecordEpisodeStatistics needs it free); ends, divergence and final keys are unchanged."""
    env = dhrl.make_vec("inverted-pendulum", 3, delay=2, autoreset_mode=mode, seed=0)
    assert env.episode_statistics is False and env.config["episode_statistics"] is False
    env.reset()
    big = np.full((3, 1), 3.0, np.float32)
    for _ in range(200):
        obs, reward, term, trunc, info = env.step(big)
        if (term | trunc).any():
            break
    assert (term | trunc).any(), "InvertedPendulum falls under a full push"
    assert "episode" not in info and "_episode" not in info
    if mode == "same_step":
        assert "final_obs" in info
        assert "episode" not in info["final_info"] and "_episode" not in info["final_info"]
    with pytest.raises(TypeError, match="episode_statistics must be True or False"):
        dhrl.make_vec("hopper", 1, episode_statistics="yes")
