"""The wheel stands alone: built by maturin (``scripts/test.sh`` builds it into
``target/wheels/``), installed with its dependencies into a fresh venv in a temporary folder,
and run from there — ``make_vec`` and one step of every task — with nothing of the checkout on
any path: its libmujoco must come from the venv's mujoco wheel, its task XMLs from the venv's
Gymnasium, and the extension's run path must name no folder of the machine that built it.
Needs PyPI (the venv installs the wheel's dependencies). Skipped without a built wheel, unless
``DHRL_REQUIRE_WHEEL=1`` (``scripts/test.sh`` sets it)."""

import json
import os
import pathlib
import subprocess
import sys
import zipfile

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]

CHECK = r"""
import json, pathlib
import numpy as np
import dhrl
from dhrl import _dhrl
out = {"package": dhrl.__file__, "extension": _dhrl.__file__, "assets": _dhrl.assets_dir(), "tasks": {}}
for name in dhrl.TASKS:
    env = dhrl.make_vec(name, num_envs=2, delay=2, seed=0)
    obs, _ = env.reset(seed=0)
    obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
    assert np.isfinite(obs).all() and np.isfinite(reward).all(), name
    out["tasks"][name] = list(obs.shape)
    env.close()
out["libmujoco"] = sorted({line.split()[-1] for line in open("/proc/self/maps") if "libmujoco" in line})
print(json.dumps(out))
"""


def wheel() -> pathlib.Path:
    wheels = sorted((ROOT / "target" / "wheels").glob("dhrl-*.whl"), key=lambda p: p.stat().st_mtime)
    if not wheels:
        missing = "no wheel in target/wheels: build it with `maturin build --release -m python/Cargo.toml` (scripts/test.sh does)"
        if os.environ.get("DHRL_REQUIRE_WHEEL") == "1":
            pytest.fail(missing)
        pytest.skip(missing)
    return wheels[-1]


def run(*command: str, cwd: pathlib.Path, env: dict[str, str]) -> str:
    done = subprocess.run(command, capture_output=True, text=True, cwd=cwd, env=env)
    assert done.returncode == 0, f"{' '.join(command)} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout


def clean_environment() -> dict[str, str]:
    """The caller's environment without anything that points into the checkout."""
    env = {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "LD_LIBRARY_PATH", "DHRL_ASSETS_DIR", "VIRTUAL_ENV"}}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if not p.startswith(str(ROOT)))
    return env


def test_the_wheel_installs_and_runs_away_from_the_checkout(tmp_path: pathlib.Path) -> None:
    built = wheel()
    names = zipfile.ZipFile(built).namelist()
    for member in ("dhrl/__init__.py", "dhrl/_installed.py", "dhrl/py.typed", "dhrl/_dhrl.pyi"):
        assert member in names, f"{member} is missing from {built.name}"
    assert any(n.startswith("dhrl/_dhrl") and n.endswith(".so") for n in names), names
    assert not any(n.startswith(("tests/", "benchmarks/")) for n in names), names
    # What a registry shows and pip resolves: the pinned MuJoCo, the licence files, the README.
    metadata = zipfile.ZipFile(built).read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    for line in ("Requires-Dist: mujoco==3.17.0", "Requires-Dist: gymnasium>=1.1", "License-Expression: MIT OR Apache-2.0", "License-File: LICENSE-MIT", "License-File: LICENSE-APACHE", "# dhrl (Python)"):
        assert line in metadata, f"{line!r} is not in the wheel's METADATA"
    assert any(n.endswith(".dist-info/licenses/LICENSE-APACHE") for n in names), names

    env = clean_environment()
    venv = tmp_path / "venv"
    run(sys.executable, "-m", "venv", str(venv), cwd=tmp_path, env=env)
    python = venv / "bin" / "python"
    run(str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", str(built), cwd=tmp_path, env=env)

    out = json.loads(run(str(python), "-c", CHECK, cwd=tmp_path, env=env).strip().splitlines()[-1])
    site = pathlib.Path(out["package"]).resolve().parent.parent
    assert site.is_relative_to(venv.resolve()), out["package"]
    assert [pathlib.Path(p).resolve() for p in out["libmujoco"]] == [(site / "mujoco" / "libmujoco.so.3.17.0").resolve()], out["libmujoco"]
    assert pathlib.Path(out["assets"]).resolve() == (site / "gymnasium" / "envs" / "mujoco" / "assets").resolve(), out["assets"]
    assert len(out["tasks"]) == 6, out["tasks"]
    for name, shape in out["tasks"].items():
        assert shape[0] == 2, (name, shape)

    # The run path is relative to the extension: no folder of the building machine in it.
    dynamic = run("readelf", "-d", out["extension"], cwd=tmp_path, env=env)
    paths = [line.split("[", 1)[1].rstrip("]") for line in dynamic.splitlines() if "RUNPATH" in line or "RPATH" in line]
    assert paths == ["$ORIGIN/../mujoco"], paths
