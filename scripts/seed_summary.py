#!/usr/bin/env python3
"""Per-setting summary of finished runs, seeds grouped: the final evaluation return and the mean
over all evaluations (the area under the learning curve, each seed's in parentheses), as mean ±
standard deviation over the seeds (population, as `dhrl plot`), and, against a reference
setting, how many of the seed pairs each setting wins on each (a tie is no win).

    scripts/seed_summary.py --group LABEL=DIR[,DIR...] [--group ...] [--reference LABEL]

Each DIR is a run folder (its evals.csv is read); a LABEL may hold "=", a DIR may not. Groups with runs of different budgets are
refused, as are runs that do not all evaluate at the same steps. Standard library only.
"""
import argparse
import csv
import statistics
import sys
from pathlib import Path


def curve(run):
    path = Path(run) / "evals.csv"
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"seed_summary: cannot read {path}: {e.strerror}")
    if not rows:
        sys.exit(f"seed_summary: {path} has no evaluations")
    missing = {"step", "return_mean"} - set(rows[0])
    if missing:
        sys.exit(f"seed_summary: {path} has no column {', '.join(sorted(missing))}")
    return [int(r["step"]) for r in rows], [float(r["return_mean"]) for r in rows]


def spread(values):
    if len(values) == 1:
        return f"{values[0]:.0f}"
    return f"{statistics.mean(values):.0f} ± {statistics.pstdev(values):.0f}"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--group", action="append", required=True, metavar="LABEL=DIR[,DIR...]")
    parser.add_argument("--reference", help="the label the others are counted against")
    args = parser.parse_args()
    groups = {}
    steps_seen = None
    for spec in args.group:
        label, sep, dirs = spec.rpartition("=")
        if not sep or not label or any(not d for d in dirs.split(",")):
            sys.exit(f"seed_summary: --group takes LABEL=DIR[,DIR...], not '{spec}'")
        if label in groups:
            sys.exit(f"seed_summary: the label '{label}' names two groups")
        runs = []
        for run in dirs.split(","):
            steps, returns = curve(run)
            if steps_seen is None:
                steps_seen = steps
            elif steps != steps_seen:
                sys.exit(f"seed_summary: {run} evaluates at other steps than the first run "
                         f"({steps[0]}..{steps[-1]}, {len(steps)} evaluations, against "
                         f"{steps_seen[0]}..{steps_seen[-1]}, {len(steps_seen)})")
            runs.append((statistics.mean(returns), returns[-1]))
        groups[label] = runs
    if args.reference is not None and args.reference not in groups:
        sys.exit(f"seed_summary: --reference '{args.reference}' is not a group label "
                 f"(labels: {', '.join(groups)})")
    print(f"| setting | final ({steps_seen[-1]}) | mean over {len(steps_seen)} evaluations |")
    print("|---|---|---|")
    for label, runs in groups.items():
        areas = [area for area, _ in runs]
        finals = [final for _, final in runs]
        each = ", ".join(f"{a:.0f}" for a in areas)
        print(f"| {label} | {spread(finals)} | {spread(areas)} ({each}) |")
    if args.reference is not None:
        reference = groups[args.reference]
        print()
        for label, runs in groups.items():
            if label == args.reference:
                continue
            pairs = len(runs) * len(reference)
            area = sum(a > ra for a, _ in runs for ra, _ in reference)
            final = sum(f > rf for _, f in runs for _, rf in reference)
            print(f"- {label} > {args.reference}: area {area}/{pairs}, final {final}/{pairs}")


if __name__ == "__main__":
    main()
