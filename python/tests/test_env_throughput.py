"""``python/benchmarks/env_throughput.py`` runs end to end as a script and reports every
measured cell (no timing is asserted: the figures depend on the machine)."""

import json
import os
import pathlib
import subprocess
import sys

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "env_throughput.py"


def run_script(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    package = str(SCRIPT.parents[1])  # python/: the dhrl package and its built extension
    env["PYTHONPATH"] = os.pathsep.join(p for p in (package, env.get("PYTHONPATH")) if p)
    # From another directory: the script finds its helper module by its own location.
    return subprocess.run(
        [sys.executable, str(SCRIPT), *args], capture_output=True, text=True, env=env, cwd="/", timeout=300
    )


def test_json_rows_hold_every_measured_cell():
    done = run_script(
        "--tasks", "InvertedPendulum-v4", "--envs", "1,3", "--delay", "2", "--threads", "2",
        "--seconds", "0.05", "--async-max", "1", "--json",
    )
    assert done.returncode == 0, done.stderr
    rows = [json.loads(line) for line in done.stdout.splitlines()]
    assert [(row["task"], row["copies"], row["delay"]) for row in rows] == [
        ("InvertedPendulum-v4", 1, 2),
        ("InvertedPendulum-v4", 3, 2),
    ]
    for row in rows:
        for cell in ("raw", "ceiling", "dhrl_native_delayed", "dhrl_python_delayed_same_step", "dhrl_delay0", "dhrl_delayed", "gym_sync"):
            assert row[cell] > 0, (cell, row)
        assert row["cpu"] and row["threads"] == 2
    assert rows[0]["gym_async"] > 0
    assert rows[1]["gym_async"] is None, "above --async-max AsyncVectorEnv is not run"


def test_rejects_bad_copy_counts():
    done = run_script("--envs", "16,zero")
    assert done.returncode == 2
    assert "expected comma-separated integers ≥ 1" in done.stderr


def test_the_benchmark_is_not_part_of_the_runtime_package():
    import importlib.util

    assert importlib.util.find_spec("dhrl.bench") is None, "python -m dhrl.bench is gone"
