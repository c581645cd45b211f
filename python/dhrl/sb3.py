"""dhrl's delayed tasks as a Stable-Baselines3 ``VecEnv``.

``SAC("MlpPolicy", dhrl.sb3.make_vec("InvertedPendulum-v4", 4, delay=5))`` trains SAC on the
augmented states (augmented SAC). SB3's conventions: a copy resets in the step that ends its
episode (its last observation in ``infos[i]["terminal_observation"]``), ``dones`` is
terminated or truncated, ``infos[i]["TimeLimit.truncated"]`` marks time-limit ends (SB3's
replay buffer bootstraps them), and ``infos[i]["episode"]`` holds ``{"r", "l", "t"}`` as SB3's
``Monitor`` writes it (from the env's own statistics, which ``make_vec`` turns on), so SB3's
logger reports episode returns without another wrapper.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

try:
    from stable_baselines3.common.vec_env import VecEnv
except ImportError as e:  # pragma: no cover - depends on the environment
    raise ImportError(
        "dhrl.sb3 needs Stable-Baselines3: pip install 'stable-baselines3>=2.3' "
        "(or pip install './python[sb3]')"
    ) from e

from .vector import DelayedVectorEnv


class DhrlVecEnv(VecEnv):
    """A same-step :class:`dhrl.DelayedVectorEnv` with its own episode statistics behind SB3's
    ``VecEnv`` interface."""

    def __init__(self, env: DelayedVectorEnv):
        if env.metadata["autoreset_mode"].name != "SAME_STEP":
            raise ValueError(
                "DhrlVecEnv needs a same-step env: dhrl.make_vec(..., autoreset_mode='same_step', "
                "episode_statistics=True) (or use dhrl.sb3.make_vec)"
            )
        if not getattr(env, "episode_statistics", False):
            raise ValueError(
                "DhrlVecEnv reports each episode in SB3's Monitor form from the env's own "
                "statistics: dhrl.make_vec(..., autoreset_mode='same_step', episode_statistics=True) "
                "(or use dhrl.sb3.make_vec)"
            )
        self.env = env
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        seed = self._seeds[0] if self._seeds and self._seeds[0] is not None else None
        obs, _ = self.env.reset(seed=seed)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async(actions)")
        obs, rewards, terminated, truncated, info = self.env.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        infos: list[dict[str, Any]] = [
            {"state": info["state"][i], "ready": bool(info["ready"][i])} for i in range(self.num_envs)
        ]
        for i in np.flatnonzero(dones):
            infos[i]["terminal_observation"] = info["final_obs"][i]
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            episode = info["episode"]
            infos[i]["episode"] = {
                "r": float(episode["r"][i]),
                "l": int(episode["l"][i]),
                "t": float(episode["t"][i]),
            }
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.env.close()

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """One seed for the whole batch: the next ``reset()`` rebuilds every copy from it."""
        self._seeds = [seed] + [None] * (self.num_envs - 1)
        return self._seeds

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self.env, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        raise AttributeError(
            f"dhrl's copies share one configuration; {attr_name!r} cannot be set per copy "
            "(build a new env with dhrl.sb3.make_vec)"
        )

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        raise AttributeError(
            f"dhrl's copies are not Python environments; there is no {method_name!r} to call per copy"
        )

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False] * len(self._get_indices(indices))


def make_vec(task: str, num_envs: int, **options: Any) -> DhrlVecEnv:
    """:func:`dhrl.make_vec` with the same options, as an SB3 ``VecEnv`` (same-step reset, the
    env's own episode statistics on)."""
    if options.get("autoreset_mode", "same_step") != "same_step":
        raise ValueError("SB3 resets in the step that ends an episode: autoreset_mode must be 'same_step'")
    if options.get("episode_statistics", True) is not True:
        raise ValueError(
            "the SB3 adapter reports episodes from the env's own statistics: episode_statistics "
            "must be True (SB3's VecMonitor may still wrap it)"
        )
    options["autoreset_mode"] = "same_step"
    options["episode_statistics"] = True
    return DhrlVecEnv(DelayedVectorEnv(task, num_envs, **options))
