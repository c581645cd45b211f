"""Bad input raises ValueError / TypeError naming what was wrong and what is accepted, and
the env keeps working after it."""

import numpy as np
import pytest

import dhrl


@pytest.mark.parametrize(
    "kwargs,error,message",
    [
        ({"task": "cartpole"}, ValueError, "unknown task 'cartpole'; accepted: 'ant' / 'Ant-v4'"),
        ({"task": "Hopper-v5"}, ValueError, "accepted:"),
        ({"delay": -1}, ValueError, "delay must be ≥ 0; got -1"),
        ({"action_delay": -2}, ValueError, "action_delay must be ≥ 0"),
        ({"delay": 2.5}, TypeError, "delay must be an integer"),
        ({"delay": 65}, ValueError, "total delay 65 is above the supported maximum 64"),
        ({"max_delay": 0}, ValueError, "max_delay must be ≥ 1"),
        ({"delay": 2, "max_delay": 4}, ValueError, "give one of them"),
        ({"num_envs": 0}, ValueError, "num_envs must be ≥ 1"),
        ({"actuator_noise": -0.1}, ValueError, "actuator_noise must be a finite number ≥ 0"),
        ({"actuator_noise": float("nan")}, ValueError, "finite"),
        ({"warmup": "ones"}, ValueError, "accepted: 'zeros' or 'random'"),
        ({"autoreset_mode": "sometimes"}, ValueError, "accepted: 'next_step', 'same_step'"),
        ({"num_threads": 0}, ValueError, "num_threads must be ≥ 1"),
    ],
)
def test_bad_construction_arguments(kwargs, error, message):
    args = {"task": "hopper", "num_envs": 2, **kwargs}
    with pytest.raises(error, match=None) as raised:
        dhrl.make_vec(**args)
    assert message in str(raised.value)


def test_bad_actions_leave_the_env_working():
    env = dhrl.make_vec("hopper", 3, delay=2)
    env.reset(seed=0)
    good = np.zeros((3, 3), np.float32)
    twin = dhrl.make_vec("hopper", 3, delay=2)
    twin.reset(seed=0)
    cases = [
        (np.zeros((3, 2), np.float32), ValueError, "actions have shape (3, 2); expected (3, 3)"),
        (np.zeros(9, np.float32), ValueError, "expected (3, 3)"),
        (np.full((3, 3), "a"), TypeError, "numeric array"),
        (np.array([[0, 0, np.nan]] * 3, np.float32), ValueError, "actions[0, 2] is nan; only finite"),
        (np.array([[0, np.inf, 0]] * 3), ValueError, "only finite numbers"),
        ([[0, 0], [0]], TypeError, "actions must be"),
    ]
    for actions, error, message in cases:
        with pytest.raises(error) as raised:
            env.step(actions)
        assert message in str(raised.value), str(raised.value)
    # Nothing was stepped: the env continues exactly like one that never saw the bad input.
    for _ in range(5):
        a = env.step(good)
        b = twin.step(good)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
    # float64 and integer actions are accepted (converted to float32).
    env.step(np.zeros((3, 3)))
    env.step(np.zeros((3, 3), int))


def test_the_raw_anchor_takes_one_thread_or_more():
    from dhrl import _dhrl

    with pytest.raises(ValueError, match="threads must be ≥ 1 .*; got 0"):
        _dhrl.raw_mj_step_rate("hopper", 4, 10, 0)
    with pytest.raises(ValueError, match="unknown task"):
        _dhrl.raw_mj_step_rate("cartpole", 4, 10, 2)


def test_bad_reset_arguments():
    env = dhrl.make_vec("hopper", 2)
    with pytest.raises(TypeError, match="one integer for the whole batch"):
        env.reset(seed=[1, 2])
    with pytest.raises(ValueError, match="seed must be ≥ 0"):
        env.reset(seed=-1)
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(options={"mask": 1})
    env.reset(seed=1)
