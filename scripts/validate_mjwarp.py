#!/usr/bin/env python3
"""Validate dhrl's physics against MuJoCo Warp (MJWarp), which computes in float32.

Usage (from the repository root):

    PYTHONPATH=python .deps/venv/bin/python scripts/validate_mjwarp.py \\
        [--tasks all|ant,half-cheetah,...] [--states 16] [--rollout-steps 1000] [--worlds 8] \\
        [--device cpu|cuda] [--seed 0] [--json] [--out FILE.md]
        [--heavy-rollout-steps T'] [--no-cone-check] [--skip-rollout] [--kernel-cache-dir DIR]
        [--nconmax N] [--njmax N]

dhrl steps the Gymnasium v4 tasks (docs/DESIGN.md §2) with libmujoco 3.17.0 in float64; MJWarp
re-implements MuJoCo's pipeline as Warp kernels in float32, here on Warp's CPU device (or a
CUDA device). Two checks per task:

1. **One step from the same states and controls.** K states per task are drawn from the task's
   reset distribution (qpos0 + noise, qvel noise as in docs/DESIGN.md §2), each advanced a random 0..50
   steps with host ``mujoco.mj_step`` under uniform random controls (stopping before a
   terminating step; the first max(1, K//8) states are left fresh resets), so some are fresh
   resets and some are mid-episode with contacts. From each state one step with a
   uniform random control (in the actuators' ctrl ranges, the task's action bounds) is taken by
   dhrl (``dhrl.make_vec(task, 1, delay=0)``, ``set_state``, ``step``), by MJWarp (K worlds
   stepped together, ``frame_skip`` × ``mjw.step``) and by host MuJoCo C (``mujoco.mj_step``,
   the sanity row: dhrl links the same libmujoco, so it is 0 up to dhrl's float32 observation,
   which is why the host result is rounded to float32 before the comparison). Every copy starts
   its step with ``qacc_warmstart`` as a fresh ``mj_resetData`` + ``set_state`` (+ ``mj_forward``)
   leaves it (zeros), as dhrl's ``reset(seed=0)`` + ``set_state`` does. Compared: the qpos part
   and the qvel part of the observation (Hopper/Walker2d clip qvel to ±10, as their
   observations do), by the normwise relative error ‖dhrl − mjw‖∞ / max(‖mjw‖∞, 1), max and
   median over the K states.

   Contact-frame diagnostic (on by default; ``--no-cone-check`` skips it): for models with
   frictional contacts and pyramidal friction cones (all but InvertedPendulum), host MuJoCo C
   and MJWarp step the same states twice more, once with the model's pyramidal cones and once
   with both switched to elliptic cones. A pyramid's four edges follow the contact frame's
   tangent axes, an elliptic cone is isotropic: where only the pyramidal run disagrees, the two
   implementations orient the contact frame differently. That is what Ant shows: MJWarp 3.17
   aligns a plane–capsule contact's first tangent with the capsule axis only when the axis'
   projection onto the plane has norm ≥ 0.5 and uses world y otherwise, MuJoCo C always uses the
   projection, so a steep leg touching the floor gets a rotated friction pyramid (a modelling
   difference, not float32 rounding; planar models are unaffected because their frames differ
   by a quarter turn, which maps a four-edge pyramid onto itself).

2. **Rollout statistics.** W copies × T steps of uniform random actions, resetting on
   termination and at 1000 steps: dhrl through ``dhrl.make_vec(task, W, delay=0, seed=…)``;
   MJWarp with W worlds stepped together, rewards and terminations computed in numpy from its
   qpos/qvel/xpos/xipos with the v4 formulas of docs/DESIGN.md §2 (velocities from positions before and
   after the frame-skip loop over dt = timestep·frame_skip), terminated worlds re-drawn from the
   task's reset noise and written back. The trajectories are chaotic (a difference of one float32
   rounding grows to O(1) within tens to hundreds of steps), so only the *distributions* can
   agree: mean/std of the per-step reward, the number of terminations, the mean length of
   terminated episodes, and the two-sample Kolmogorov–Smirnov statistic of the per-step rewards.
   The KS statistic is descriptive only: per-step rewards within one trajectory are strongly
   autocorrelated, so the usual critical value (about 1.36·sqrt(2/(W·T)) at 5%) is far too strict.

Tolerance rationale. float32 rounds each operation with relative error ~6e-8 (2^-24). One
environment step is ``frame_skip`` (2–5) MuJoCo substeps, each a forward pass (kinematics,
composite inertia, Cholesky factorisation, RNE) and, with contacts or joint limits, an iterative
constraint solve; RK4 models (all but HalfCheetah) do four forward passes per substep. MJWarp also
raises the solver's stopping tolerance to at least 1e-6 (MuJoCo C keeps the XML's 1e-8), so where
constraints are active the two solvers stop at different iterates. Expect relative errors of
1e-6..1e-4 on smooth tasks (InvertedPendulum, HalfCheetah without contacts), larger where a
contact switches on or off within the step in one implementation but not the other (the
state-dependent contact set is discontinuous). Each task's worst state is printed with its contact
count so that such outliers can be told apart.

Features MJWarp lacks: ``put_model`` raises (e.g. Humanoid-v4's XML asks for the PGS solver,
which MJWarp does not implement); such a task is reported "not supported" with the reason, and only
the dhrl-vs-host sanity row is computed for it.

The script prints a header line (MJWarp and Warp versions, device, CPU model), then one Markdown
table per check (or, with ``--json``, one JSON object per line: a header object, then one per
task), and writes the same to ``--out`` when given. The first ``mjw.step`` of a model compiles
its kernels (or loads them from Warp's kernel cache, ``--kernel-cache-dir``): its time is
reported apart from the steady state.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pathlib
import sys
import time
from typing import Any

import numpy as np

MAX_EPISODE_STEPS = 1000
MAX_ADVANCE = 50  # a sampled state is 0..MAX_ADVANCE steps past its reset


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """One Gymnasium v4 task as docs/DESIGN.md §2 defines it."""

    name: str
    xml: str
    frame_skip: int
    qpos_skip: int  # the observation starts with qpos[qpos_skip:]
    vel_clip: float | None  # then qvel (clipped to ±vel_clip)
    noise: str  # "uniform": qpos, qvel += U(±scale); "uniform-normal": qvel = scale·N(0,1)
    noise_scale: float
    progress: str  # "none", "root-x" (qpos[0]), "body-x:<body>" (xpos), "com-x" (xipos)
    forward_weight: float
    healthy_reward: float
    ctrl_cost_weight: float


TASK_SPECS: dict[str, TaskSpec] = {
    "ant": TaskSpec("ant", "ant.xml", 5, 2, None, "uniform-normal", 0.1, "body-x:torso", 1.0, 1.0, 0.5),
    "half-cheetah": TaskSpec("half-cheetah", "half_cheetah.xml", 5, 1, None, "uniform-normal", 0.1, "root-x", 1.0, 0.0, 0.1),
    "hopper": TaskSpec("hopper", "hopper.xml", 4, 1, 10.0, "uniform", 5e-3, "root-x", 1.0, 1.0, 1e-3),
    "walker2d": TaskSpec("walker2d", "walker2d.xml", 4, 1, 10.0, "uniform", 5e-3, "root-x", 1.0, 1.0, 1e-3),
    "humanoid": TaskSpec("humanoid", "humanoid.xml", 5, 2, None, "uniform", 1e-2, "com-x", 1.25, 5.0, 0.1),
    "inverted-pendulum": TaskSpec("inverted-pendulum", "inverted_pendulum.xml", 2, 0, None, "uniform", 0.01, "none", 0.0, 1.0, 0.0),
}
TASK_ORDER = list(TASK_SPECS)


# --- the tasks, vectorised over rows (worlds) ----------------------------------------------------


def terminated(task: str, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
    """The v4 termination of ``task`` for each row of ``qpos`` [n, nq] / ``qvel`` [n, nv]."""
    qpos, qvel = np.atleast_2d(qpos), np.atleast_2d(qvel)
    finite = np.isfinite(qpos).all(axis=1) & np.isfinite(qvel).all(axis=1)
    with np.errstate(invalid="ignore"):
        if task == "ant":
            z = qpos[:, 2]
            return ~(finite & (z >= 0.2) & (z <= 1.0))
        if task == "half-cheetah":
            return np.zeros(len(qpos), bool)
        if task == "hopper":
            state = np.concatenate([qpos[:, 2:], qvel], axis=1)
            state_ok = ((state > -100) & (state < 100)).all(axis=1)
            return ~(state_ok & (qpos[:, 1] > 0.7) & (qpos[:, 2] > -0.2) & (qpos[:, 2] < 0.2))
        if task == "walker2d":
            z, angle = qpos[:, 1], qpos[:, 2]
            return ~((z > 0.8) & (z < 2.0) & (angle > -1.0) & (angle < 1.0))
        if task == "humanoid":
            z = qpos[:, 2]
            return ~((z > 1.0) & (z < 2.0))
        if task == "inverted-pendulum":
            return ~finite | (np.abs(qpos[:, 1]) > 0.2)
    raise ValueError(f"unknown task {task!r}")


def reset_noise(spec: TaskSpec, qpos0: np.ndarray, nv: int, rng: np.random.Generator, n: int):
    """``n`` states from the task's reset distribution: (qpos [n, nq], qvel [n, nv])."""
    s = spec.noise_scale
    qpos = qpos0[None, :] + rng.uniform(-s, s, (n, len(qpos0)))
    if spec.noise == "uniform":
        qvel = rng.uniform(-s, s, (n, nv))
    else:
        qvel = s * rng.standard_normal((n, nv))
    return qpos, qvel


def observed(spec: TaskSpec, qpos: np.ndarray, qvel: np.ndarray):
    """The qpos part and the qvel part of the observation, for rows of qpos / qvel."""
    vel = qvel if spec.vel_clip is None else np.clip(qvel, -spec.vel_clip, spec.vel_clip)
    return qpos[:, spec.qpos_skip:], vel


def progress_of(spec: TaskSpec, mjm, qpos: np.ndarray, xpos: np.ndarray | None, xipos: np.ndarray | None) -> np.ndarray:
    """The quantity whose change over a step is the forward velocity, per row."""
    kind = spec.progress
    if kind == "none":
        return np.zeros(len(qpos))
    if kind == "root-x":
        return qpos[:, 0].astype(np.float64)
    if kind.startswith("body-x:"):
        body = body_id(mjm, kind.split(":", 1)[1])
        return xpos[:, body, 0].astype(np.float64)
    if kind == "com-x":
        mass = mjm.body_mass
        return (xipos[:, :, 0].astype(np.float64) * mass[None, :]).sum(axis=1) / mass.sum()
    raise ValueError(kind)


def body_id(mjm, name: str) -> int:
    import mujoco

    return mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_BODY, name)


def reward_of(spec: TaskSpec, before: np.ndarray, after: np.ndarray, dt: float, actions: np.ndarray) -> np.ndarray:
    """v4 reward: forward_weight·Δprogress/dt + healthy − ctrl_cost_weight·Σa² (a unclipped)."""
    velocity = (after - before) / dt
    ctrl_cost = spec.ctrl_cost_weight * np.square(actions.astype(np.float64)).sum(axis=1)
    return spec.forward_weight * velocity + spec.healthy_reward - ctrl_cost


# --- environment ---------------------------------------------------------------------------------


def assets_dir() -> str:
    import gymnasium

    return os.path.join(os.path.dirname(gymnasium.__file__), "envs", "mujoco", "assets")


def load_model(spec: TaskSpec):
    import mujoco

    return mujoco.MjModel.from_xml_path(os.path.join(assets_dir(), spec.xml))


def check_task(task: str) -> TaskSpec:
    if task not in TASK_SPECS:
        raise ValueError(f"unknown task {task!r}; accepted: {', '.join(TASK_ORDER)}")
    return TASK_SPECS[task]


def task_seed(seed: int, task: str, stream: int) -> np.random.Generator:
    return np.random.default_rng([seed, TASK_ORDER.index(task), stream])


_warp_ready = False


def import_warp(kernel_cache_dir: str | None = None):
    """(warp, mujoco_warp), configured quiet; a clear error when mujoco_warp is missing."""
    global _warp_ready
    try:
        import warp as wp
        import mujoco_warp as mjw
    except ImportError as e:
        raise RuntimeError(
            f"MuJoCo Warp is not importable ({e}); install mujoco-warp (and warp-lang) in this "
            "environment, e.g. `.deps/venv/bin/pip install mujoco-warp`"
        ) from e
    if not _warp_ready:
        wp.config.quiet = True  # older Warp
        if hasattr(wp, "LOG_WARNING"):
            wp.config.log_level = wp.LOG_WARNING  # Warp ≥ 1.19: quiet is a log level
        if kernel_cache_dir:
            wp.config.kernel_cache_dir = kernel_cache_dir
        wp.init()
        _warp_ready = True
    return wp, mjw


def versions(device: str) -> dict[str, str]:
    import mujoco

    # The benchmarks' report helper (python/benchmarks/machine.py), shared rather than copied.
    benchmarks = str(pathlib.Path(__file__).resolve().parents[1] / "python" / "benchmarks")
    if benchmarks not in sys.path:
        sys.path.insert(0, benchmarks)
    from machine import cpu_model

    out = {"mujoco": mujoco.__version__, "device": device, "cpu": cpu_model(), "cores": str(os.cpu_count())}
    try:
        wp, mjw = import_warp()
        out["mujoco_warp"] = mjw.__version__
        out["warp"] = wp.config.version
        out["kernel_cache"] = str(wp.config.kernel_cache_dir)
    except RuntimeError:
        out["mujoco_warp"] = out["warp"] = "missing"
    return out


class NotSupported(Exception):
    """MJWarp cannot take this model (put_model raised)."""


def put_model(mjw, mjm):
    try:
        return mjw.put_model(mjm)
    except (NotImplementedError, ValueError) as e:
        raise NotSupported(f"put_model raised {type(e).__name__}: {e}") from e


# --- check 1: one step from the same states -----------------------------------------------------


def sample_states(spec: TaskSpec, mjm, k: int, rng: np.random.Generator):
    """``k`` states: reset noise, then 0..MAX_ADVANCE host steps under uniform random controls,
    stopping before a step that would terminate (the first max(1, k//8) states stay fresh
    resets). Returns qpos [k, nq], qvel [k, nv], the steps
    each was advanced, and the number of contacts in each state."""
    import mujoco

    data = mujoco.MjData(mjm)
    low, high = mjm.actuator_ctrlrange[:, 0], mjm.actuator_ctrlrange[:, 1]
    qpos0, qvel0 = reset_noise(spec, mjm.qpos0.copy(), mjm.nv, rng, k)
    qpos, qvel = np.empty_like(qpos0), np.empty_like(qvel0)
    advanced, contacts = np.zeros(k, int), np.zeros(k, int)
    for i in range(k):
        mujoco.mj_resetData(mjm, data)
        data.qpos[:], data.qvel[:] = qpos0[i], qvel0[i]
        mujoco.mj_forward(mjm, data)
        target = int(rng.integers(0, MAX_ADVANCE + 1))
        if i < max(1, k // 8):
            target = 0  # some fresh resets for certain
        for _ in range(target):
            saved_qpos, saved_qvel = data.qpos.copy(), data.qvel.copy()
            data.ctrl[:] = rng.uniform(low, high)
            for _ in range(spec.frame_skip):
                mujoco.mj_step(mjm, data)
            if terminated(spec.name, data.qpos, data.qvel)[0]:
                data.qpos[:], data.qvel[:] = saved_qpos, saved_qvel
                break
            advanced[i] += 1
        qpos[i], qvel[i] = data.qpos, data.qvel
        mujoco.mj_resetData(mjm, data)
        data.qpos[:], data.qvel[:] = qpos[i], qvel[i]
        mujoco.mj_forward(mjm, data)
        contacts[i] = data.ncon
    return qpos, qvel, advanced, contacts


def normwise(a_qpos, a_qvel, b_qpos, b_qvel) -> dict[str, np.ndarray]:
    """Per-row ‖a − b‖∞ / max(‖b‖∞, 1) for the qpos part and the qvel part."""
    out = {}
    for part, a, b in (("qpos", a_qpos, b_qpos), ("qvel", a_qvel, b_qvel)):
        a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
        diff = np.abs(a - b).max(axis=1)
        scale = np.maximum(np.abs(b).max(axis=1), 1.0)
        out[part] = diff / scale
    return out


def summary(errors: np.ndarray) -> dict[str, float]:
    return {"max": float(np.max(errors)), "median": float(np.median(errors))}


def host_one_step(spec: TaskSpec, mjm, qpos, qvel, actions):
    """One env step per state with host ``mujoco.mj_step`` (float64), each from a fresh
    ``mj_resetData`` + state + ``mj_forward``. Returns qpos, qvel after the step, the
    ``qacc_warmstart`` each step started from, and the progress before and after."""
    import mujoco

    data = mujoco.MjData(mjm)
    n = len(qpos)
    out_qpos, out_qvel, warmstart = np.empty_like(qpos), np.empty_like(qvel), np.empty_like(qvel)
    before, after = np.empty(n), np.empty(n)
    for i in range(n):
        mujoco.mj_resetData(mjm, data)
        data.qpos[:], data.qvel[:] = qpos[i], qvel[i]
        mujoco.mj_forward(mjm, data)
        warmstart[i] = data.qacc_warmstart
        before[i] = progress_of(spec, mjm, data.qpos[None], data.xpos[None], data.xipos[None])[0]
        data.ctrl[:] = actions[i].astype(np.float64)
        for _ in range(spec.frame_skip):
            mujoco.mj_step(mjm, data)
        out_qpos[i], out_qvel[i] = data.qpos, data.qvel
        after[i] = progress_of(spec, mjm, data.qpos[None], data.xpos[None], data.xipos[None])[0]
    return out_qpos, out_qvel, warmstart, before, after


def mjwarp_one_step(spec: TaskSpec, mjm, qpos, qvel, actions, warmstart, device: str,
                    nconmax: int | None = None, njmax: int | None = None) -> dict[str, Any]:
    """One env step of every state at once, one MJWarp world each (raises NotSupported)."""
    import mujoco

    wp, mjw = import_warp()
    data = mujoco.MjData(mjm)
    with wp.ScopedDevice(device):
        model = put_model(mjw, mjm)
        data.qpos[:], data.qvel[:] = qpos[0], qvel[0]
        mujoco.mj_forward(mjm, data)
        d = mjw.put_data(mjm, data, nworld=len(qpos), nconmax=nconmax, njmax=njmax)
        d.qpos.assign(qpos.astype(np.float32))
        d.qvel.assign(qvel.astype(np.float32))
        d.ctrl.assign(actions.astype(np.float32))
        d.qacc_warmstart.assign(warmstart.astype(np.float32))
        started = time.perf_counter()
        mjw.step(model, d)
        wp.synchronize()
        first_s = time.perf_counter() - started
        started = time.perf_counter()
        for _ in range(spec.frame_skip - 1):
            mjw.step(model, d)
        wp.synchronize()
        rest_s = time.perf_counter() - started
        qpos_w = d.qpos.numpy().astype(np.float64)
        return {
            "qpos": qpos_w,
            "qvel": d.qvel.numpy().astype(np.float64),
            "progress": progress_of(
                spec, mjm, qpos_w,
                d.xpos.numpy() if spec.progress.startswith("body-x") else None,
                d.xipos.numpy() if spec.progress == "com-x" else None,
            ),
            "overflow": int(np.bitwise_or.reduce(d.overflow.numpy())),
            "first_s": first_s,
            "step_ms": 1e3 * rest_s / max(spec.frame_skip - 1, 1),
        }


def cone_check(spec: TaskSpec, qpos, qvel, actions, device: str,
               nconmax: int | None = None, njmax: int | None = None) -> dict[str, Any]:
    """Host MuJoCo C (float64) vs MJWarp on the same states and controls, with the model's
    pyramidal friction cones and again with elliptic ones. A pyramid's edges depend on the
    contact frame's tangent axes, an elliptic cone does not: where only the pyramidal run
    disagrees, the two implementations orient contact frames differently (MJWarp 3.17 aligns a
    plane–capsule contact's first tangent with the capsule axis only when the axis' projection
    onto the plane has norm ≥ 0.5, and uses world y otherwise; MuJoCo C always uses the
    projection). Returns the max normwise relative error over both parts, per cone, and the
    states that disagree by more than 1e-4 under each."""
    import mujoco

    out: dict[str, Any] = {}
    for cone in (mujoco.mjtCone.mjCONE_PYRAMIDAL, mujoco.mjtCone.mjCONE_ELLIPTIC):
        mjm = load_model(spec)
        mjm.opt.cone = cone
        hq, hv, warm, _, _ = host_one_step(spec, mjm, qpos, qvel, actions)
        w = mjwarp_one_step(spec, mjm, qpos, qvel, actions, warm, device, nconmax, njmax)
        a_q, a_v = observed(spec, hq, hv)
        b_q, b_v = observed(spec, w["qpos"], w["qvel"])
        err = normwise(b_q, b_v, a_q, a_v)
        worst = np.maximum(err["qpos"], err["qvel"])
        name = "pyramidal" if cone == mujoco.mjtCone.mjCONE_PYRAMIDAL else "elliptic"
        out[name] = {"max": float(worst.max()), "states_over_1e-4": np.flatnonzero(worst > 1e-4).tolist()}
    return out


def has_pyramidal_friction(mjm) -> bool:
    """Whether the model can make frictional contacts (condim ≥ 3) with pyramidal cones."""
    import mujoco

    can_touch = ((mjm.geom_contype[:, None] & mjm.geom_conaffinity[None, :]) != 0).any()
    return bool(mjm.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL and can_touch and mjm.geom_condim.max() >= 3)


def one_step_errors(task: str, states: int = 16, device: str = "cpu", seed: int = 0,
                    nconmax: int | None = None, njmax: int | None = None,
                    with_cone_check: bool = False) -> dict[str, Any]:
    """One step of ``task`` from ``states`` sampled states: dhrl vs MJWarp and dhrl vs host
    MuJoCo C. Returns per-part (qpos, qvel) max/median normwise relative errors, per-state
    errors, timings, and ``supported=False`` with ``reason`` where MJWarp rejects the model.
    ``with_cone_check`` adds :func:`cone_check` for models with pyramidal friction cones."""
    import mujoco
    import dhrl

    spec = check_task(task)
    mjm = load_model(spec)
    rng = task_seed(seed, task, 0)
    qpos, qvel, advanced, contacts = sample_states(spec, mjm, states, rng)
    low, high = mjm.actuator_ctrlrange[:, 0], mjm.actuator_ctrlrange[:, 1]
    actions = rng.uniform(low, high, (states, mjm.nu)).astype(np.float32)

    # dhrl: a fresh batch per state (reset(seed=0)), then set_state and one step.
    started = time.perf_counter()
    env = dhrl.make_vec(task, 1, delay=0)
    bounds = (env.single_action_space.low, env.single_action_space.high)
    if not (np.allclose(bounds[0], low) and np.allclose(bounds[1], high)):
        raise AssertionError(f"{task}: dhrl's action bounds {bounds} differ from the ctrl ranges")
    dhrl_obs = np.empty((states, env.obs_dim), np.float32)
    dhrl_reward = np.empty(states)
    for i in range(states):
        env.reset(seed=0)
        env.set_state(qpos[i], qvel[i])
        _, reward, _, _, info = env.step(actions[i][None])
        dhrl_obs[i] = info["state"][0]
        dhrl_reward[i] = reward[0]
    env.close()
    dhrl_s = time.perf_counter() - started
    nq_obs = mjm.nq - spec.qpos_skip
    d_qpos, d_qvel = dhrl_obs[:, :nq_obs], dhrl_obs[:, nq_obs:nq_obs + mjm.nv]

    # host MuJoCo C (float64), rounded to float32 as dhrl's observation is.
    host_qpos, host_qvel, warmstart, before, host_after = host_one_step(spec, mjm, qpos, qvel, actions)
    dt = mjm.opt.timestep * spec.frame_skip
    # The script's own v4 reward formula (the one its MJWarp rollouts use) on the host data:
    # equal to dhrl's float32 reward up to its rounding.
    host_reward = reward_of(spec, before, host_after, dt, actions)
    h_qpos, h_qvel = observed(spec, host_qpos, host_qvel)
    host_err = normwise(d_qpos, d_qvel, h_qpos.astype(np.float32), h_qvel.astype(np.float32))

    result: dict[str, Any] = {
        "task": task,
        "gymnasium_id": dhrl.TASKS[task],
        "states": states,
        "fresh_resets": int((advanced == 0).sum()),
        "states_with_contacts": int((contacts > 0).sum()),
        "frame_skip": spec.frame_skip,
        "integrator": mujoco.mjtIntegrator(mjm.opt.integrator).name,
        "cone": mujoco.mjtCone(mjm.opt.cone).name,
        "host": {part: summary(e) for part, e in host_err.items()},
        "host_reward_abs_error": float(np.max(np.abs(dhrl_reward - host_reward))),
        "dhrl_s": round(dhrl_s, 3),
    }

    try:
        w = mjwarp_one_step(spec, mjm, qpos, qvel, actions, warmstart, device, nconmax, njmax)
    except NotSupported as e:
        result.update(supported=False, reason=str(e))
        return result
    m_qpos, m_qvel = observed(spec, w["qpos"], w["qvel"])
    err = normwise(d_qpos, d_qvel, m_qpos, m_qvel)
    worst = int(np.argmax(np.maximum(err["qpos"], err["qvel"])))
    result.update(
        supported=True,
        mjwarp={part: summary(e) for part, e in err.items()},
        mjwarp_reward_abs_error=summary(np.abs(dhrl_reward - reward_of(spec, before, w["progress"], dt, actions))),
        per_state={
            "qpos": err["qpos"].tolist(),
            "qvel": err["qvel"].tolist(),
            "advanced": advanced.tolist(),
            "contacts": contacts.tolist(),
        },
        worst_state={"index": worst, "advanced": int(advanced[worst]), "contacts": int(contacts[worst])},
        mjwarp_first_step_s=round(w["first_s"], 3),
        mjwarp_step_ms=round(w["step_ms"], 2),
        overflow=w["overflow"],
    )
    if with_cone_check and has_pyramidal_friction(mjm):
        result["cone_check"] = cone_check(spec, qpos, qvel, actions, device, nconmax, njmax)
    return result


# --- check 2: rollout statistics ----------------------------------------------------------------


def ks_statistic(a: np.ndarray, b: np.ndarray) -> float:
    """Two-sample Kolmogorov–Smirnov statistic sup_x |F_a(x) − F_b(x)|."""
    a, b = np.sort(np.asarray(a, np.float64)), np.sort(np.asarray(b, np.float64))
    if len(a) == 0 or len(b) == 0:
        return float("nan")
    points = np.concatenate([a, b])
    cdf_a = np.searchsorted(a, points, side="right") / len(a)
    cdf_b = np.searchsorted(b, points, side="right") / len(b)
    return float(np.max(np.abs(cdf_a - cdf_b)))


class _Episodes:
    """Per-step rewards and episode ends of W copies."""

    def __init__(self, worlds: int, steps: int):
        self.rewards = np.empty((steps, worlds))
        self.length = np.zeros(worlds, int)
        self.terminated_lengths: list[int] = []
        self.truncations = 0
        self.diverged = 0

    def record(self, t: int, reward, term, trunc) -> np.ndarray:
        self.rewards[t] = reward
        self.length += 1
        for i in np.flatnonzero(term):
            self.terminated_lengths.append(int(self.length[i]))
        self.truncations += int((trunc & ~term).sum())
        done = term | trunc
        self.length[done] = 0
        return done

    def stats(self) -> dict[str, Any]:
        r = self.rewards.ravel()
        lengths = self.terminated_lengths
        return {
            "reward_mean": float(r.mean()),
            "reward_std": float(r.std()),
            "terminations": len(lengths),
            "mean_terminated_length": float(np.mean(lengths)) if lengths else None,
            "truncations": self.truncations,
            "diverged": self.diverged,
        }


def dhrl_rollout(task: str, worlds: int, steps: int, seed: int) -> tuple[_Episodes, float]:
    import dhrl

    env = dhrl.make_vec(task, worlds, delay=0, seed=seed, autoreset_mode="same_step")
    env.reset(seed=seed)
    low, high = env.single_action_space.low, env.single_action_space.high
    rng = task_seed(seed, task, 1)
    episodes = _Episodes(worlds, steps)
    started = time.perf_counter()
    for t in range(steps):
        actions = rng.uniform(low, high, (worlds, len(low))).astype(np.float32)
        _, reward, term, trunc, info = env.step(actions)
        if "diverged" in info:
            episodes.diverged += int(np.sum(info["diverged"]))
        episodes.record(t, reward, np.asarray(term, bool), np.asarray(trunc, bool))
    env.close()
    return episodes, time.perf_counter() - started


def mjwarp_rollout(task: str, worlds: int, steps: int, device: str, seed: int,
                   nconmax: int | None = None, njmax: int | None = None):
    """W MJWarp worlds × ``steps`` env steps; returns (episodes, first-step s, run s, overflow)."""
    import mujoco

    spec = check_task(task)
    mjm = load_model(spec)
    wp, mjw = import_warp()
    rng = task_seed(seed, task, 2)
    low, high = mjm.actuator_ctrlrange[:, 0], mjm.actuator_ctrlrange[:, 1]
    dt = mjm.opt.timestep * spec.frame_skip
    host = mujoco.MjData(mjm)

    def host_progress(qpos_rows: np.ndarray) -> np.ndarray:
        """Progress at freshly reset states (Gymnasium's mj_forward after the reset)."""
        out = np.empty(len(qpos_rows))
        for i, q in enumerate(qpos_rows):
            host.qpos[:] = q
            mujoco.mj_kinematics(mjm, host)
            out[i] = progress_of(spec, mjm, q[None], host.xpos[None], host.xipos[None])[0]
        return out

    qpos, qvel = reset_noise(spec, mjm.qpos0.copy(), mjm.nv, rng, worlds)
    episodes = _Episodes(worlds, steps)
    with wp.ScopedDevice(device):
        model = put_model(mjw, mjm)
        mujoco.mj_resetData(mjm, host)
        host.qpos[:], host.qvel[:] = qpos[0], qvel[0]
        mujoco.mj_forward(mjm, host)
        d = mjw.put_data(mjm, host, nworld=worlds, nconmax=nconmax, njmax=njmax)
        d.qpos.assign(qpos.astype(np.float32))
        d.qvel.assign(qvel.astype(np.float32))
        d.qacc_warmstart.zero_()
        before = host_progress(qpos)
        started = time.perf_counter()
        first_s = None
        for t in range(steps):
            actions = rng.uniform(low, high, (worlds, mjm.nu)).astype(np.float32)
            d.ctrl.assign(actions)
            for _ in range(spec.frame_skip):
                mjw.step(model, d)
                if first_s is None:
                    wp.synchronize()
                    first_s = time.perf_counter() - started
                    started = time.perf_counter()
            qpos_w = d.qpos.numpy().astype(np.float64)
            qvel_w = d.qvel.numpy().astype(np.float64)
            xpos = d.xpos.numpy() if spec.progress.startswith("body-x") else None
            xipos = d.xipos.numpy() if spec.progress == "com-x" else None
            after = progress_of(spec, mjm, qpos_w, xpos, xipos)
            reward = reward_of(spec, before, after, dt, actions)
            finite = np.isfinite(qpos_w).all(axis=1) & np.isfinite(qvel_w).all(axis=1)
            term = terminated(task, qpos_w, qvel_w)
            trunc = episodes.length + 1 >= MAX_EPISODE_STEPS
            if not finite.all():  # MJWarp has no bad-state resets: count and restart
                episodes.diverged += int((~finite).sum())
                reward = np.where(finite, reward, 0.0)
                trunc = trunc | (~finite & ~term)
            done = episodes.record(t, reward, term, trunc)
            before = after
            if done.any():
                new_qpos, new_qvel = reset_noise(spec, mjm.qpos0.copy(), mjm.nv, rng, int(done.sum()))
                qpos_w[done], qvel_w[done] = new_qpos, new_qvel
                d.qpos.assign(qpos_w.astype(np.float32))
                d.qvel.assign(qvel_w.astype(np.float32))
                warm = d.qacc_warmstart.numpy()
                warm[done] = 0.0  # as mj_resetData leaves it
                d.qacc_warmstart.assign(warm)
                before[done] = host_progress(new_qpos)
        wp.synchronize()
        run_s = time.perf_counter() - started
        overflow = int(np.bitwise_or.reduce(d.overflow.numpy()))
    return episodes, first_s or 0.0, run_s, overflow


def rollout_stats(task: str, worlds: int = 8, steps: int = 1000, device: str = "cpu", seed: int = 0,
                  nconmax: int | None = None, njmax: int | None = None) -> dict[str, Any]:
    """Random-action rollouts of ``worlds`` copies × ``steps`` steps in dhrl and in MJWarp:
    per-step reward mean/std, terminations, mean terminated-episode length, KS statistic."""
    spec = check_task(task)
    result: dict[str, Any] = {"task": task, "worlds": worlds, "steps": steps}
    ours, dhrl_s = dhrl_rollout(task, worlds, steps, seed)
    result["dhrl"] = ours.stats()
    result["dhrl_s"] = round(dhrl_s, 3)
    try:
        theirs, first_s, run_s, overflow = mjwarp_rollout(task, worlds, steps, device, seed, nconmax, njmax)
    except NotSupported as e:
        result.update(supported=False, reason=str(e))
        return result
    result.update(
        supported=True,
        mjwarp=theirs.stats(),
        ks=ks_statistic(ours.rewards.ravel(), theirs.rewards.ravel()),
        mjwarp_first_step_s=round(first_s, 3),
        mjwarp_s=round(run_s, 3),
        mjwarp_step_ms=round(1e3 * run_s / max(steps * spec.frame_skip - 1, 1), 2),
        overflow=overflow,
    )
    return result


# --- output --------------------------------------------------------------------------------------


def _g(x: Any, digits: int = 3) -> str:
    if x is None:
        return "–"
    if isinstance(x, float):
        if x != x:
            return "nan"
        if x == 0:
            return "0"
        if abs(x) < 1e-3 or abs(x) >= 1e5:
            return f"{x:.{digits - 1}e}"
        return f"{x:.{digits}g}"
    return str(x)


def header_line(info: dict[str, str]) -> str:
    return (
        f"MJWarp {info['mujoco_warp']} on Warp {info['warp']}, device `{info['device']}`, "
        f"CPU {info['cpu']} ({info['cores']} cores), MuJoCo C {info['mujoco']} (host and dhrl)"
    )


def _rollout_table(roll: list[dict]) -> list[str]:
    lines: list[str] = []
    lines += [
        "",
        "## Rollout statistics (random actions)",
        "",
        "The trajectories are chaotic: one float32 rounding difference grows to O(1) within tens to "
        "hundreds of steps, so dhrl and MJWarp trajectories part and only the distributions can agree. "
        "W copies × T steps of uniform random actions, reset on termination and at 1000 steps. KS: "
        "two-sample Kolmogorov–Smirnov statistic of the per-step rewards (descriptive; rewards within a "
        "trajectory are autocorrelated, so the textbook critical value is far too strict).",
        "",
        "| task | W × T | reward mean dhrl | MJWarp | reward std dhrl | MJWarp | terminations dhrl | MJWarp | "
        "mean terminated length dhrl | MJWarp | KS | MJWarp first step s | MJWarp run s (mjw.step ms) | dhrl s | wall s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in roll:
        o = r["dhrl"]
        head = f"| {r['task']} | {r['worlds']} × {r['steps']} | "
        if not r.get("supported"):
            lines.append(
                head + f"{_g(o['reward_mean'])} | not supported | {_g(o['reward_std'])} | | "
                f"{o['terminations']} | | {_g(o['mean_terminated_length'])} | | | | | {r['dhrl_s']:.2f} | {_g(r.get('wall_s'))} |"
            )
            continue
        t = r["mjwarp"]
        lines.append(
            head + f"{_g(o['reward_mean'])} | {_g(t['reward_mean'])} | {_g(o['reward_std'])} | {_g(t['reward_std'])} | "
            f"{o['terminations']} | {t['terminations']} | {_g(o['mean_terminated_length'])} | "
            f"{_g(t['mean_terminated_length'])} | {_g(r['ks'])} | {r['mjwarp_first_step_s']:.1f} | "
            f"{r['mjwarp_s']:.1f} ({r['mjwarp_step_ms']:.1f}) | {r['dhrl_s']:.2f} | {_g(r.get('wall_s'))} |"
        )
    return lines


def markdown(info: dict[str, str], one: list[dict], roll: list[dict], args) -> str:
    lines = ["# dhrl vs MuJoCo Warp (float32)", "", header_line(info), ""]
    if args is not None:
        lines += [f"Command: `{' '.join(sys.argv)}` (seed {args.seed}); Warp kernel cache `{info.get('kernel_cache')}`.", ""]
    lines += [
        "Tolerance rationale: float32 rounds each operation with relative error ~6e-8; one env step is "
        "frame_skip substeps (RK4: four forward passes each) through the constraint solver, whose stopping "
        "tolerance MJWarp raises to ≥ 1e-6 (MuJoCo C: 1e-8). Expect 1e-6..1e-4 on smooth tasks and larger "
        "errors where a contact switches on or off within the step in one implementation only.",
        "",
        "## One step from the same states and controls",
        "",
        "Normwise relative error ‖dhrl − other‖∞ / max(‖other‖∞, 1) of the observation's qpos and qvel "
        "parts after one step (frame_skip substeps), max and median over the states. The host columns "
        "are dhrl vs `mujoco.mj_step` (same libmujoco, compared at dhrl's float32 observation). Reward "
        "|Δ|: dhrl's reward of the step vs the v4 formula computed from the other's qpos/xpos/xipos "
        "(the formula the MJWarp rollouts use; the host column checks the formula itself). "
        "C vs MJWarp: host MuJoCo C (float64) against MJWarp on the same states and controls, once "
        "with the model's pyramidal friction cones and once with elliptic ones (both sides switched), "
        "with the states whose error exceeds 1e-4; – where the model has no frictional contacts.",
        "",
        "| task | integrator × frame_skip | states (fresh / with contacts) | MJWarp qpos max | median | "
        "MJWarp qvel max | median | worst state (steps advanced, contacts) | MJWarp reward abs max | "
        "C vs MJWarp max, pyramidal / elliptic cones | "
        "host qpos max | host qvel max | host reward abs max | first mjw.step s | mjw.step ms | wall s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in one:
        host = (f"{_g(r['host']['qpos']['max'])} | {_g(r['host']['qvel']['max'])} | "
                f"{_g(r['host_reward_abs_error'])}")
        head = f"| {r['task']} | {r['integrator'].removeprefix('mjINT_')} × {r['frame_skip']} | " \
               f"{r['states']} ({r['fresh_resets']} / {r['states_with_contacts']}) | "
        if not r.get("supported"):
            lines.append(head + f"not supported: {r['reason']} | | | | | | | {host} | | | {_g(r.get('wall_s'))} |")
            continue
        w = r["mjwarp"]
        ws = r["worst_state"]
        cc = r.get("cone_check")
        cone = "–" if cc is None else (
            f"{_g(cc['pyramidal']['max'])} (states {cc['pyramidal']['states_over_1e-4'] or '–'}) / "
            f"{_g(cc['elliptic']['max'])} (states {cc['elliptic']['states_over_1e-4'] or '–'})"
        )
        lines.append(
            head + f"{_g(w['qpos']['max'])} | {_g(w['qpos']['median'])} | {_g(w['qvel']['max'])} | "
            f"{_g(w['qvel']['median'])} | #{ws['index']} ({ws['advanced']}, {ws['contacts']}) | "
            f"{_g(r['mjwarp_reward_abs_error']['max'])} | {cone} | {host} | "
            f"{r['mjwarp_first_step_s']:.1f} | {r['mjwarp_step_ms']:.1f} | {_g(r.get('wall_s'))} |"
        )
    if roll:
        lines += _rollout_table(roll)
    notes = []
    for r in one + roll:
        if r.get("overflow"):
            notes.append(f"- {r['task']}: MJWarp reported overflow bits {r['overflow']:#x} (raise --nconmax/--njmax)")
        for side in ("dhrl", "mjwarp"):
            if isinstance(r.get(side), dict) and r[side].get("diverged"):
                notes.append(f"- {r['task']}: {side} diverged {r[side]['diverged']} times")
    unsupported = sorted({r["task"] + ": " + r["reason"] for r in one + roll if r.get("supported") is False})
    if unsupported:
        notes.append("- Not supported by MJWarp: " + "; ".join(unsupported))
    if notes:
        lines += ["", "Notes:", "", *notes]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", default="all", help="'all' or comma-separated dhrl task names")
    parser.add_argument("--states", type=int, default=16, help="states for the one-step check (K)")
    parser.add_argument("--rollout-steps", type=int, default=1000, help="env steps per copy (T)")
    parser.add_argument("--heavy-rollout-steps", type=int, default=None,
                        help="T for the heavy tasks (ant, hopper, walker2d, humanoid) instead of --rollout-steps")
    parser.add_argument("--worlds", type=int, default=8, help="copies in the rollout check (W)")
    parser.add_argument("--device", default="cpu", help="Warp device: cpu or cuda (cuda:N)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--nconmax", type=int, default=None, help="MJWarp contacts per world (default: its heuristic)")
    parser.add_argument("--njmax", type=int, default=None, help="MJWarp constraint rows per world (default: its heuristic)")
    parser.add_argument("--kernel-cache-dir", default=None, help="Warp kernel cache (default: Warp's)")
    parser.add_argument("--skip-rollout", action="store_true", help="only the one-step check")
    parser.add_argument("--no-cone-check", action="store_true",
                        help="skip the host-C-vs-MJWarp rerun with elliptic friction cones")
    parser.add_argument("--json", action="store_true", help="JSON lines: a header object, then one per task")
    parser.add_argument("--out", default=None, help="also write the output to this file")
    args = parser.parse_args(argv)

    tasks = TASK_ORDER if args.tasks == "all" else [t.strip() for t in args.tasks.split(",") if t.strip()]
    for task in tasks:
        check_task(task)
    for name in ("states", "rollout_steps", "worlds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be ≥ 1")
    wp, _ = import_warp(args.kernel_cache_dir)
    try:
        wp.get_device(args.device)
    except Exception as e:
        parser.error(f"Warp device {args.device!r} is not available: {e}")
    info = versions(args.device)
    print(header_line(info), file=sys.stderr, flush=True)

    one, roll = [], []
    for task in tasks:
        started = time.perf_counter()
        r1 = one_step_errors(task, args.states, args.device, args.seed, args.nconmax, args.njmax,
                             with_cone_check=not args.no_cone_check)
        r1["wall_s"] = round(time.perf_counter() - started, 2)
        one.append(r1)
        print(f"{task}: one-step done in {r1['wall_s']:.1f} s", file=sys.stderr, flush=True)
        if args.skip_rollout:
            continue
        steps = args.rollout_steps
        if args.heavy_rollout_steps and task in ("ant", "hopper", "walker2d", "humanoid"):
            steps = args.heavy_rollout_steps
        started = time.perf_counter()
        r2 = rollout_stats(task, args.worlds, steps, args.device, args.seed, args.nconmax, args.njmax)
        r2["wall_s"] = round(time.perf_counter() - started, 2)
        roll.append(r2)
        print(f"{task}: rollout done in {r2['wall_s']:.1f} s", file=sys.stderr, flush=True)

    if args.json:
        rows = [json.dumps({"kind": "header", **info})]
        by_task = {r["task"]: r for r in roll}
        for r in one:
            rows.append(json.dumps({"kind": "task", "task": r["task"], "one_step": r, "rollout": by_task.get(r["task"])}))
        text = "\n".join(rows) + "\n"
    else:
        text = markdown(info, one, roll, args)
    sys.stdout.write(text)
    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with open(args.out, "w") as f:
            f.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
