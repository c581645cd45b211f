"""Shared helpers: the repository's `dhrl` binary (for the rollout comparison)."""

import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def dhrl_bin() -> pathlib.Path:
    path = pathlib.Path(os.environ.get("DHRL_BIN", ROOT / "target" / "release" / "dhrl"))
    if not path.is_file():
        pytest.fail(f"{path} is missing: build it with `cargo build --release` (or set DHRL_BIN)")
    return path


def run_dhrl(binary: pathlib.Path, *args: str) -> str:
    done = subprocess.run([str(binary), *args], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, f"dhrl {' '.join(args)} failed:\n{done.stderr}"
    return done.stdout
