"""dhrl from Python: the batched, delayed Gymnasium v4 MuJoCo tasks of the dhrl Rust library.

``dhrl.make_vec(task, num_envs, delay=…)`` returns a ``gymnasium.vector.VectorEnv`` whose copies
step in parallel in Rust (the GIL released); ``dhrl.sb3.make_vec`` wraps it as a
Stable-Baselines3 ``VecEnv``. See ``dhrl.vector`` for exactly what a delayed agent receives.
Importing dhrl registers its tasks with Gymnasium (``dhrl.registration``):
``gymnasium.make_vec("dhrl/HalfCheetah-delayed-v0", num_envs=16, delay=5)`` builds the same env.
"""

from ._installed import load_libmujoco, task_assets

load_libmujoco()

from ._dhrl import MAX_DELAY, set_assets_dir  # noqa: E402 (after libmujoco is loaded)
from .registration import GYMNASIUM_IDS, register_envs  # noqa: E402
from .vector import TASKS, DelayedVectorEnv, make_vec, task_name  # noqa: E402

set_assets_dir(str(task_assets()))

register_envs()

__all__ = ["GYMNASIUM_IDS", "MAX_DELAY", "TASKS", "DelayedVectorEnv", "make_vec", "task_name"]
