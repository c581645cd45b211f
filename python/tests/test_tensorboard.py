"""`dhrl train` writes TensorBoard event files beside its CSVs: read back with TensorBoard's own
reader (EventAccumulator), every train.csv statistic and every evaluation is there at its
step with the CSV's value, and a killed, resumed run shows each step once (the resumed file's
SessionLog START drops what the killed process logged past its checkpoint)."""

import csv
import pathlib
import signal
import subprocess
import time

import pytest

from conftest import ROOT, run_dhrl

event_accumulator = pytest.importorskip("tensorboard.backend.event_processing.event_accumulator")


def read_events(run: pathlib.Path) -> dict:
    """Every scalar tag's (step, value) pairs, as TensorBoard loads the run's folder."""
    accumulator = event_accumulator.EventAccumulator(str(run / "tensorboard"), size_guidance={"scalars": 0})
    accumulator.Reload()
    return {tag: [(e.step, e.value) for e in accumulator.Scalars(tag)] for tag in accumulator.Tags()["scalars"]}


def read_csv(path: pathlib.Path) -> list:
    with path.open() as f:
        return list(csv.DictReader(f))


def assert_events_match_csvs(run: pathlib.Path) -> None:
    events = read_events(run)
    train = read_csv(run / "train.csv")
    for column in train[0]:
        if column == "step":
            continue
        expected = [(int(row["step"]), float(row[column])) for row in train if row[column] != ""]
        found = events.get(f"train/{column}", [])
        assert [s for s, _ in found] == [s for s, _ in expected], column
        for (_, value), (_, want) in zip(found, expected):
            assert value == pytest.approx(want, rel=1e-5, abs=1e-3), column
    evals = read_csv(run / "evals.csv")
    for column in ("return_mean", "return_std", "length_mean"):
        found = events[f"eval/{column}"]
        assert [s for s, _ in found] == [int(row["step"]) for row in evals], column
        for (_, value), row in zip(found, evals):
            assert value == pytest.approx(float(row[column]), rel=1e-5, abs=1e-3), column


TINY = ["--task", "inverted-pendulum", "--algo", "sac", "--warmup-steps", "100", "--batch-size", "32",
        "--eval-every", "200", "--eval-episodes", "1"]


def test_tensorboard_holds_every_logged_statistic_and_evaluation(dhrl_bin, tmp_path):
    config = tmp_path / "log-often.toml"
    config.write_text("log_every = 50\n")
    run = tmp_path / "run"
    run_dhrl(dhrl_bin, "train", *TINY, "--steps", "600", "--config", str(config), "--out", str(run))
    assert_events_match_csvs(run)
    assert len(read_events(run)["eval/return_mean"]) == 3


def test_a_killed_and_resumed_run_shows_each_step_once(dhrl_bin, tmp_path):
    config = tmp_path / "log-often.toml"
    config.write_text("log_every = 50\ncheckpoint_every = 300\n")
    run = tmp_path / "run"
    child = subprocess.Popen(
        [str(dhrl_bin), "train", *TINY, "--steps", "1500", "--config", str(config), "--out", str(run)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT,
    )
    start = time.monotonic()
    # Past the first checkpoint (300) and logging beyond it, then killed.
    while not any(int(r["step"]) >= 450 for r in (read_csv(run / "train.csv") if (run / "train.csv").exists() else [])):
        assert child.poll() is None, "the run ended before it was killed"
        assert time.monotonic() - start < 300, "step 450 never came"
        time.sleep(0.05)
    child.send_signal(signal.SIGKILL)
    child.wait()
    run_dhrl(dhrl_bin, "train", "--resume", str(run))
    assert len(list((run / "tensorboard").iterdir())) == 2, "one event file per process"
    assert_events_match_csvs(run)
    steps = [s for s, _ in read_events(run)["train/updates"]]
    assert steps == sorted(set(steps)) and steps[-1] == 1499


def test_no_tensorboard_writes_none(dhrl_bin, tmp_path):
    run = tmp_path / "run"
    run_dhrl(dhrl_bin, "train", *TINY, "--steps", "200", "--no-tensorboard", "--out", str(run))
    assert not (run / "tensorboard").exists()
    assert "tensorboard = false" in (run / "config.toml").read_text()
