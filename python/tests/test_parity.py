"""At Δ = 0 every step of dhrl.make_vec equals gymnasium.make("<Task>-v4") from the same
state, for all six tasks; at Δ > 0 observations, rewards and transitions equal the traces of
`dhrl rollout` (undelayed and `--delay`)."""

import json

import gymnasium as gym
import numpy as np
import pytest

import dhrl

from conftest import run_dhrl

TASK_STEPS = {
    "Ant-v4": 300,
    "HalfCheetah-v4": 1000,  # a full episode, truncated by the time limit
    "Hopper-v4": 300,
    "Walker2d-v4": 300,
    "Humanoid-v4": 300,
    "InvertedPendulum-v4": 300,
}


@pytest.mark.parametrize("gym_id", list(TASK_STEPS))
def test_undelayed_steps_equal_gymnasium(gym_id):
    reference = gym.make(gym_id)
    ours = dhrl.make_vec(gym_id, 1)
    rng = np.random.default_rng(0)
    episodes = ends = 0
    steps = 0
    while steps < TASK_STEPS[gym_id]:
        gym_obs, _ = reference.reset(seed=episodes)
        qpos, qvel = reference.unwrapped.data.qpos.copy(), reference.unwrapped.data.qvel.copy()
        obs, _ = ours.set_state(qpos, qvel)
        np.testing.assert_array_equal(obs[0], gym_obs.astype(np.float32))
        episodes += 1
        while steps < TASK_STEPS[gym_id]:
            action = rng.uniform(-1, 1, reference.action_space.shape).astype(np.float32)
            gym_obs, gym_reward, gym_term, gym_trunc, _ = reference.step(action.astype(np.float64))
            obs, reward, term, trunc, info = ours.step(action[None])
            steps += 1
            np.testing.assert_array_equal(obs[0], gym_obs.astype(np.float32), err_msg=f"step {steps}")
            np.testing.assert_array_equal(info["state"][0], gym_obs.astype(np.float32))
            assert reward[0] == np.float32(gym_reward), f"step {steps}: {reward[0]} vs {gym_reward}"
            assert (term[0], trunc[0]) == (gym_term, gym_trunc), f"step {steps}"
            if gym_term or gym_trunc:
                ends += 1
                ours.step(np.zeros((1, ours.act_dim), np.float32))  # the next-step reset
                break
    if gym_id == "HalfCheetah-v4":
        assert trunc[0], "the 1000-step time limit truncates the episode"
    elif gym_id != "Ant-v4":
        assert ends > 0, "at least one terminated episode"


def trace(dhrl_bin, tmp_path, task, state, actions, *delay):
    (tmp_path / "state.json").write_text(json.dumps(state))
    (tmp_path / "actions.csv").write_text(
        "\n".join(",".join(repr(float(a)) for a in row) for row in actions) + "\n"
    )
    out = run_dhrl(
        dhrl_bin, "rollout", "--task", task, "--init-state", str(tmp_path / "state.json"),
        "--actions", str(tmp_path / "actions.csv"), *delay,
    )
    return [json.loads(line) for line in out.splitlines()]


@pytest.mark.parametrize("task,delay,action_delay", [("hopper", 3, 0), ("walker2d", 2, 2)])
def test_delayed_steps_and_transitions_equal_dhrl_rollout(dhrl_bin, tmp_path, task, delay, action_delay):
    reference = gym.make(dhrl.TASKS[task])
    reference.reset(seed=11)
    state = {
        "qpos": reference.unwrapped.data.qpos.tolist(),
        "qvel": reference.unwrapped.data.qvel.tolist(),
    }
    total = delay + action_delay
    env = dhrl.make_vec(task, 1, delay=delay, action_delay=action_delay)
    rng = np.random.default_rng(3)
    actions = rng.uniform(-1, 1, (400, env.act_dim)).astype(np.float32)
    actions[:total] = 0  # the zero warm-up the env executes before x_0 exists
    undelayed = trace(dhrl_bin, tmp_path, task, state, actions)
    delayed = trace(
        dhrl_bin, tmp_path, task, state, actions, "--delay", str(delay), "--action-delay", str(action_delay)
    )
    obs, info = env.set_state(state["qpos"], state["qvel"])
    shown = {0: obs[0].copy()}
    checked = 0
    for line in delayed[1:]:
        t = line["t"]
        obs, reward, term, trunc, info = env.step(actions[t - 1][None])
        if "delivered" in line:  # the end: everything in flight arrives with it
            end = undelayed[t]
            assert (term[0], trunc[0]) == (end["terminated"], end["truncated"]), f"t = {t}"
            delivered = sum(d["reward"] for d in line["delivered"] if "reward" in d)
            regular = line.get("reward", 0.0)
            assert reward[0] == pytest.approx(delivered + regular, rel=1e-5)
        else:
            assert not (term[0] or trunc[0]), f"t = {t}"
            expected = np.asarray(line.get("augmented", np.zeros(env.single_observation_space.shape)), np.float32)
            np.testing.assert_array_equal(obs[0], expected, err_msg=f"t = {t}")
            assert reward[0] == np.float32(line.get("reward", 0.0)), f"t = {t}"
            shown[t] = obs[0].copy()
        tr = info["transitions"]
        for k in range(len(tr["tau"])):
            tau = int(tr["tau"][k])
            np.testing.assert_array_equal(tr["augmented"][k], shown[tau])
            np.testing.assert_array_equal(tr["state"][k], np.float32(undelayed[tau]["obs"]))
            np.testing.assert_array_equal(tr["action"][k], actions[tau])
            assert tr["reward"][k] == np.float32(undelayed[tau + 1]["reward"])
            np.testing.assert_array_equal(tr["next_state"][k], np.float32(undelayed[tau + 1]["obs"]))
            if tau + 1 in shown:
                np.testing.assert_array_equal(tr["next_augmented"][k], shown[tau + 1])
            assert bool(tr["terminated"][k]) == bool(undelayed[tau + 1]["terminated"])
            checked += 1
        if term[0] or trunc[0]:
            break
    assert checked > 20
