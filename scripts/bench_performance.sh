#!/usr/bin/env bash
# The README's performance figures measured again on this machine, in one run, as markdown: each
# row dhrl's figure beside its anchor timed in the same run and their ratio, under the CPU's
# name and the commit. Run it alone on the machine (they are shared and noisy: run it twice and
# report the range). Needs torch and envpool in .deps/venv (`.deps/venv/bin/pip install torch
# envpool`); builds the binary and the Python extension from the checkout first (nothing to do
# when they are current), so that the figures are the named commit's. About 16 minutes on 2
# cores.
#
# Each run also appends one JSON object per claim (date, commit, cpu, cores, claim, dhrl's
# figure, the anchor's, ratio) to docs/results/performance/<cpu-slug>.jsonl, and then
# scripts/performance_table.py rewrites README.md's performance table from every such file
# (docs/results/performance/README.md). DHRL_PERF_NO_RECORD=1 measures and prints only.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
py=.deps/venv/bin/python dhrl=target/release/dhrl
export OPENBLAS_NUM_THREADS=1
if ! "$py" -c "import torch, envpool" 2>/dev/null; then
    echo "bench_performance.sh: needs torch and envpool in .deps/venv: .deps/venv/bin/pip install torch envpool" >&2
    exit 2
fi
command -v bc > /dev/null || { echo "bench_performance.sh: needs bc (scripts/bench_stack.sh uses it)" >&2; exit 2; }
cargo build --quiet --release --features wgpu-learner --bin dhrl
PYO3_PYTHON="$PWD/$py" cargo build --quiet --release --features wgpu-learner -p dhrl-python
cp target/release/lib_dhrl.so python/dhrl/_dhrl.abi3.so
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# The run's records, one JSON object per claim, each with the run's date, commit, CPU and cores
# (from the environment below) before the claim's own fields.
export BENCH_RECORDS="$work/records.jsonl"
# Appends one record: `record CLAIM JSON` (the claim's fields as a JSON object).
record() {
    "$py" -c '
import json, os, sys
rec = {k: os.environ["BENCH_" + k.upper()] for k in ("date", "commit", "cpu", "run")}
rec["cores"] = int(os.environ["BENCH_CORES"])
rec["claim"] = sys.argv[1]
rec.update(json.loads(sys.argv[2]))
with open(os.environ["BENCH_RECORDS"], "a", encoding="utf-8") as f:
    f.write(json.dumps(rec, ensure_ascii=False) + "\n")' "$@"
}
# Prints `| what | dhrl | anchor | ratio (target) |` from one JSON report on stdin, and records it
# as CLAIM (MEASURE: what the figures count): `row CLAIM MEASURE what ours anchor target unit`.
row() {
    local claim=$1 measure=$2
    shift 2
    local report
    report=$(cat)
    "$py" -c '
import json, sys
what, ours, anchor, target, unit = sys.argv[1:]
r = json.loads(sys.stdin.read())
goal = f" (goal {target})" if target else ""
print(f"| {what} | {r[ours]:,.1f} {unit} | {r[anchor]:,.1f} {unit} | {r[ours] / r[anchor]:.2f}{goal} |")' "$@" <<< "$report"
    record "$claim" "$("$py" -c '
import json, sys
measure, ours, anchor = sys.argv[1:]
r = json.loads(sys.stdin.read())
print(json.dumps({"measure": measure, "dhrl": r[ours], "anchor": r[anchor],
                  "ratio": round(r[ours] / r[anchor], 4), "report": r}))' "$measure" "$2" "$3" <<< "$report")"
}

commit=$(git rev-parse --short HEAD)
# What this script writes itself (the records, README.md's table) does not count as a change.
[[ -z $(git status --porcelain --untracked-files=no -- . ':!docs/results/performance' ':!README.md') ]] ||
    commit="$commit with uncommitted changes"
export BENCH_DATE BENCH_COMMIT=$commit BENCH_CPU BENCH_CORES BENCH_RUN
BENCH_DATE=$(date -u +%F) BENCH_RUN=$(date -u +%FT%TZ)
BENCH_CPU=$(lscpu | sed -n 's/^Model name: *//p' | head -1) BENCH_CORES=$(nproc)
echo "## $BENCH_DATE, $commit, \"$BENCH_CPU\", $BENCH_CORES cores"
echo
echo "| what | dhrl | anchor, same run | ratio |"
echo "|---|---|---|---|"

# 1. SAC on InvertedPendulum, 1 update per env step, 1 thread, against CleanRL's loop in PyTorch.
"$py" scripts/bench_torch_sac.py --end-to-end --steps 6000 --learning-starts 1000 --dhrl "$dhrl" |
    row sac_end_to_end_vs_pytorch "env steps/s" \
        "SAC end to end, env steps/s, vs PyTorch (bench_torch_sac.py --end-to-end)" \
        dhrl_env_steps_per_sec torch_env_steps_per_sec "≥ 1.6" "/s"

# 2. The training loop's updates/s (train.csv, after the first 2,000 steps) against the learner
#    alone, benched before and after it.
bench() { "$dhrl" bench update --algo sac --task inverted-pendulum --updates 2000 --threads 1 --json; }
bench > "$work/bench"
"$dhrl" train --task inverted-pendulum --algo sac --steps 12000 --threads 1 --no-tensorboard \
    --out "$work/loop" > /dev/null
bench >> "$work/bench"
"$py" -c '
import csv, json, statistics, sys
loop = statistics.median(float(r["updates_per_sec"]) for r in csv.DictReader(open(sys.argv[1]))
                         if int(r["step"]) >= 2000)
bench = statistics.median(json.loads(l)["updates_per_sec"] for l in open(sys.argv[2]))
print(json.dumps({"loop": loop, "bench": bench}))' "$work/loop/train.csv" "$work/bench" |
    row loop_vs_update "updates/s" \
        "SAC training loop vs \`dhrl bench update\`, updates/s (median rows; bench before and after)" \
        loop bench "≥ 0.9" "/s"

# 2b. Stacked runs against separate processes (scripts/bench_stack.sh at one size): SAC on
#     InvertedPendulum, 4 seeds as one stack per core (passes of 2) against 4 separate processes,
#     as many at a time as there are cores; aggregate env steps/s, start-up included. About a minute.
DHRL_BIN="$dhrl" scripts/bench_stack.sh --algo sac --task inverted-pendulum --steps 3000 --sizes 4 \
    --out "$work/stack" > "$work/stack.txt"
"$py" -c '
import json, sys
s, separate, stacked, ratio = open(sys.argv[1]).read().strip().splitlines()[-1].split()
print(json.dumps({"seeds": int(s), "steps": 3000, "stacked": float(stacked), "separate": float(separate)}))' \
    "$work/stack.txt" |
    row stacked_vs_separate "env steps/s" \
        "SAC, 4 seeds as one stack per core vs 4 separate processes, aggregate env steps/s (bench_stack.sh --sizes 4 --steps 3000)" \
        stacked separate "" "/s"

# 3. VDPO's update against the same update in PyTorch: the training schedule (bursts of 1,000
#    cloning steps), then one cloning step per update with the products timed alone.
"$py" scripts/bench_torch_vdpo.py --dhrl "$dhrl" > "$work/vdpo"
"$py" scripts/bench_torch_vdpo.py --dhrl "$dhrl" --bc-every 10 --bc-updates 10 --updates 100 \
    --products > "$work/vdpo-scaled"
for report in vdpo vdpo-scaled; do
    "$py" -c '
import json, sys
r = json.loads(open(sys.argv[1]).read())
print(json.dumps({"dhrl": 1e3 / r["dhrl_ms_per_update"], "torch": 1e3 / r["torch_ms_per_update"],
                  "dhrl_ms_per_update": r["dhrl_ms_per_update"], "torch_ms_per_update": r["torch_ms_per_update"],
                  **({"torch_products_ms": r["products_ms"]} if "products_ms" in r else {})}))' \
        "$work/$report" |
        row "$([[ $report == vdpo ]] && echo vdpo_vs_pytorch || echo vdpo_one_clone_step_vs_pytorch)" "updates/s" \
            "VDPO updates/s vs PyTorch (bench_torch_vdpo.py$([[ $report == vdpo ]] || echo ' --bc-every 10 --bc-updates 10 --products'))" \
            dhrl torch "≥ 1.5" "/s"
done
"$py" -c '
import json, sys
r = json.loads(open(sys.argv[1]).read())
r["over_products"] = r["dhrl_ms_per_update"] / r["products_ms"]
r["ms_at_1_5x"] = r["torch_ms_per_update"] / 1.5
print(("\nVDPO, one cloning step per update: {dhrl_ms_per_update:.1f} ms, PyTorch {torch_ms_per_update:.1f} ms. "
       "The update has {products_gflop_per_update:.2f} GFLOP of matrix products; PyTorch runs them alone in "
       "{products_ms:.1f} ms ({products_gflop_per_sec:.0f} GFLOP/s), and dhrl'"'"'s whole update takes "
       "{over_products:.2f}× that. At 1.5× PyTorch ({ms_at_1_5x:.1f} ms) "
       + ("{other_ms_at_1_5x:.1f} ms would be left for everything besides the products at that rate."
          if r["other_ms_at_1_5x"] >= 0 else
          "the products alone at that rate would not fit: 1.5× takes faster products than PyTorch'"'"'s on "
          "this CPU.")).format(**r))' \
    "$work/vdpo-scaled"

# 4. Table 1's grid as `dhrl sweep plan` costs it from updates timed here.
echo
"$dhrl" sweep plan table1 --cost-updates 3 --out "$work/plan" | grep '^total:' | sed 's/^/Table 1 grid, /' |
    tee "$work/grid.txt"
record table1_grid_core_hours "$("$py" -c '
import json, re, sys
hours = float(re.search(r"total: ([0-9.]+) core-hours", open(sys.argv[1]).read()).group(1))
print(json.dumps({"measure": "core-hours", "value": hours}))' "$work/grid.txt")"

# 5. Environment throughput, 256 copies at Δ = 20 on 2 threads: the Rust batch and the Python
#    path against raw mj_step and the machine's ceiling, six tasks.
echo
PYTHONPATH=python "$py" python/benchmarks/env_throughput.py --tasks all --envs 256 --seconds 2 \
    --async-max 0 --json-out "$work/env.jsonl" | grep '^|'
# Three claims from those rows, each with every task's figures and the tasks' range of ratios:
# dhrl's Python path (next-step, make_vec's default) against EnvPool at Δ = 0, the Rust batch
# against the machine's ceiling, and the Python path (same-step) against the Rust batch.
"$py" -c '
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
claims = [("env_vs_envpool", "dhrl_delayed", "envpool_delay0"),
          ("env_vs_ceiling", "dhrl_native_delayed", "ceiling"),
          ("python_vs_rust_batch", "dhrl_python_delayed_same_step", "dhrl_native_delayed")]
for claim, ours, anchor in claims:
    per_task = {r["task"]: {"dhrl": round(r[ours], 1), "anchor": round(r[anchor], 1),
                            "ratio": round(r[ours] / r[anchor], 4), "raw": round(r["raw"], 1)}
                for r in rows if r.get(ours) and r.get(anchor)}
    if not per_task:
        continue
    ratios = [t["ratio"] for t in per_task.values()]
    print(claim, json.dumps({"measure": "env steps/s", "copies": rows[0]["copies"], "delay": rows[0]["delay"],
                             "threads": rows[0]["threads"], "ratio_lo": min(ratios), "ratio_hi": max(ratios),
                             "per_task": per_task}))' "$work/env.jsonl" |
    while read -r claim fields; do record "$claim" "$fields"; done

# The records go beside the earlier runs' on this CPU, and README.md's table is made again.
if [[ ${DHRL_PERF_NO_RECORD:-0} != 1 ]]; then
    file="docs/results/performance/$("$py" scripts/performance_table.py --slug "$BENCH_CPU").jsonl"
    mkdir -p docs/results/performance
    cat "$BENCH_RECORDS" >> "$file"
    echo
    echo "Recorded $(wc -l < "$BENCH_RECORDS") claims in $file; README.md's performance table:"
    echo
    "$py" scripts/performance_table.py
fi
