#!/usr/bin/env bash
# The README's performance figures measured again on this machine, in one run, as markdown: each
# row dhrl's figure beside its anchor timed in the same run and their ratio, under the CPU's
# name and the commit. Run it alone on the machine (they are shared and noisy: run it twice and
# report the range). Needs torch and envpool in .deps/venv (`.deps/venv/bin/pip install torch
# envpool`); builds the binary and the Python extension from the checkout first (nothing to do
# when they are current), so that the figures are the named commit's. About 15 minutes on 2
# cores.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
py=.deps/venv/bin/python dhrl=target/release/dhrl
export OPENBLAS_NUM_THREADS=1
if ! "$py" -c "import torch, envpool" 2>/dev/null; then
    echo "bench_performance.sh: needs torch and envpool in .deps/venv: .deps/venv/bin/pip install torch envpool" >&2
    exit 2
fi
cargo build --quiet --release --features wgpu-learner --bin dhrl
PYO3_PYTHON="$PWD/$py" cargo build --quiet --release --features wgpu-learner -p dhrl-python
cp target/release/lib_dhrl.so python/dhrl/_dhrl.abi3.so
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# Prints `| what | dhrl | anchor | ratio (target) |` from one JSON report on stdin.
row() {
    "$py" -c '
import json, sys
what, ours, anchor, target, unit = sys.argv[1:]
r = json.loads(sys.stdin.read())
print(f"| {what} | {r[ours]:,.1f} {unit} | {r[anchor]:,.1f} {unit} | {r[ours] / r[anchor]:.2f} (goal {target}) |")' "$@"
}

commit=$(git rev-parse --short HEAD)
[[ -z $(git status --porcelain --untracked-files=no) ]] || commit="$commit with uncommitted changes"
echo "## $(date -u +%F), $commit, \"$(lscpu | sed -n 's/^Model name: *//p' | head -1)\", $(nproc) cores"
echo
echo "| what | dhrl | anchor, same run | ratio |"
echo "|---|---|---|---|"

# 1. SAC on InvertedPendulum, 1 update per env step, 1 thread, against CleanRL's loop in PyTorch.
"$py" scripts/bench_torch_sac.py --end-to-end --steps 6000 --learning-starts 1000 --dhrl "$dhrl" |
    row "SAC end to end, env steps/s, vs PyTorch (bench_torch_sac.py --end-to-end)" \
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
    row "SAC training loop vs \`dhrl bench update\`, updates/s (median rows; bench before and after)" \
        loop bench "≥ 0.9" "/s"

# 3. VDPO's update against the same update in PyTorch: the training schedule (bursts of 1,000
#    cloning steps), then one cloning step per update with the products timed alone.
"$py" scripts/bench_torch_vdpo.py --dhrl "$dhrl" > "$work/vdpo"
"$py" scripts/bench_torch_vdpo.py --dhrl "$dhrl" --bc-every 10 --bc-updates 10 --updates 100 \
    --products > "$work/vdpo-scaled"
for report in vdpo vdpo-scaled; do
    "$py" -c '
import json, sys
r = json.loads(open(sys.argv[1]).read())
print(json.dumps({"dhrl": 1e3 / r["dhrl_ms_per_update"], "torch": 1e3 / r["torch_ms_per_update"]}))' \
        "$work/$report" |
        row "VDPO updates/s vs PyTorch (bench_torch_vdpo.py$([[ $report == vdpo ]] || echo ' --bc-every 10 --bc-updates 10 --products'))" \
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
"$dhrl" sweep plan table1 --cost-updates 3 --out "$work/plan" | grep '^total:' | sed 's/^/Table 1 grid, /'

# 5. Environment throughput, 256 copies at Δ = 20 on 2 threads: the Rust batch and the Python
#    path against raw mj_step and the machine's ceiling, six tasks.
echo
PYTHONPATH=python "$py" python/benchmarks/env_throughput.py --tasks all --envs 256 --seconds 2 \
    --async-max 0 | grep '^|'
