"""dhrl's tasks in Gymnasium's registry: ``import dhrl`` registers one id per task,
``dhrl/<Task>-delayed-v0`` (``dhrl/HalfCheetah-delayed-v0``, …), so that

    gymnasium.make_vec("dhrl/HalfCheetah-delayed-v0", num_envs=16, delay=5, seed=0)

builds :class:`dhrl.DelayedVectorEnv` (the same env as ``dhrl.make_vec("HalfCheetah-v4", 16,
delay=5, seed=0)``): every keyword is passed on to it, with the same defaults (``delay=0``).
Without importing dhrl first, name the module in the id: ``gymnasium.make_vec(
"dhrl:dhrl/HalfCheetah-delayed-v0", …)`` (Gymnasium ≥ 1.0 loads no plugin entry points).

The ids are vector-only: the copies step together in Rust, and dhrl has no single-env class,
so ``gymnasium.make`` and ``make_vec(..., vectorization_mode="sync" | "async")`` refuse them.
Gymnasium's 1000-step time limit is the env's own (counted in true steps); a
``max_episode_steps`` other than 1000 is refused rather than ignored.
"""

from __future__ import annotations

from typing import Any

from .vector import TASKS, DelayedVectorEnv

NAMESPACE = "dhrl"
VERSION = 0
TIME_LIMIT = 1000
"""True steps after which the env truncates an episode (Gymnasium's v4 ``TimeLimit``)."""


def gymnasium_id(task: str) -> str:
    """The registered id of dhrl's ``task`` (a dhrl name): ``dhrl/HalfCheetah-delayed-v0``."""
    base = TASKS[task].rsplit("-v", 1)[0]
    return f"{NAMESPACE}/{base}-delayed-v{VERSION}"


GYMNASIUM_IDS: dict[str, str] = {task: gymnasium_id(task) for task in TASKS}
"""dhrl's task names and the ids :func:`register_envs` gives them."""


def make_registered_vec(
    num_envs: int = 1, *, task: str, max_episode_steps: int | None = None, **options: Any
) -> DelayedVectorEnv:
    """The ``vector_entry_point`` of every registered id: :func:`dhrl.make_vec` of the id's
    task, ``options`` passed on."""
    if max_episode_steps is not None and max_episode_steps != TIME_LIMIT:
        raise ValueError(
            f"max_episode_steps={max_episode_steps!r}: dhrl's tasks truncate at Gymnasium's "
            f"{TIME_LIMIT}-step time limit, counted in true steps, which cannot be changed"
        )
    return DelayedVectorEnv(task, num_envs, **options)


def register_envs() -> list[str]:
    """Registers the ids of :data:`GYMNASIUM_IDS` (those not registered already); returns them."""
    import gymnasium

    for task, env_id in GYMNASIUM_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                vector_entry_point=f"{__name__}:make_registered_vec",
                kwargs={"task": task},
            )
    return list(GYMNASIUM_IDS.values())
