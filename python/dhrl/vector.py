"""`make_vec`: dhrl's batched delayed MuJoCo tasks as a ``gymnasium.vector.VectorEnv``.

What the agent receives (the delay layer of the Rust library, the path ``dhrl train`` runs):

* **Observations** are the augmented states ``x_t = (s_{t-Δ}, a_{t-Δ}, …, a_{t-1})``, one
  float32 array ``[num_envs, obs_dim + Δ·act_dim]``; Δ is ``delay + action_delay`` (a random
  delay counts as its bound ``max_delay``). For ``t < Δ`` no observation has arrived yet:
  ``x_t`` is all zeros, ``info["ready"]`` is False, and the env executes warm-up actions
  (``warmup``: zeros, or uniform random in the bounds) in place of the given ones
  (``info["action"]`` holds what was applied).
* **Rewards** travel with the observations: the reward of step ``t`` is the reward of the true
  step that produced ``s_{t-Δ}`` (0 for ``t ≤ Δ``). When an episode ends, the observations
  still in flight are delivered at once, and so are their rewards: the step that ends an
  episode returns their sum. The rewards of an episode therefore add up to its true return.
* **terminated / truncated** are the true flags of this step (the end of an episode is not
  delayed: everything still in flight arrives with it). Truncation is Gymnasium's 1000-step
  ``TimeLimit``, counted in true steps.
* ``info["state"]``: the true current states ``s_t`` ``[num_envs, obs_dim]``, of the same
  moment as the observation; ``info["transitions"]``: the time-aligned transitions
  ``(x_τ, s_τ, a_τ, r_τ, x_{τ+1}, s_{τ+1}, terminated)`` completed at this step, as arrays
  (``env`` and ``tau`` say whose and which step), ready for a replay buffer.
* **Episode statistics** are left to Gymnasium's ``gymnasium.wrappers.vector.RecordEpisodeStatistics``
  (the delivered rewards add up to the true return and every step of an episode is one call, so
  its ``r`` and ``l`` are the true return and length). With ``episode_statistics=True`` the env
  writes them itself, in that wrapper's form: ``info["episode"]`` / ``info["_episode"]`` (true
  return, true length, seconds) where an episode ended; that key then collides with the
  wrapper's, so use one or the other.

Autoreset: ``"next_step"`` (Gymnasium's default: the step after the end returns the first
observation of the next episode, reward 0 and no flags, ignoring that copy's action),
``"same_step"`` (the end step already returns the next episode's first observation;
``info["final_obs"]`` / ``info["final_observation"]`` and ``info["final_info"]`` carry the
finished one's), or ``"disabled"`` (a finished copy waits for ``reset(options={"reset_mask":
…})``).
"""

from __future__ import annotations

import math
import numbers
import os
import time
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv

from . import _dhrl

TASKS: dict[str, str] = dict(_dhrl.TASKS)
"""dhrl's task names and the Gymnasium ids they reproduce."""
_BY_GYM_ID = {gym_id: name for name, gym_id in TASKS.items()}

_STEP, _HOLD, _RESTART = 0, 1, 2
_MODES = {
    "next_step": AutoresetMode.NEXT_STEP,
    "same_step": AutoresetMode.SAME_STEP,
    "disabled": AutoresetMode.DISABLED,
}


def task_name(task: Any) -> str:
    """dhrl's name of ``task`` (a dhrl name or a Gymnasium id), or a ValueError."""
    if isinstance(task, str):
        if task in TASKS:
            return task
        if task in _BY_GYM_ID:
            return _BY_GYM_ID[task]
    accepted = ", ".join(f"{name!r} / {gym_id!r}" for name, gym_id in TASKS.items())
    raise ValueError(f"unknown task {task!r}; accepted: {accepted}")


def _integer(name: str, value: Any, minimum: int, kind: str = "an integer") -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be {kind} ≥ {minimum}; got {value!r} ({type(value).__name__})")
    if value < minimum:
        raise ValueError(f"{name} must be ≥ {minimum}; got {value}")
    return int(value)


def _optional_integer(name: str, value: Any, minimum: int) -> int | None:
    return None if value is None else _integer(name, value, minimum, "an integer or None")


def _nonnegative_real(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number ≥ 0; got {value!r}")
    number = float(value)
    if not (math.isfinite(number) and number >= 0):
        raise ValueError(f"{name} must be a finite number ≥ 0; got {value}")
    return number


def _autoreset_mode(value: Any) -> AutoresetMode:
    if isinstance(value, AutoresetMode):
        return value
    if isinstance(value, str):
        key = value.lower().replace("-", "_")
        if key in _MODES:
            return _MODES[key]
        for mode in _MODES.values():
            if value == mode.value:
                return mode
    raise ValueError(
        f"autoreset_mode {value!r}; accepted: 'next_step', 'same_step', 'disabled' "
        "or a gymnasium.vector.AutoresetMode"
    )


class DelayedVectorEnv(VectorEnv):
    """``num_envs`` copies of a Gymnasium v4 MuJoCo task under one delay (see the module for
    what the agent receives), stepped in parallel on ``num_threads`` threads (default: one per
    core, at most one per copy).

    ``delay``: steps before an observation (with its reward) reaches the agent;
    ``action_delay``: steps before an action is executed; ``max_delay``: random observation
    delays in ``1..max_delay`` instead of a fixed one (the agent holds each observation until it
    is ``max_delay`` old); ``actuator_noise``: σ of Gaussian noise on the executed action,
    clipped to the bounds; ``warmup``: what runs before the first observation arrives
    (``"zeros"`` or ``"random"``); ``episode_statistics``: write ``info["episode"]`` itself
    (off by default: wrap the env in Gymnasium's ``RecordEpisodeStatistics`` instead, which
    needs that key free). Copy ``i`` draws from stream ``i`` of ``seed``.
    """

    def __init__(
        self,
        task: str,
        num_envs: int,
        delay: int = 0,
        action_delay: int = 0,
        max_delay: int | None = None,
        actuator_noise: float = 0.0,
        warmup: str = "zeros",
        seed: int = 0,
        num_threads: int | None = None,
        autoreset_mode: str | AutoresetMode = "next_step",
        episode_statistics: bool = False,
    ) -> None:
        name = task_name(task)
        num_envs = _integer("num_envs", num_envs, 1)
        delay = _integer("delay", delay, 0)
        action_delay = _integer("action_delay", action_delay, 0)
        max_delay = _optional_integer("max_delay", max_delay, 1)
        if max_delay is not None and delay != 0:
            raise ValueError(
                f"delay={delay} with max_delay={max_delay}: max_delay turns on random observation "
                "delays in 1..max_delay, which replace the fixed one; give one of them"
            )
        actuator_noise = _nonnegative_real("actuator_noise", actuator_noise)
        if warmup not in ("zeros", "random"):
            raise ValueError(f"warmup {warmup!r}; accepted: 'zeros' or 'random'")
        seed = _integer("seed", seed, 0)
        if num_threads is None:
            num_threads = max(1, min(num_envs, os.cpu_count() or 1))
        num_threads = _integer("num_threads", num_threads, 1)
        self.autoreset_mode = _autoreset_mode(autoreset_mode)
        if not isinstance(episode_statistics, (bool, np.bool_)):
            raise TypeError(f"episode_statistics must be True or False; got {episode_statistics!r}")
        self.episode_statistics = bool(episode_statistics)

        self._batch = _dhrl.Batch(
            name, num_envs, delay, action_delay, max_delay, actuator_noise, warmup, seed,
            num_threads,
        )
        self.task = name
        self.gymnasium_id = TASKS[name]
        self.delay = self._batch.delay
        self.num_envs = num_envs
        self.num_threads = num_threads
        self.obs_dim = self._batch.obs_dim
        self.act_dim = self._batch.act_dim
        low, high = self._batch.action_bounds()
        self.single_action_space = spaces.Box(
            low.astype(np.float32), high.astype(np.float32), dtype=np.float32
        )
        obs_low = np.concatenate(
            [np.full(self.obs_dim, -np.inf, np.float32), np.tile(low, self.delay).astype(np.float32)]
        )
        obs_high = np.concatenate(
            [np.full(self.obs_dim, np.inf, np.float32), np.tile(high, self.delay).astype(np.float32)]
        )
        self.single_observation_space = spaces.Box(obs_low, obs_high, dtype=np.float32)
        self.action_space = spaces.Box(
            np.tile(self.single_action_space.low, (num_envs, 1)),
            np.tile(self.single_action_space.high, (num_envs, 1)),
            dtype=np.float32,
        )
        self.observation_space = spaces.Box(
            np.tile(obs_low, (num_envs, 1)), np.tile(obs_high, (num_envs, 1)), dtype=np.float32
        )
        self.metadata = {"autoreset_mode": self.autoreset_mode, "render_modes": []}
        self.render_mode = None
        self.config = {
            "task": name,
            "delay": delay,
            "action_delay": action_delay,
            "max_delay": max_delay,
            "actuator_noise": actuator_noise,
            "warmup": warmup,
            "episode_statistics": self.episode_statistics,
        }
        self._seeded_at_build = True
        # Copies whose episode ended in the last step (next-step / disabled modes).
        self._ended = np.zeros(num_envs, dtype=bool)
        self._show(
            np.zeros((num_envs, self._batch.augmented_dim), np.float32),
            np.zeros((num_envs, self.obs_dim), np.float32),
            np.zeros(num_envs, bool),
        )
        self._episode_started = np.full(num_envs, time.perf_counter())

    # --- Gymnasium's interface ------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Starts new episodes: every copy's (from ``seed`` when given: the whole batch is
        rebuilt from it, as a new env with that seed would be), or, with
        ``options={"reset_mask": mask}``, only the copies where the ``[num_envs]`` bool mask is
        True (from their own random streams; the others keep their episodes and observations)."""
        mask = None
        if options is not None:
            if not isinstance(options, dict):
                raise TypeError(f"options must be a dict or None; got {type(options).__name__}")
            unknown = set(options) - {"reset_mask"}
            if unknown:
                raise ValueError(f"unknown reset options {sorted(unknown)}; accepted: 'reset_mask'")
            if "reset_mask" in options:
                mask = self._reset_mask(options["reset_mask"])
        if seed is not None:
            if isinstance(seed, (list, tuple, np.ndarray)):
                raise TypeError(
                    "seed must be one integer for the whole batch (copy i draws from stream i "
                    f"of it); got {type(seed).__name__}"
                )
            seed = _integer("seed", seed, 0)
            if mask is not None and not mask.all():
                raise ValueError(
                    "seed rebuilds the whole batch; a partial reset_mask restarts copies from "
                    "their own streams: give one or the other"
                )
        now = time.perf_counter()
        if seed is not None:
            out = self._batch.reseed(seed)
            self._ended[:] = False
            self._episode_started[:] = now
        elif mask is None and self._seeded_at_build:
            out = self._batch.current()
        else:
            restart = np.ones(self.num_envs, bool) if mask is None else mask
            # A copy whose episode ended has already begun its next one: it is only held.
            controls = np.where(restart & ~self._ended, _RESTART, _HOLD).astype(np.uint8)
            out = self._batch.step(np.zeros((self.num_envs, self.act_dim), np.float32), controls)
            self._ended[restart] = False
            self._episode_started[restart] = now
            if mask is not None:
                keep = ~mask
                out["augmented"][keep] = self._obs[keep]
                out["state"][keep] = self._state[keep]
                out["ready"][keep] = self._ready[keep]
        self._seeded_at_build = False
        return self._show(out["augmented"], out["state"], out["ready"])

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        actions = self._check_actions(actions)
        mode = self.autoreset_mode
        if mode == AutoresetMode.DISABLED and self._ended.any():
            raise ValueError(
                f"copies {np.flatnonzero(self._ended).tolist()} ended their episodes; with "
                "autoreset_mode='disabled' reset them first: reset(options={'reset_mask': mask})"
            )
        if mode == AutoresetMode.NEXT_STEP and self._ended.any():
            # A finished copy already began its next episode: this step only shows it.
            controls = np.where(self._ended, _HOLD, _STEP).astype(np.uint8)
        else:
            controls = None
        # The extension rejects non-finite actions before it steps anything. `done` and
        # `ended` come from it too: after a step the interpreter's caches are cold (the
        # simulation threads ran on every core), and each numpy call here costs ~10 µs.
        out = self._batch.step(actions, controls)
        self._seeded_at_build = False
        terminated, truncated, done, ended = out["terminated"], out["truncated"], out["done"], out["ended"]
        obs, state = out["augmented"], out["state"]
        info: dict[str, Any] = {
            "ready": out["ready"],
            "action": out["action"],
            "transitions": out["transitions"],
        }
        now = time.perf_counter()
        if ended:
            if self.episode_statistics:
                info["episode"] = {
                    "r": np.where(done, out["episode_return"], 0.0).astype(np.float32),
                    "l": np.where(done, out["episode_length"], 0).astype(np.int64),
                    "t": np.where(done, np.round(now - self._episode_started, 6), 0.0),
                }
                info["_episode"] = done
            if out["diverged"].any():
                info["diverged"] = out["diverged"]
        if mode == AutoresetMode.SAME_STEP:
            if ended:
                final_obs = np.full(self.num_envs, None, dtype=object)
                for i in np.flatnonzero(done):
                    final_obs[i] = out["final_augmented"][i]
                info["final_obs"] = final_obs
                info["_final_obs"] = done
                info["final_observation"] = final_obs
                info["_final_observation"] = done
                info["final_info"] = {
                    "state": np.where(done[:, None], out["final_state"], 0.0).astype(np.float32),
                    "_state": done,
                    "ready": done & (out["episode_length"] >= self.delay),
                    "_ready": done,
                }
                if self.episode_statistics:
                    info["final_info"]["episode"] = info["episode"]
                    info["final_info"]["_episode"] = done
        elif ended:
            # Next-step and disabled: this step shows the finished episode's last moment.
            obs = obs.copy()
            obs[done] = out["final_augmented"][done]
            state = state.copy()
            state[done] = out["final_state"][done]
            info["ready"] = info["ready"].copy()
            info["ready"][done] = out["episode_length"][done] >= self.delay
        if ended:
            self._episode_started[done] = now
        self._ended = done
        self._show(obs, state, info["ready"])
        info["state"] = state
        return obs, out["reward"], terminated, truncated, info

    def set_state(self, qpos: Any, qvel: Any) -> tuple[np.ndarray, dict[str, Any]]:
        """Starts every copy's episode from ``(qpos, qvel)`` (Gymnasium's ``set_state``), the
        delay layer with them; returns the observations and info of that moment."""
        out = self._batch.set_state(
            np.asarray(qpos, np.float64).ravel().tolist(), np.asarray(qvel, np.float64).ravel().tolist()
        )
        self._ended[:] = False
        self._seeded_at_build = False
        return self._show(out["augmented"], out["state"], out["ready"])

    def _show(self, obs: np.ndarray, state: np.ndarray, ready: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
        """Remembers what the agent is shown (a partial reset keeps it for the other copies)."""
        self._obs, self._state, self._ready = obs, state, ready
        return obs, {"state": state, "ready": ready}

    def close_extras(self, **kwargs: Any) -> None:
        del self._batch  # frees the copies now

    def __repr__(self) -> str:
        options = ", ".join(f"{k}={v!r}" for k, v in self.config.items() if k != "task")
        return f"DelayedVectorEnv({self.task!r}, num_envs={self.num_envs}, {options})"

    # --- input checks -------------------------------------------------------------------

    def _check_actions(self, actions: Any) -> np.ndarray:
        """``actions`` as the C-contiguous float32 ``[N, act_dim]`` array the extension takes
        (which checks that every value is finite)."""
        expected = (self.num_envs, self.act_dim)
        if (
            type(actions) is np.ndarray
            and actions.dtype == np.float32
            and actions.shape == expected
            and actions.flags.c_contiguous
        ):
            return actions
        try:
            array = np.asarray(actions)
        except Exception as e:  # ragged lists and the like
            raise TypeError(f"actions must be an array of shape {expected}; got {type(actions).__name__}: {e}") from e
        if array.dtype.kind not in "fiu":
            raise TypeError(
                f"actions must be a numeric array (float32 preferred) of shape {expected}; "
                f"got dtype {array.dtype}"
            )
        if array.shape != expected:
            raise ValueError(
                f"actions have shape {array.shape}; expected {expected} "
                f"({self.num_envs} copies × {self.act_dim} action dimensions of {self.gymnasium_id})"
            )
        return np.ascontiguousarray(array, dtype=np.float32)

    def _reset_mask(self, mask: Any) -> np.ndarray:
        array = np.asarray(mask)
        if array.dtype != np.bool_:
            raise TypeError(f"reset_mask must be a bool array of shape ({self.num_envs},); got dtype {array.dtype}")
        if array.shape != (self.num_envs,):
            raise ValueError(f"reset_mask has shape {array.shape}; expected ({self.num_envs},)")
        if not array.any():
            raise ValueError("reset_mask selects no copy; it needs at least one True")
        return array.copy()


def make_vec(task: str, num_envs: int, **options: Any) -> DelayedVectorEnv:
    """``num_envs`` copies of ``task`` (``"half-cheetah"`` or ``"HalfCheetah-v4"``) as the
    delayed agent lives in them: a :class:`DelayedVectorEnv`, whose options it takes
    (``delay=0, action_delay=0, max_delay=None, actuator_noise=0.0, warmup="zeros", seed=0,
    num_threads=None, autoreset_mode="next_step", episode_statistics=False``)."""
    return DelayedVectorEnv(task, num_envs, **options)
