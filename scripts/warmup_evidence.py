#!/usr/bin/env python3
"""Which warm-up can reach the paper's published returns? (issue 15, item 6)

Before the first observation arrives (t < Δ) a delayed agent cannot act; something else is
executed. The paper's Algorithm 1 says uniform random actions; the BPQL code of the same group
executes zero actions. On tasks that terminate, a random warm-up can end an episode before any
policy acts: such an episode returns at most Δ (one reward ≤ 1 per step on InvertedPendulum),
so the mean evaluation return of *any* policy is bounded by

    P(survive) · 1000 + (1 − P(survive)) · Δ      (InvertedPendulum: reward 1 per step)

This script measures, with Gymnasium's own v4 tasks (the task spec), the fraction of episodes
that survive Δ warm-up steps of each kind from Gymnasium's reset distribution, and sets the
InvertedPendulum bound beside the paper's best published return at each Δ
(src/report/paper_table1.csv).

    .deps/venv/bin/python scripts/warmup_evidence.py [--episodes 1000]
"""
import argparse
import csv
import pathlib
import warnings

import gymnasium as gym
import numpy as np

TASKS = {
    "inverted-pendulum": "InvertedPendulum-v4",
    "hopper": "Hopper-v4",
    "walker2d": "Walker2d-v4",
    "ant": "Ant-v4",
    "humanoid": "Humanoid-v4",
}
DELAYS = (5, 10, 20)


def survival(env_id, delay, kind, episodes):
    """Fraction of episodes not terminated after `delay` warm-up steps of `kind`."""
    env = gym.make(env_id)
    low, high = env.action_space.low, env.action_space.high
    rng = np.random.default_rng(0)
    alive = 0
    for episode in range(episodes):
        env.reset(seed=episode)
        for _ in range(delay):
            if kind == "random":
                action = rng.uniform(low, high).astype(np.float32)
            else:
                action = np.zeros_like(low)
            _, _, terminated, _, _ = env.step(action)
            if terminated:
                break
        else:
            alive += 1
    env.close()
    return alive / episodes


def paper_best(task):
    """The paper's best Table 1 return per delay on `task`, with its algorithm."""
    table = pathlib.Path(__file__).resolve().parent.parent / "src/report/paper_table1.csv"
    best = {}
    with open(table) as f:
        for row in csv.DictReader(f):
            if row["task"] == task and int(row["delay"]) in DELAYS:
                delay, mean = int(row["delay"]), float(row["mean"])
                if delay not in best or mean > best[delay][0]:
                    best[delay] = (mean, row["algorithm"], row["std"])
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    args = parser.parse_args()
    warnings.filterwarnings("ignore")  # Gymnasium's "v4 is out of date"

    print(f"Episodes surviving the Δ warm-up steps ({args.episodes} resets per cell, seeds 0..):\n")
    print("| task | Δ | random | zeros |")
    print("|---|---|---|---|")
    rates = {}
    for task, env_id in TASKS.items():
        for delay in DELAYS:
            rates[task, delay] = {k: survival(env_id, delay, k, args.episodes) for k in ("random", "zeros")}
            r = rates[task, delay]
            print(f"| {task} | {delay} | {r['random']:.3f} | {r['zeros']:.3f} |")

    print("\nInvertedPendulum: the highest mean return any policy can reach, against the paper:\n")
    print("| Δ | bound with random warm-up | bound with zeros | paper's best (Table 1) |")
    print("|---|---|---|---|")
    best = paper_best("inverted-pendulum")
    for delay in DELAYS:
        r = rates["inverted-pendulum", delay]
        bound = {k: p * 1000 + (1 - p) * delay for k, p in r.items()}
        mean, algo, std = best[delay]
        print(f"| {delay} | {bound['random']:.1f} | {bound['zeros']:.1f} | {mean} ± {std} ({algo}) |")


if __name__ == "__main__":
    main()
