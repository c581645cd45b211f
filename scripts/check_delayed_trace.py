#!/usr/bin/env python3
"""An outside check of `dhrl rollout --delay ...`: verifies, from the undelayed trace of the
same state and actions, every line of the delayed trace.

    check_delayed_trace.py --delay D --undelayed U.jsonl --delayed X.jsonl --actions A.csv

For every line t of the delayed trace: `obs` is s_{t-D} (absent while t < D) with the reward and
flags of the step that produced it; `augmented` is x_t = (s_{t-D}, a_{t-D}, ..., a_{t-1}) while
the episode runs; the line that ends the episode carries the remaining states in `delivered`.
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

    checked = 0
    for t, line in enumerate(seen):
        if line["t"] != t:
            fail(f"line {t} has t={line['t']}")
        got = {k: line[k] for k in ("obs", "reward", "terminated", "truncated") if k in line}
        want = arrival(t - d) if t >= d else {}
        if got != want:
            fail(f"t={t}: received {got}, expected {want}")
        ended = t == end and (truth[t].get("terminated") or truth[t].get("truncated"))
        if t >= d and not ended:
            x = f32(truth[t - d]["obs"]) + [a for row in actions[t - d:t] for a in f32(row)]
            if line.get("augmented") != x:
                fail(f"t={t}: augmented state differs from (s_(t-D), a_(t-D..t-1))")
            checked += 1
        elif "augmented" in line:
            fail(f"t={t}: unexpected augmented state")
        if ended and d > 0:
            first = t - d + 1 if t >= d else 0
            want = [arrival(j) for j in range(first, t + 1)]
            if line.get("delivered") != want:
                fail(f"t={t}: delivered {line.get('delivered')}, expected {want}")
    print(json.dumps({"lines": len(seen), "augmented_checked": checked, "ended": bool(seen[-1].get("delivered") or d == 0)}))


if __name__ == "__main__":
    main()
