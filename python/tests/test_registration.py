"""``import dhrl`` registers one Gymnasium id per task, ``dhrl/<Task>-delayed-v0``, whose
vector entry point builds the same env as ``dhrl.make_vec`` with every keyword passed on."""

import os
import pathlib
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest

import dhrl
from dhrl.registration import GYMNASIUM_IDS, register_envs

PYTHON_DIR = pathlib.Path(dhrl.__file__).resolve().parents[1]


def test_every_task_has_an_id():
    assert set(GYMNASIUM_IDS) == set(dhrl.TASKS) and len(GYMNASIUM_IDS) == 6
    assert GYMNASIUM_IDS["half-cheetah"] == "dhrl/HalfCheetah-delayed-v0"
    assert GYMNASIUM_IDS["inverted-pendulum"] == "dhrl/InvertedPendulum-delayed-v0"
    for task, env_id in GYMNASIUM_IDS.items():
        spec = gym.spec(env_id)
        assert spec.namespace == "dhrl" and spec.version == 0
        assert spec.name == dhrl.TASKS[task].removesuffix("-v4") + "-delayed"
        assert spec.kwargs == {"task": task}
        assert spec.entry_point is None, "vector-only: dhrl has no single-env class"
        assert spec.vector_entry_point == "dhrl.registration:make_registered_vec"


@pytest.mark.parametrize("task", sorted(GYMNASIUM_IDS))
def test_make_vec_builds_the_task(task):
    env = gym.make_vec(GYMNASIUM_IDS[task], num_envs=2, delay=2)
    assert isinstance(env, dhrl.DelayedVectorEnv)
    assert env.task == task and env.num_envs == 2 and env.delay == 2
    assert env.spec.id == GYMNASIUM_IDS[task]
    assert env.spec.kwargs["num_envs"] == 2 and env.spec.kwargs["delay"] == 2
    twin = dhrl.make_vec(task, 2, delay=2)
    assert env.single_observation_space == twin.single_observation_space
    assert env.single_action_space == twin.single_action_space
    env.close()


def test_every_option_is_passed_on():
    options = dict(
        delay=3, action_delay=1, actuator_noise=0.05, warmup="random", seed=9, num_threads=2,
        autoreset_mode="same_step", episode_statistics=True,
    )
    env = gym.make_vec("dhrl/Hopper-delayed-v0", num_envs=3, **options)
    twin = dhrl.make_vec("hopper", 3, **options)
    assert env.config == twin.config and env.delay == 4 and env.num_threads == 2
    assert env.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    o1, i1 = env.reset()
    o2, i2 = twin.reset()
    np.testing.assert_array_equal(o1, o2)
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(150):
        a = rng.uniform(-1, 1, (3, 3)).astype(np.float32)
        s1, s2 = env.step(a), twin.step(a)
        for x, y in zip(s1[:4], s2[:4]):
            np.testing.assert_array_equal(x, y)
        done = s1[2] | s1[3]
        if done.any():
            np.testing.assert_array_equal(s1[4]["episode"]["l"], s2[4]["episode"]["l"])
            ends += int(done.sum())
    assert ends > 0


def test_refusals():
    with pytest.raises(gym.error.Error, match="entry_point is not specified"):
        gym.make("dhrl/HalfCheetah-delayed-v0")
    with pytest.raises(gym.error.Error, match="doesn't have an entry point"):
        gym.make_vec("dhrl/HalfCheetah-delayed-v0", num_envs=2, vectorization_mode="sync")
    with pytest.raises(TypeError, match="unexpected keyword argument 'bogus'"):
        gym.make_vec("dhrl/HalfCheetah-delayed-v0", num_envs=2, bogus=1)
    with pytest.raises(ValueError, match="delay must be ≥ 0"):
        gym.make_vec("dhrl/HalfCheetah-delayed-v0", num_envs=2, delay=-1)
    with pytest.raises(ValueError, match="1000-step time limit"):
        gym.make_vec("dhrl/HalfCheetah-delayed-v0", num_envs=2, max_episode_steps=500)
    # Gymnasium's own time limit, as its v4 tasks have it: accepted, it is the env's.
    assert gym.make_vec("dhrl/HalfCheetah-delayed-v0", num_envs=1, max_episode_steps=1000).num_envs == 1


def test_registering_again_changes_nothing():
    before = {env_id: gym.spec(env_id) for env_id in GYMNASIUM_IDS.values()}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # Gymnasium warns when an id is overridden
        assert register_envs() == list(GYMNASIUM_IDS.values())
    assert all(gym.spec(env_id) is spec for env_id, spec in before.items())


def test_a_fresh_process_finds_the_ids_through_the_module_prefix():
    """Gymnasium ≥ 1.0 loads no plugin entry points: without ``import dhrl`` the plain id is
    unknown, and ``"dhrl:<id>"`` imports dhrl (registering the ids) first."""
    code = (
        "import gymnasium as gym\n"
        "try:\n"
        "    gym.make_vec('dhrl/InvertedPendulum-delayed-v0', num_envs=2)\n"
        "except gym.error.Error as e:\n"
        "    print('unknown:', type(e).__name__)\n"
        "env = gym.make_vec('dhrl:dhrl/InvertedPendulum-delayed-v0', num_envs=2, delay=1)\n"
        "print(type(env).__name__, env.task, env.num_envs, env.delay)\n"
    )
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(PYTHON_DIR), env.get("PYTHONPATH")) if p)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["unknown: NamespaceNotFound", "DelayedVectorEnv inverted-pendulum 2 1"]
