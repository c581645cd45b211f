"""dhrl's physics against MuJoCo Warp (MJWarp, float32 on Warp's CPU device), through the
functions of scripts/validate_mjwarp.py, on InvertedPendulum and HalfCheetah.

MJWarp is a required test dependency: without `mujoco_warp` these tests fail with a message
saying so; set DHRL_SKIP_MJWARP=1 to skip them knowingly.

Tolerances (measured on the 2-core Intel Xeon development VM, MJWarp 3.17.0 / Warp 1.19.0, CPU):

* One step, normwise relative error ‖dhrl − mjw‖∞ / max(‖mjw‖∞, 1), worst over 5 seeds × 8
  states and 5 seeds × 64 states: InvertedPendulum 3.6e-7 (qvel; qpos 3.0e-8), HalfCheetah
  6.6e-5 (qvel, a state with a foot contact; qpos 6.1e-6). The bounds are 10× these. The test
  itself (seed 0, 8 states) sees 2.4e-7 and 4.7e-6. dhrl vs host MuJoCo C (the same libmujoco)
  is exactly 0 at dhrl's float32 observation; the bound is 1e-12.
* Reward of that step from MJWarp's state with the script's v4 formula: worst 7.5e-6 absolute
  (HalfCheetah; InvertedPendulum's reward is 1); bound 1e-4. The same formula on host MuJoCo's
  state equals dhrl's float32 reward up to its rounding (≤ 3e-8 seen; bound 1e-6).
* Rollouts, 4 copies × 150 random-action steps, independent random streams for dhrl and MJWarp
  (the trajectories are chaotic, only distributions can agree). dhrl alone over 100 seeds:
  HalfCheetah's per-step reward mean has sd 0.094 between seeds, so the difference of two
  independent means has sd 0.133: bound 0.5 (3.8 sd); its per-step reward std is 0.670 ± 0.039,
  so the ratio of two has a log-sd of 0.083: bounds 0.7..1.4 (about 4 sd). InvertedPendulum (reward 1 per step):
  terminations 97.7 ± 6.1 and mean terminated length 6.02 ± 0.38 between seeds: bounds on the
  difference 35 and 2.2 (4 sd of a difference, 4·√2·sd).

Time: after kernel compilation the four tests take about 15 s on the 2-core VM; a cold Warp
kernel cache adds the compilation, measured ~35 s for the two models together (see the report in
docs/results/mjwarp-validation.md).
"""

import os
import pathlib
import sys

import pytest

SCRIPTS = pathlib.Path(__file__).resolve().parents[2] / "scripts"
sys.path.insert(0, str(SCRIPTS))

SKIP = os.environ.get("DHRL_SKIP_MJWARP", "").strip() == "1"
pytestmark = pytest.mark.skipif(SKIP, reason="DHRL_SKIP_MJWARP=1: MJWarp validation skipped knowingly")

DEVICE = "cpu"
STATES = 8
SEED = 0
ONE_STEP_TOLERANCE = {"inverted-pendulum": 4e-6, "half-cheetah": 7e-4}
REWARD_TOLERANCE = 1e-4
HOST_TOLERANCE = 1e-12
HOST_REWARD_TOLERANCE = 1e-6
WORLDS, STEPS = 4, 150
HALF_CHEETAH_MEAN_TOLERANCE = 0.5
HALF_CHEETAH_STD_RATIO = (0.7, 1.4)
PENDULUM_TERMINATIONS_TOLERANCE = 35
PENDULUM_LENGTH_TOLERANCE = 2.2


@pytest.fixture(scope="module")
def vm():
    """The script's module, after checking that MJWarp is importable (a failure otherwise)."""
    try:
        import mujoco_warp  # noqa: F401
        import warp  # noqa: F401
    except ImportError as e:
        pytest.fail(
            f"mujoco_warp is not importable ({e}): install mujoco-warp and warp-lang in this venv "
            "(`.deps/venv/bin/pip install mujoco-warp`), or set DHRL_SKIP_MJWARP=1 to skip the "
            "MJWarp validation knowingly",
            pytrace=False,
        )
    import validate_mjwarp

    return validate_mjwarp


@pytest.mark.parametrize("task", ["inverted-pendulum", "half-cheetah"])
def test_one_step_matches_mjwarp(vm, task):
    r = vm.one_step_errors(task, STATES, DEVICE, SEED)
    assert r["supported"], r.get("reason")
    assert r["overflow"] == 0, f"MJWarp overflow bits {r['overflow']:#x}"
    for part in ("qpos", "qvel"):
        assert r["host"][part]["max"] <= HOST_TOLERANCE, f"dhrl vs host MuJoCo C, {part}: {r['host']}"
        worst = r["mjwarp"][part]["max"]
        assert worst < ONE_STEP_TOLERANCE[task], (
            f"{task} {part}: normwise relative error {worst:.3g} against MJWarp exceeds "
            f"{ONE_STEP_TOLERANCE[task]:g}; per state: {r['per_state']}"
        )
    assert r["host_reward_abs_error"] <= HOST_REWARD_TOLERANCE, r["host_reward_abs_error"]
    assert r["mjwarp_reward_abs_error"]["max"] < REWARD_TOLERANCE, r["mjwarp_reward_abs_error"]


@pytest.mark.parametrize("task", ["inverted-pendulum", "half-cheetah"])
def test_rollout_statistics_agree_with_mjwarp(vm, task):
    r = vm.rollout_stats(task, WORLDS, STEPS, DEVICE, SEED)
    assert r["supported"], r.get("reason")
    assert r["overflow"] == 0, f"MJWarp overflow bits {r['overflow']:#x}"
    ours, theirs = r["dhrl"], r["mjwarp"]
    assert ours["diverged"] == 0 and theirs["diverged"] == 0, r
    if task == "inverted-pendulum":
        assert ours["reward_mean"] == theirs["reward_mean"] == 1.0, r
        assert ours["terminations"] > 0 and theirs["terminations"] > 0, r
        assert abs(ours["terminations"] - theirs["terminations"]) <= PENDULUM_TERMINATIONS_TOLERANCE, r
        assert abs(ours["mean_terminated_length"] - theirs["mean_terminated_length"]) <= PENDULUM_LENGTH_TOLERANCE, r
    else:
        assert ours["terminations"] == theirs["terminations"] == 0, r
        assert abs(ours["reward_mean"] - theirs["reward_mean"]) < HALF_CHEETAH_MEAN_TOLERANCE, r
        assert HALF_CHEETAH_STD_RATIO[0] < ours["reward_std"] / theirs["reward_std"] < HALF_CHEETAH_STD_RATIO[1], r
