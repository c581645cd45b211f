"""dhrl flushes subnormal floats on its own threads only: its pool's workers have the mode on,
and the caller's (Python's) thread gets its own mode back after every call, so numpy in the
user's process keeps IEEE subnormals."""

import os
import platform

import numpy as np
import pytest

import dhrl

pytestmark = pytest.mark.skipif(
    platform.machine().lower() not in ("x86_64", "amd64", "aarch64", "arm64"),
    reason="the float mode is only set on x86_64 and aarch64",
)
FLUSHING = os.environ.get("DHRL_FLUSH_SUBNORMALS", "").strip() != "0"


def python_thread_keeps_subnormals():
    """True when this thread neither flushes subnormal results (FTZ) nor reads subnormal
    inputs as zero (DAZ)."""
    tiny = np.array([1e-30], np.float32) * np.array([1e-10], np.float32)  # 1e-40: subnormal
    subnormal_in = np.array([1e-39], np.float32) * np.float32(1.0)
    return bool(tiny[0] != 0 and subnormal_in[0] != 0)


@pytest.mark.parametrize("num_envs,num_threads", [(1, 1), (3, 1), (4, 2)])
def test_workers_flush_and_the_callers_thread_is_left_alone(num_envs, num_threads):
    assert python_thread_keeps_subnormals()
    env = dhrl.make_vec("half-cheetah", num_envs, delay=2, num_threads=num_threads)
    assert python_thread_keeps_subnormals()
    assert env._batch.workers_flush_subnormals() == [FLUSHING] * num_threads
    env.reset(seed=1)
    assert python_thread_keeps_subnormals()
    actions = np.full((num_envs, 6), 0.3, np.float32)
    for _ in range(4):
        env.step(actions)
        assert python_thread_keeps_subnormals()
    env.set_state(np.zeros(9), np.full(9, 0.1))
    assert python_thread_keeps_subnormals()
    env.step(actions)
    assert python_thread_keeps_subnormals()
    env.close()
