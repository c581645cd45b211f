#!/usr/bin/env bash
# Markdown table of `dhrl bench env` for the six tasks: the median of RUNS runs of each
# (this machine is shared and noisy), batched copies at THREADS threads against the raw
# single-thread mj_step anchor measured in the same process.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
envs="${ENVS:-1024}" threads="${THREADS:-2}" runs="${RUNS:-3}"
dhrl=target/release/dhrl
[[ -x $dhrl ]] || cargo build --release
echo "| task | copies | threads | env steps/s | raw mj_step env steps/s (1 thread) | ratio |"
echo "|---|---|---|---|---|---|"
for task in ant half-cheetah hopper walker2d humanoid inverted-pendulum; do
    case $task in humanoid|ant) steps=60 ;; inverted-pendulum) steps=400 ;; *) steps=200 ;; esac
    for _ in $(seq "$runs"); do
        "$dhrl" bench env --task "$task" --envs "$envs" --threads "$threads" --steps "$steps" --json
    done | python3 -c '
import json, statistics, sys
rows = [json.loads(l) for l in sys.stdin]
best = sorted(rows, key=lambda r: r["ratio"])[len(rows) // 2]
print("| {task} | {envs} | {threads} | {env_steps_per_sec:,.0f} | {raw_env_steps_per_sec:,.0f} | {ratio:.2f} |".format(**best))'
done
