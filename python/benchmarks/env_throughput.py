"""``python/benchmarks/env_throughput.py``: environment steps per second of ``dhrl.make_vec``
beside what a Python user runs today, measured in the same run on this machine: Gymnasium's
``SyncVectorEnv`` and ``AsyncVectorEnv`` of ``<Task>-v4`` wrapped in ``DelayObservation``, and
EnvPool at Δ = 0 when it is installed. Random actions, uniform in the task's action bounds,
resets included; every vector step counts ``num_envs`` environment steps.

Beside them, in the same process, the anchors of dhrl's own path: the same batch stepped
inside the library with nothing built for Python ("Rust", ``Batch.time_native_steps``), and
one copy stepped by bare ``mj_step`` calls on one thread ("raw", hot in cache), and the
machine's ceiling for the batch: as many such bare loops at once as dhrl has threads, each on
a thread of its own over its share of the copies, never synchronised ("ceiling": the thread
count times "raw" on an ideal machine; less where the copies do not fit in a core's caches or
the cores slow each other down). "Rust" and dhrl's Python path at Δ with
``autoreset_mode="same_step"`` are measured in alternating slices (six each, twice
``--seconds`` in all), so that their ratio, the cost of the Python path, does not take in the
machine's drift between two separate windows. Same-step, because that is what the native loop
does: every copy steps in every call, and one whose episode ended restarts in the same call.
Under the default next-step autoreset such a copy spends its next call held, without physics
(as in Gymnasium and EnvPool, which is why the columns set beside theirs use it): on
InvertedPendulum, whose episodes last about six steps under random actions, one call in seven
of each copy, which made the Python path look 10–14% faster than the loop it wraps.

Every column executes the same random actions: ``DelayObservation`` passes the agent's
actions on from the first step, so dhrl's delayed env runs with ``warmup="random"`` (uniform
in the bounds too) rather than its default zeros, which would change the physics being timed
(a Humanoid given zero torques for Δ steps is a different, costlier contact problem).

Run it from the repository root, with the built extension on the path:

    PYTHONPATH=python .deps/venv/bin/python python/benchmarks/env_throughput.py --tasks all --envs 256

``--json`` prints one JSON object per row instead of the table; ``--json-out FILE`` appends those
objects to FILE as well, beside the table (``scripts/bench_performance.sh`` records its rows so).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Callable

import numpy as np
from gymnasium import spaces

from machine import cpu_model  # this folder's module (the script's folder is on sys.path)


def timed_steps(step: Callable[[np.ndarray], object], actions: np.ndarray, seconds: float) -> tuple[int, float]:
    """Calls ``step`` with ``actions[0], actions[1], …`` (cycling) for at least ``seconds``:
    (calls, seconds taken)."""
    steps, start = 0, time.perf_counter()
    while True:
        step(actions[steps % len(actions)])
        steps += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds and steps >= 3:
            return steps, elapsed


def measure(step: Callable[[np.ndarray], object], actions: np.ndarray, seconds: float) -> float:
    """Environment steps per second of ``step`` over at least ``seconds`` (after 5 warm-up steps)."""
    for k in range(5):
        step(actions[k % len(actions)])
    steps, elapsed = timed_steps(step, actions, seconds)
    return steps * actions.shape[1] / elapsed


def bench_dhrl(gym_id: str, num_envs: int, delay: int, threads: int, actions, seconds) -> float:
    import dhrl

    env = dhrl.make_vec(gym_id, num_envs, delay=delay, num_threads=threads, warmup="random")
    env.reset(seed=0)
    try:
        return measure(env.step, actions, seconds)
    finally:
        env.close()


def bench_python_and_native(
    gym_id: str, num_envs: int, delay: int, threads: int, actions, seconds, rounds: int = 6
) -> tuple[float, float]:
    """Steps/s of the same batch stepped inside the library with nothing returned to Python
    (``Batch.time_native_steps``) and through ``env.step`` with same-step autoreset (the same
    physics per call as the native loop), two envs of one configuration measured in
    alternating slices of ``seconds / rounds`` each: the machine's drift (other processes,
    clock) falls on both alike, so their ratio is steadier than two separate windows."""
    import dhrl

    envs = [
        dhrl.make_vec(
            gym_id, num_envs, delay=delay, num_threads=threads, warmup="random", autoreset_mode="same_step"
        )
        for _ in range(2)
    ]
    try:
        for env in envs:
            env.reset(seed=0)
        native, python = envs
        table = np.ascontiguousarray(actions, np.float32)

        calls = [8]  # steps per native call, doubled until one call lasts a slice

        def native_steps(slice_seconds: float) -> tuple[int, float]:
            # One call steps `calls[0]` times (the pool's threads stay awake between its steps).
            while True:
                elapsed = native._batch.time_native_steps(table, calls[0])
                if elapsed >= slice_seconds:
                    return calls[0], elapsed
                calls[0] *= 2

        native_steps(0.0)
        for k in range(5):
            python.step(actions[k % len(actions)])
        totals = {"native": [0, 0.0], "python": [0, 0.0]}
        for _ in range(rounds):
            for name, run in (
                ("native", native_steps),
                ("python", lambda s: timed_steps(python.step, actions, s)),
            ):
                steps, elapsed = run(seconds / rounds)
                totals[name][0] += steps
                totals[name][1] += elapsed
        rate = {name: steps * num_envs / elapsed for name, (steps, elapsed) in totals.items()}
        return rate["native"], rate["python"]
    finally:
        for env in envs:
            env.close()


def bench_raw(gym_id: str, seconds: float, copies: int = 1, threads: int = 1) -> float:
    """Bare ``mj_step`` loops over at least ``seconds``: one copy on this thread by default
    ("raw"), or ``threads`` loops at once, each over its share of ``copies`` ("ceiling")."""
    import dhrl
    from dhrl import _dhrl

    task = dhrl.task_name(gym_id)
    steps = 1000 * threads
    while True:
        rate = _dhrl.raw_mj_step_rate(task, copies, steps, threads)
        if steps / rate >= seconds:
            return rate
        steps *= 2


def bench_gymnasium(gym_id: str, num_envs: int, delay: int, kind: str, actions, seconds) -> float:
    import gymnasium as gym
    from gymnasium.wrappers import DelayObservation

    def make():
        env = gym.make(gym_id)
        return DelayObservation(env, delay) if delay > 0 else env

    vector = gym.vector.SyncVectorEnv if kind == "sync" else gym.vector.AsyncVectorEnv
    env = vector([make] * num_envs)
    env.reset(seed=0)
    try:
        return measure(env.step, actions.astype(np.float64), seconds)
    finally:
        env.close()


def bench_envpool(gym_id: str, num_envs: int, threads: int, actions, seconds) -> float | None:
    try:
        import envpool
    except ImportError:
        return None
    env = envpool.make_gymnasium(gym_id, num_envs=num_envs, num_threads=threads, seed=0)
    env.reset()
    try:
        return measure(env.step, actions.astype(np.float64), seconds)
    finally:
        env.close()


def ratio(a: float | None, b: float | None) -> str:
    return f"{a / b:.2f}×" if a and b else "–"


def rate(value: float | None) -> str:
    return f"{value:,.0f}" if value else "–"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="env_throughput.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", default="HalfCheetah-v4,Humanoid-v4", help="comma-separated, or 'all'")
    parser.add_argument("--envs", default="1,16,256", help="comma-separated copy counts")
    parser.add_argument("--delay", type=int, default=20, help="the delayed configuration's Δ")
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1, help="dhrl's and EnvPool's threads")
    parser.add_argument("--seconds", type=float, default=3.0, help="time per measurement")
    parser.add_argument(
        "--async-max", type=int, default=256,
        help="largest copy count AsyncVectorEnv is run at (one process per copy)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object per row instead of the table")
    parser.add_argument(
        "--json-out", metavar="FILE",
        help="also append one JSON object per row (as --json prints) to FILE, whatever is printed",
    )
    args = parser.parse_args(argv)
    try:
        sizes = [int(n) for n in args.envs.split(",")]
        if any(n < 1 for n in sizes):
            raise ValueError
    except ValueError:
        parser.error(f"--envs {args.envs!r}: expected comma-separated integers ≥ 1, e.g. 1,16,256")
    if args.delay < 0 or args.threads < 1 or args.seconds <= 0:
        parser.error("--delay must be ≥ 0, --threads ≥ 1 and --seconds > 0")
    import dhrl

    if args.tasks.strip() == "all":
        args.tasks = ",".join(dhrl.TASKS.values())
    tasks = [t.strip() for t in args.tasks.split(",") if t.strip()]

    for task in tasks:
        try:
            dhrl.task_name(task)
        except ValueError as e:
            parser.error(str(e))

    delay = args.delay
    header = (
        f"| task | copies | raw mj_step (1 copy, 1 thread) | ceiling ({args.threads} raw loops) "
        f"| dhrl Rust Δ={delay} | dhrl Python Δ={delay} same-step | dhrl Python Δ=0 | dhrl Python Δ={delay} "
        f"| Gymnasium Sync Δ={delay} | Gymnasium Async Δ={delay} | EnvPool Δ=0 "
        f"| Python / Rust (Δ={delay}) | Rust / raw | ceiling / raw | Rust / ceiling "
        f"| dhrl Δ={delay} / best Gymnasium | dhrl / EnvPool (Δ=0) | Δ={delay} / Δ=0 |"
    )
    if not args.json:
        print(
            f"env steps/s on {cpu_model()}, {args.threads} dhrl/EnvPool threads, {args.seconds:g} s per cell, "
            f"{os.cpu_count()} cores"
        )
        print(header)
        print("|" + "---|" * 18)
    for task in tasks:
        gym_id = dhrl.TASKS.get(task, task)
        for n in sizes:
            space = dhrl.make_vec(gym_id, 1).single_action_space
            assert isinstance(space, spaces.Box)
            low, high = space.low, space.high
            actions = np.random.default_rng(0).uniform(low, high, (64, n, low.size)).astype(np.float32)
            native, python = bench_python_and_native(gym_id, n, delay, args.threads, actions, 2 * args.seconds)
            row = {
                "task": gym_id,
                "copies": n,
                "raw": bench_raw(gym_id, args.seconds),
                "ceiling": bench_raw(gym_id, args.seconds, copies=n, threads=args.threads),
                "dhrl_native_delayed": native,
                "dhrl_python_delayed_same_step": python,
                "dhrl_delayed": bench_dhrl(gym_id, n, delay, args.threads, actions, args.seconds),
                "dhrl_delay0": bench_dhrl(gym_id, n, 0, args.threads, actions, args.seconds),
                "gym_sync": bench_gymnasium(gym_id, n, delay, "sync", actions, args.seconds),
                "gym_async": (
                    bench_gymnasium(gym_id, n, delay, "async", actions, args.seconds)
                    if n <= args.async_max
                    else None
                ),
                "envpool_delay0": bench_envpool(gym_id, n, args.threads, actions, args.seconds),
                "delay": delay,
                "threads": args.threads,
                "cpu": cpu_model(),
            }
            best_gym = max(v for v in (row["gym_sync"], row["gym_async"]) if v)
            if args.json_out:
                with open(args.json_out, "a", encoding="utf-8") as out:
                    out.write(json.dumps(row) + "\n")
            if args.json:
                print(json.dumps(row), flush=True)
            else:
                print(
                    f"| {gym_id} | {n} | {rate(row['raw'])} | {rate(row['ceiling'])} "
                    f"| {rate(row['dhrl_native_delayed'])} | {rate(row['dhrl_python_delayed_same_step'])} "
                    f"| {rate(row['dhrl_delay0'])} | {rate(row['dhrl_delayed'])} "
                    f"| {rate(row['gym_sync'])} | {rate(row['gym_async'])} | {rate(row['envpool_delay0'])} "
                    f"| {ratio(row['dhrl_python_delayed_same_step'], row['dhrl_native_delayed'])} "
                    f"| {ratio(row['dhrl_native_delayed'], row['raw'])} "
                    f"| {ratio(row['ceiling'], row['raw'])} | {ratio(row['dhrl_native_delayed'], row['ceiling'])} "
                    f"| {ratio(row['dhrl_delayed'], best_gym)} | {ratio(row['dhrl_delay0'], row['envpool_delay0'])} "
                    f"| {ratio(row['dhrl_delayed'], row['dhrl_delay0'])} |",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
