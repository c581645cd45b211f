"""dhrl from Python: the batched, delayed Gymnasium v4 MuJoCo tasks of the dhrl Rust library.

``dhrl.make_vec(task, num_envs, delay=…)`` returns a ``gymnasium.vector.VectorEnv`` whose copies
step in parallel in Rust (the GIL released); ``dhrl.sb3.make_vec`` wraps it as a
Stable-Baselines3 ``VecEnv``. See ``dhrl.vector`` for exactly what a delayed agent receives.
"""

from ._dhrl import MAX_DELAY
from .vector import TASKS, DelayedVectorEnv, make_vec, task_name

__all__ = ["MAX_DELAY", "TASKS", "DelayedVectorEnv", "make_vec", "task_name"]
