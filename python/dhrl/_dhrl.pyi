"""Types of ``dhrl._dhrl``, the extension module built from ``python/src/lib.rs``: the batched
delayed tasks of the dhrl library as one class, ``Batch``. ``dhrl.vector.DelayedVectorEnv``
builds Gymnasium's interface on it; use that unless you need the raw arrays.

Every array it returns is a new NumPy array that owns its memory. The ``_Current``,
``_Stepped`` and ``_Transitions`` dicts exist for type checkers only. Keep this file in step
with lib.rs: ``python/tests/test_typing.py`` compares it with the built module.
"""

from collections.abc import Sequence
from typing import Final, TypedDict, final

import numpy as np
import numpy.typing as npt

__all__ = ["Batch", "raw_mj_step_rate", "set_assets_dir", "assets_dir", "TASKS", "MAX_DELAY"]

TASKS: Final[list[tuple[str, str]]]
"""``(dhrl name, Gymnasium id)`` of every task, e.g. ``("half-cheetah", "HalfCheetah-v4")``."""

MAX_DELAY: Final[int]
"""The largest total delay (observation + action, or a random delay's bound) a ``Batch`` takes."""

class _Current(TypedDict):
    """What the agent holds now (``Batch.current``, ``reseed``, ``set_state``)."""

    augmented: npt.NDArray[np.float32]
    """``[N, obs_dim + delay·act_dim]``: the augmented states ``x_t`` (zeros before the first
    observation arrives)."""
    ready: npt.NDArray[np.bool_]
    """``[N]``: whether an observation has arrived in the copy's episode."""
    state: npt.NDArray[np.float32]
    """``[N, obs_dim]``: the true current states ``s_t``."""

class _Transitions(TypedDict):
    """The time-aligned transitions ``(x_τ, s_τ, a_τ, r_τ, x_{τ+1}, s_{τ+1}, terminated)``
    completed by one step, one row each (``M`` rows, possibly none)."""

    env: npt.NDArray[np.int64]
    """``[M]``: the copy."""
    episode: npt.NDArray[np.uint32]
    """``[M]``: the copy's episode counter."""
    tau: npt.NDArray[np.uint32]
    """``[M]``: the step τ within the episode."""
    augmented: npt.NDArray[np.float32]
    state: npt.NDArray[np.float32]
    action: npt.NDArray[np.float32]
    reward: npt.NDArray[np.float32]
    next_augmented: npt.NDArray[np.float32]
    next_state: npt.NDArray[np.float32]
    terminated: npt.NDArray[np.bool_]

class _Stepped(_Current):
    """Everything one ``Batch.step`` produced."""

    reward: npt.NDArray[np.float32]
    """``[N]``: the delivered rewards (those travelling with the observations)."""
    terminated: npt.NDArray[np.bool_]
    truncated: npt.NDArray[np.bool_]
    done: npt.NDArray[np.bool_]
    """``[N]``: terminated or truncated."""
    ended: bool
    """Whether any copy's episode ended in this step (``done.any()``)."""
    diverged: npt.NDArray[np.bool_]
    """``[N]``: the copy's simulation diverged (its episode ended, truncated)."""
    final_augmented: npt.NDArray[np.float32]
    """``[N, augmented_dim]``: where an episode ended, its last augmented state ``x_T`` (zeros
    where none ended, or it ended before ``x_T`` existed)."""
    final_state: npt.NDArray[np.float32]
    """``[N, obs_dim]``: where an episode ended, its last true state."""
    episode_return: npt.NDArray[np.float32]
    """``[N]``: where an episode ended, its undiscounted true return."""
    episode_length: npt.NDArray[np.uint32]
    """``[N]``: where an episode ended, its length in true steps."""
    action: npt.NDArray[np.float32]
    """``[N, act_dim]``: the actions applied (warm-up rows filled in)."""
    transitions: _Transitions

@final
class Batch:
    """N copies of one task under one delay, as the delayed agent lives in them."""

    def __new__(
        cls,
        task: str,
        num_envs: int,
        delay: int,
        action_delay: int,
        max_delay: int | None,
        actuator_noise: float,
        warmup: str,
        seed: int,
        num_threads: int,
    ) -> Batch:
        """``task``: a dhrl name (``half-cheetah``) or a Gymnasium id (``HalfCheetah-v4``);
        ``warmup``: ``"zeros"`` or ``"random"``; the other options as ``dhrl train`` takes them.
        Raises ValueError on what the library refuses."""

    @property
    def task(self) -> str: ...
    @property
    def gymnasium_id(self) -> str: ...
    @property
    def num_envs(self) -> int: ...
    @property
    def obs_dim(self) -> int: ...
    @property
    def act_dim(self) -> int: ...
    @property
    def delay(self) -> int:
        """Δ: the total delay the agent sees (a random delay counts as its bound)."""
    @property
    def augmented_dim(self) -> int:
        """``obs_dim + delay·act_dim``."""
    @property
    def num_threads(self) -> int: ...
    def workers_flush_subnormals(self) -> list[bool]:
        """Per worker thread of the copies' pool, whether it flushes subnormal floats."""
    def action_bounds(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``(low, high)`` of each action dimension."""
    def reseed(self, seed: int) -> _Current:
        """Rebuilds every copy from ``seed``: the state of a fresh ``Batch`` with that seed."""
    def set_state(self, qpos: Sequence[float], qvel: Sequence[float]) -> _Current:
        """Starts every copy's episode from ``(qpos, qvel)``, the delay layer with them."""
    def current(self) -> _Current:
        """What the agent holds now, without stepping."""
    def time_native_steps(self, actions: npt.NDArray[np.float32], steps: int) -> float:
        """Seconds ``steps`` steps of every copy take inside the library, actions cycling
        through the C-contiguous ``[K, N, act_dim]`` float32 table."""
    def step(
        self, actions: npt.NDArray[np.float32], controls: npt.NDArray[np.uint8] | None = None
    ) -> _Stepped:
        """One step of every copy. ``actions``: C-contiguous ``[N, act_dim]`` float32, all finite;
        ``controls``: ``[N]`` uint8 (0 step, 1 hold, 2 restart), every copy stepping when None."""

def raw_mj_step_rate(task: str, copies: int, env_steps: int, threads: int = 1) -> float:
    """Environment steps per second of ``copies`` copies of ``task`` stepped in turn by bare
    ``mj_step`` calls on this thread; with ``threads`` above 1, that many such loops at once on
    threads of their own, each over its share of the copies (at most one loop per copy), all
    ``env_steps`` over the last loop's time: the machine's ceiling for a batch on that many
    threads."""

def set_assets_dir(path: str) -> None:
    """Reads the task XMLs from ``path`` from now on (``import dhrl`` points it at the installed
    Gymnasium's ``envs/mujoco/assets``); the environment variable ``DHRL_ASSETS_DIR`` still wins."""

def assets_dir() -> str:
    """The folder the task XMLs are read from."""
