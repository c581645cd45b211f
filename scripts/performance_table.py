#!/usr/bin/env python3
"""The README's performance table, generated from the runs of ``scripts/bench_performance.sh``.

Reads every ``docs/results/performance/*.jsonl`` (one JSON object per claim per run: the run's
date, commit, CPU and cores, the claim's id, dhrl's figure, its anchor's from the same run and
their ratio; see ``docs/results/performance/README.md``) and writes one Markdown table: a row
per claim, a column per CPU, each cell the lowest and highest ratio over that CPU's runs (for
the environment rows over the six tasks too) and the number of runs. The table replaces what
lies between ``<!-- performance-table:start -->`` and ``<!-- performance-table:end -->`` in
README.md, and is printed. Running it again with the same files changes nothing.

    python3 scripts/performance_table.py            # rewrite README.md's table, print it
    python3 scripts/performance_table.py --check    # exit 1 if README.md's table is not current
    python3 scripts/performance_table.py --slug "Intel(R) Xeon(R) Processor"   # -> intel-xeon-processor

Standard library only.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RECORDS = os.path.join(ROOT, "docs", "results", "performance")
README = os.path.join(ROOT, "README.md")
START, END = "<!-- performance-table:start -->", "<!-- performance-table:end -->"
HISTORY = "docs/results/performance-history.md"

# The table's rows, in order: (claim id, what dhrl's figure is; against what anchor, from the same run).
CLAIMS = [
    ("sac_end_to_end_vs_pytorch",
     "SAC end to end, InvertedPendulum, 1 update per env step, 1 thread, env steps/s; "
     "anchor: CleanRL's SAC loop in PyTorch (`scripts/bench_torch_sac.py --end-to-end`)"),
    ("loop_vs_update",
     "SAC's training loop, updates/s (`train.csv`); anchor: the learner alone, `dhrl bench update`"),
    ("env_vs_envpool",
     "256 copies at Δ = 20 on all cores, six tasks: dhrl's Python `make_vec`, env steps/s; "
     "anchor: EnvPool at Δ = 0 (`python/benchmarks/env_throughput.py`)"),
    ("env_vs_ceiling",
     "the same copies, dhrl's Rust batch; anchor: the machine's ceiling, one bare `mj_step` loop "
     "per core over its share of the copies"),
    ("python_vs_rust_batch",
     "the same copies, Python `make_vec` (same-step autoreset); anchor: the Rust batch it wraps, "
     "timed in alternating slices"),
    ("vdpo_vs_pytorch",
     "VDPO's update, HalfCheetah, Δ = 5, 1 thread, training schedule (cloning in bursts of 1,000); "
     "anchor: the same update in PyTorch (`scripts/bench_torch_vdpo.py`)"),
    ("vdpo_one_clone_step_vs_pytorch",
     "the same with one cloning step per update (`--bc-every 10 --bc-updates 10`)"),
    ("stacked_vs_separate",
     "SAC, 4 seeds as one stack per core, aggregate env steps/s; anchor: 4 separate processes, "
     "one per core at a time (`scripts/bench_stack.sh --sizes 4`)"),
    ("table1_grid_core_hours",
     "Table 1's grid (570 runs of 1M steps), core-hours projected from this CPU's update costs "
     "(`dhrl sweep plan table1 --cost-updates 3`; a cost, not a ratio)"),
]


def slug(cpu: str) -> str:
    """A file name for a CPU's model name: "Intel(R) Xeon(R) Processor" -> intel-xeon-processor."""
    name = re.sub(r"\((r|tm)\)", "", cpu, flags=re.I).split("@")[0]
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-") or "unknown-cpu"


def load(folder: str) -> list[dict]:
    records = []
    for path in sorted(glob.glob(os.path.join(folder, "*.jsonl"))):
        with open(path, encoding="utf-8") as f:
            for n, line in enumerate(f, 1):
                if line.strip():
                    try:
                        records.append(json.loads(line))
                    except json.JSONDecodeError as e:
                        raise SystemExit(f"{path}:{n}: not JSON: {e}")
    return records


def span(record: dict) -> tuple[float, float] | None:
    """The record's figure as a range: (ratio, ratio), the tasks' (lowest, highest), or the value."""
    if "ratio_lo" in record:
        return record["ratio_lo"], record["ratio_hi"]
    for key in ("ratio", "value"):
        if isinstance(record.get(key), (int, float)):
            return record[key], record[key]
    return None


def run_key(record: dict) -> tuple:
    return record.get("date"), record.get("commit"), record.get("run")


def cell(claim: str, records: list[dict]) -> str:
    spans = [s for s in map(span, records) if s]
    if not spans:
        return "–"
    lo, hi = min(s[0] for s in spans), max(s[1] for s in spans)
    runs = len({run_key(r) for r in records})
    count = f"({runs} run{'s' if runs != 1 else ''})"
    if claim == "table1_grid_core_hours":
        text = f"{lo:,.0f}" if round(lo) == round(hi) else f"{lo:,.0f}–{hi:,.0f}"
        return f"{text} core-hours {count}"
    text = f"{lo:.2f}" if f"{lo:.2f}" == f"{hi:.2f}" else f"{lo:.2f}–{hi:.2f}"
    return f"{text}× {count}"


def short_commit(commit: str) -> str:
    return commit.replace(" with uncommitted changes", "+")


def column_header(cpu: str, records: list[dict]) -> str:
    dates = sorted({r["date"] for r in records if r.get("date")})
    date = dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}" if dates else "no date"
    commits: list[str] = []
    for r in sorted(records, key=lambda r: (r.get("date") or "", r.get("run") or "")):
        c = short_commit(str(r.get("commit", "?")))
        if c not in commits:
            commits.append(c)
    cores = sorted({r.get("cores") for r in records if r.get("cores")})
    runs = len({run_key(r) for r in records})
    cores_text = "/".join(map(str, cores)) + " cores" if cores else "cores unknown"
    return (f"{cpu}, {cores_text}: {runs} run{'s' if runs != 1 else ''}, {date}, "
            f"at {', '.join(commits)}")


def table(records: list[dict]) -> str:
    known = [c for c, _ in CLAIMS]
    by_cpu: dict[str, list[dict]] = {}
    for r in records:
        if r.get("claim") in known:
            by_cpu.setdefault(r.get("cpu", "unknown CPU"), []).append(r)
    # Columns: CPUs in the order of their first run.
    cpus = sorted(by_cpu, key=lambda c: (min(r.get("date") or "" for r in by_cpu[c]), c))
    out = [
        "<!-- generated by scripts/performance_table.py from docs/results/performance/*.jsonl: "
        "edit those (run scripts/bench_performance.sh), not this table -->",
        "",
    ]
    if not cpus:
        out.append("No runs of `scripts/bench_performance.sh` recorded yet.")
        return "\n".join(out)
    out.append("| claim: dhrl's figure; anchor, timed in the same run | "
               + " | ".join(f"{cpu} ({i + 1})" for i, cpu in enumerate(cpus)) + " |")
    out.append("|---|" + "---|" * len(cpus))
    for claim, what in CLAIMS:
        cells = [cell(claim, [r for r in by_cpu[cpu] if r["claim"] == claim]) for cpu in cpus]
        out.append(f"| {what} | " + " | ".join(cells) + " |")
    out.append("")
    out.append("Each cell: dhrl's figure over its anchor's, lowest and highest over that CPU's runs "
               "(and over the six tasks in the environment rows). The columns' runs"
               " (`+`: a tree with uncommitted changes):")
    out.append("")
    for i, cpu in enumerate(cpus):
        out.append(f"{i + 1}. {column_header(cpu, by_cpu[cpu])}.")
    out.append("")
    out.append(f"The history behind the table, with every run's own figures: [{HISTORY}]({HISTORY}).")
    return "\n".join(out)


def splice(text: str, generated: str) -> str:
    if text.count(START) != 1 or text.count(END) != 1 or text.index(START) > text.index(END):
        raise SystemExit(f"README.md must hold {START} and then {END}, once each")
    head, rest = text.split(START)
    _, tail = rest.split(END)
    return f"{head}{START}\n{generated}\n{END}{tail}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="performance_table.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--slug", metavar="CPU", help="print the records file's name for this CPU model and exit")
    parser.add_argument("--records", default=RECORDS, help="folder of *.jsonl records (default: %(default)s)")
    parser.add_argument("--readme", default=README, help="file whose markers get the table (default: %(default)s)")
    parser.add_argument("--check", action="store_true", help="exit 1 if the file's table is not current; write nothing")
    args = parser.parse_args(argv)
    if args.slug is not None:
        print(slug(args.slug))
        return 0
    generated = table(load(args.records))
    with open(args.readme, encoding="utf-8") as f:
        text = f.read()
    new = splice(text, generated)
    if args.check:
        if new != text:
            print(f"{args.readme}: the performance table is not current: run scripts/performance_table.py",
                  file=sys.stderr)
            return 1
        return 0
    if new != text:
        with open(args.readme, "w", encoding="utf-8") as f:
            f.write(new)
    print(generated)
    return 0


if __name__ == "__main__":
    sys.exit(main())
