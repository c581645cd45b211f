#!/usr/bin/env python3
"""An outside check of `dhrl rollout --delay ...`: verifies, from the undelayed trace of the
same state and actions, every line of the delayed trace.

    check_delayed_trace.py --delay D --undelayed U.jsonl --delayed X.jsonl --actions A.csv
                           [--random-bound B]

For every line t of the delayed trace: `obs` is s_{t-D} (absent while t < D) with the reward and
flags of the step that produced it; `augmented` is x_t = (s_{t-D}, a_{t-D}, ..., a_{t-1}) while
the episode runs; the line that ends the episode, and only that line, carries the remaining
states in `delivered`.

With --random-bound B (random observation delays in {1..B}, the conservative agent): every line
t >= 1 lists in `arrived` the observations that reached the agent at t; each is the state s_tau
of the undelayed trace, 1 <= t - tau <= B steps old; no state arrives twice; every state that
must have arrived by the end (tau <= T - B) did; and the state the agent acts on at t, s_{t-D},
arrived at or before t. The summary counts arrivals, how old they were and how many overtook
an older state (out of order).

Delayed values are float32, so they are compared to float32-rounded undelayed values.
Exits 1 with a message on the first mismatch; prints a JSON summary otherwise.
"""
import argparse
import json
import sys

import numpy as np


def f32(values):
    return np.asarray(values, dtype=np.float64).astype(np.float32).astype(np.float64).tolist()


def fail(message):
    print(message, file=sys.stderr)
    sys.exit(1)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--delay", type=int, required=True)
    parser.add_argument("--undelayed", required=True)
    parser.add_argument("--delayed", required=True)
    parser.add_argument("--actions", required=True)
    parser.add_argument("--random-bound", type=int, default=None)
    args = parser.parse_args()
    d = args.delay
    truth = [json.loads(line) for line in open(args.undelayed)]
    seen = [json.loads(line) for line in open(args.delayed)]
    actions = [[float(v) for v in line.split(",")] for line in open(args.actions) if line.strip()]
    end = len(truth) - 1  # the step that ended the episode (or the last action)
    if len(seen) != len(truth):
        fail(f"delayed trace has {len(seen)} lines, undelayed {len(truth)}")

    def arrival(j):
        """What reaches the agent with s_j: the state and the step that produced it."""
        out = {"obs": f32(truth[j]["obs"])}
        if j >= 1:
            out.update(reward=f32([truth[j]["reward"]])[0], terminated=truth[j]["terminated"], truncated=truth[j]["truncated"])
        return out

    # Whether the undelayed episode ended (rather than the actions running out).
    ended = bool(truth[end].get("terminated") or truth[end].get("truncated"))
    bound = args.random_bound
    arrived_at = {}  # tau -> the step its observation arrived
    checked = 0
    for t, line in enumerate(seen):
        if line["t"] != t:
            fail(f"line {t} has t={line['t']}")
        got = {k: line[k] for k in ("obs", "reward", "terminated", "truncated") if k in line}
        want = arrival(t - d) if t >= d else {}
        if got != want:
            fail(f"t={t}: received {got}, expected {want}")
        ends_here = ended and t == end
        if bound is None:
            if "arrived" in line:
                fail(f"t={t}: 'arrived' without random delays")
        elif t >= 1:
            if not isinstance(line.get("arrived"), list):
                fail(f"t={t}: no 'arrived' list under random delays")
            for came in line["arrived"]:
                tau = came["tau"]
                if not 1 <= t - tau <= bound:
                    fail(f"t={t}: s_{tau} arrived {t - tau} steps old, outside 1..{bound}")
                if tau in arrived_at:
                    fail(f"t={t}: s_{tau} arrived again (first at t={arrived_at[tau]})")
                if came["obs"] != f32(truth[tau]["obs"]):
                    fail(f"t={t}: the observation that arrived as s_{tau} is not s_{tau}")
                arrived_at[tau] = t
            if t >= d and t - d not in arrived_at:
                fail(f"t={t}: the agent acts on s_{t - d}, which has not arrived")
        if t >= d and not ends_here:
            x = f32(truth[t - d]["obs"]) + [a for row in actions[t - d:t] for a in f32(row)]
            if line.get("augmented") != x:
                fail(f"t={t}: augmented state differs from (s_(t-D), a_(t-D..t-1))")
            checked += 1
        elif "augmented" in line:
            fail(f"t={t}: unexpected augmented state")
        if ends_here and d > 0:
            first = t - d + 1 if t >= d else 0
            want = [arrival(j) for j in range(first, t + 1)]
            if line.get("delivered") != want:
                fail(f"t={t}: delivered {line.get('delivered')}, expected {want}")
        elif "delivered" in line:
            fail(f"t={t}: 'delivered' on a line that does not end the episode")
    summary = {"lines": len(seen), "augmented_checked": checked, "ended": ended}
    if bound is not None:
        missing = [tau for tau in range(0, end - bound + 1) if tau not in arrived_at]
        if missing:
            fail(f"states {missing} never arrived, though at most {bound} steps late")
        ages = [arrived_at[tau] - tau for tau in arrived_at]
        summary["arrivals"] = len(arrived_at)
        summary["ages"] = {str(age): ages.count(age) for age in range(1, bound + 1)}
        summary["out_of_order"] = sum(
            1 for tau in arrived_at if tau - 1 in arrived_at and arrived_at[tau] < arrived_at[tau - 1]
        )
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
