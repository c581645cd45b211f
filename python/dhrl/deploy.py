"""Acting under delay with a policy that ``dhrl export`` wrote, with numpy and onnxruntime only.

``DelayedPolicy(export_dir)`` reads ``policy.json`` and ``policy.onnx``. Feed it each delayed
observation as it arrives, ``observe(step, observation)`` (``step`` is the step of the state it
shows, counted from the episode's start), and call ``act()`` once per control step: for the first
Δ decisions of an episode it returns the warm-up action (the manifest's rule: zeros, or uniform
within the bounds), after that the policy's action on
``x_t = (s_{t-Δ}, a_{t-Δ}, ..., a_{t-1})``, built exactly as dhrl built it in training. Random
delays are handled as the conservative agent does: an observation that arrives early waits
until it is exactly Δ old. ``reset()`` starts a new episode.

This is the Rust runtime ``dhrl::deploy::DelayedPolicy``, step for step
(``python/tests/test_export.py`` replays the decisions ``dhrl export`` recorded with it). The one
difference is the random warm-up's stream: numpy's generator here, ChaCha8 in Rust.

The module itself imports only numpy (and onnxruntime for the ONNX network), nothing else of
dhrl: it can be copied beside a robot's controller (imported as ``dhrl.deploy`` it loads the
package, whose import loads MuJoCo for the environments).

With an action delay Δ_a (``delay.action_delay`` in the manifest), Δ is the sum of both delays
and steps count decisions: the state that has felt the actions chosen at decisions 0..k-1 is
step k (its physical step minus Δ_a), observed as such; the states before it are not observed.
"""

from __future__ import annotations

import json
import pathlib
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np

FORMAT = "dhrl-policy"
FORMAT_VERSION = 1


class DelayedPolicyError(ValueError):
    """An observation or a decision the policy's delay model rules out."""


def read_manifest(export_dir: Union[str, pathlib.Path]) -> Dict[str, Any]:
    """``policy.json`` of an export folder, checked to be a manifest this module reads."""
    path = pathlib.Path(export_dir) / "policy.json"
    manifest = json.loads(path.read_text())
    if manifest.get("format") != FORMAT or manifest.get("format_version") != FORMAT_VERSION:
        raise DelayedPolicyError(
            f"{path} is format {manifest.get('format')!r} version {manifest.get('format_version')!r}; "
            f"this module reads {FORMAT} version {FORMAT_VERSION}"
        )
    return manifest


class OnnxPolicy:
    """The exported network: rows of ``x_t`` in, deterministic actions out (onnxruntime, CPU)."""

    def __init__(self, export_dir: Union[str, pathlib.Path], manifest: Optional[Dict[str, Any]] = None):
        import onnxruntime

        self.manifest = manifest if manifest is not None else read_manifest(export_dir)
        files = self.manifest["files"]
        self.session = onnxruntime.InferenceSession(
            str(pathlib.Path(export_dir) / files["onnx"]), providers=["CPUExecutionProvider"]
        )
        self.input_name = files["onnx_input"]

    def outputs(self, augmented_states: np.ndarray) -> Dict[str, np.ndarray]:
        """Every output (``action``, ``mean``, ``log_std``) for ``[rows, width]`` inputs."""
        x = np.ascontiguousarray(augmented_states, dtype=np.float32)
        if x.ndim == 1:
            x = x[None, :]
        names = [o.name for o in self.session.get_outputs()]
        return dict(zip(names, self.session.run(names, {self.input_name: x})))

    def __call__(self, augmented_state: np.ndarray) -> np.ndarray:
        return self.outputs(augmented_state)["action"][0]


class DelayedPolicy:
    """The delay-aware runtime around an exported policy (see the module's documentation).

    ``policy`` replaces the ONNX network (any callable from ``x_t`` to an action); ``warmup``
    (``"zeros"`` or ``"random"``) replaces the manifest's warm-up rule; ``seed`` seeds a random
    warm-up.
    """

    def __init__(
        self,
        export_dir: Union[str, pathlib.Path],
        *,
        seed: int = 0,
        warmup: Optional[str] = None,
        policy: Any = None,
    ):
        self.manifest = read_manifest(export_dir)
        m = self.manifest
        self.observation_dim: int = m["observation_dim"]
        self.action_dim: int = m["action_dim"]
        self.delay: int = m["delay"]["total"]
        self.action_low = np.asarray(m["action_low"], dtype=np.float32)
        self.action_high = np.asarray(m["action_high"], dtype=np.float32)
        self.warmup: str = warmup if warmup is not None else m["warmup"]["rule"]
        if self.warmup not in ("zeros", "random"):
            raise DelayedPolicyError(f"warm-up rule {self.warmup!r}: accepted are 'zeros' and 'random'")
        self.policy = policy if policy is not None else OnnxPolicy(export_dir, m)
        self._rng = np.random.default_rng(seed)
        self.reset()

    def reset(self) -> None:
        """Starts a new episode: forgets the actions and the observations not yet used."""
        self._t = 0
        self._recent_actions: List[np.ndarray] = []
        self._waiting: Dict[int, np.ndarray] = {}

    @property
    def decision(self) -> int:
        """The index ``t`` of the next decision in this episode."""
        return self._t

    def observe(self, emitted_at: int, observation: Sequence[float]) -> None:
        """Takes the observation of the state at step ``emitted_at`` (``s_τ``), in any order."""
        if isinstance(emitted_at, (bool, np.bool_)) or not isinstance(emitted_at, (int, np.integer)) or emitted_at < 0:
            raise DelayedPolicyError(
                f"the observation's step is {emitted_at!r}; accepted is a whole number ≥ 0 (the step of the "
                "state it shows, counted from the episode's start)"
            )
        emitted_at = int(emitted_at)
        obs = np.asarray(observation, dtype=np.float32).reshape(-1)
        if obs.shape[0] != self.observation_dim:
            raise DelayedPolicyError(
                f"the observation has {obs.shape[0]} values; the policy takes {self.observation_dim} "
                "(the task's observation size)"
            )
        bad = np.flatnonzero(~np.isfinite(obs))
        if bad.size:
            raise DelayedPolicyError(
                f"the observation of step {emitted_at} holds a non-finite value at index {bad[0]}; "
                "only finite numbers are accepted"
            )
        if emitted_at > self._t:
            raise DelayedPolicyError(
                f"the observation of step {emitted_at} cannot have arrived before decision {self._t} "
                f"(observations of steps 0..={self._t} can)"
            )
        needed = emitted_at + self.delay
        if needed < self._t:
            raise DelayedPolicyError(
                f"the observation of step {emitted_at} arrived at decision {self._t}, after it was needed "
                f"(at decision {needed}): its delay is above the policy's Δ = {self.delay}"
            )
        if emitted_at in self._waiting:
            raise DelayedPolicyError(f"the observation of step {emitted_at} arrived twice")
        self._waiting[emitted_at] = obs.copy()

    @property
    def augmented_state(self) -> Optional[np.ndarray]:
        """``x_t`` for the next decision once ``s_{t-Δ}`` has arrived, else ``None``."""
        if self._t < self.delay:
            return None
        observation = self._waiting.get(self._t - self.delay)
        if observation is None:
            return None
        return np.concatenate([observation, *self._recent_actions]).astype(np.float32)

    def act(self) -> np.ndarray:
        """``a_t``: the warm-up action for ``t < Δ``, else the policy's action on ``x_t``."""
        if self._t < self.delay:
            action = self._warmup_action()
        else:
            needed = self._t - self.delay
            x = self.augmented_state
            if x is None:
                raise DelayedPolicyError(
                    f"decision {self._t} needs the observation of step {needed} (Δ = {self.delay}), which "
                    "has not arrived: observe it first (its delay may be at most Δ)"
                )
            action = np.asarray(self.policy(x), dtype=np.float32).reshape(-1)
            if action.shape[0] != self.action_dim:
                raise DelayedPolicyError(
                    f"the policy returned {action.shape[0]} values, expected {self.action_dim} (the action size)"
                )
            del self._waiting[needed]
        if self.delay > 0:
            if len(self._recent_actions) == self.delay:
                self._recent_actions.pop(0)
            self._recent_actions.append(action.copy())
        self._t += 1
        return action

    def _warmup_action(self) -> np.ndarray:
        if self.warmup == "zeros":
            return np.zeros(self.action_dim, dtype=np.float32)
        return self._rng.uniform(self.action_low, self.action_high).astype(np.float32)


__all__ = ["DelayedPolicy", "DelayedPolicyError", "OnnxPolicy", "read_manifest"]
