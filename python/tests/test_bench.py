"""``python -m dhrl.bench`` runs end to end and reports every measured cell (no timing is
asserted: the figures depend on the machine)."""

import json

import pytest

from dhrl import bench


def test_bench_json_rows_hold_every_measured_cell(capsys):
    assert bench.main(
        ["--tasks", "InvertedPendulum-v4", "--envs", "1,3", "--delay", "2", "--threads", "1",
         "--seconds", "0.05", "--async-max", "1", "--json"]
    ) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [(row["task"], row["copies"], row["delay"]) for row in rows] == [
        ("InvertedPendulum-v4", 1, 2),
        ("InvertedPendulum-v4", 3, 2),
    ]
    for row in rows:
        for cell in ("raw", "dhrl_native_delayed", "dhrl_delay0", "dhrl_delayed", "gym_sync"):
            assert row[cell] > 0, (cell, row)
    assert rows[0]["gym_async"] > 0
    assert rows[1]["gym_async"] is None, "above --async-max AsyncVectorEnv is not run"


def test_bench_rejects_bad_copy_counts(capsys):
    with pytest.raises(SystemExit):
        bench.main(["--envs", "16,zero"])
    assert "expected comma-separated integers ≥ 1" in capsys.readouterr().err
