#!/usr/bin/env bash
# Stacked runs against separate processes at the same total thread count (the machine's cores):
# for each S, S runs of `dhrl train` (one per seed, each one thread) side by side, against the
# same S seeds as stacks (`--seeds`), one stack process per core. Prints the aggregate env
# steps per second (S·steps / wall seconds, start-up and evaluations included) of each, and
# their ratio, with the CPU named.
#
#   scripts/bench_stack.sh [--algo sac] [--task inverted-pendulum] [--delay 0] [--steps 3000]
#                          [--sizes "1 2 4 8 16"] [--cores N] [--out DIR]
set -euo pipefail
algo=sac task=inverted-pendulum delay=0 steps=3000 sizes="1 2 4 8 16" cores=$(nproc) out=""
while [[ $# -gt 0 ]]; do
    case "$1" in
        --algo) algo=$2; shift 2 ;;
        --task) task=$2; shift 2 ;;
        --delay) delay=$2; shift 2 ;;
        --steps) steps=$2; shift 2 ;;
        --sizes) sizes=$2; shift 2 ;;
        --cores) cores=$2; shift 2 ;;
        --out) out=$2; shift 2 ;;
        *) echo "bench_stack.sh: unknown option $1 (see the header for the options)" >&2; exit 2 ;;
    esac
done
dhrl=${DHRL_BIN:-$(dirname "$0")/../target/release/dhrl}
[[ -x $dhrl ]] || { echo "bench_stack.sh: no dhrl at $dhrl (build it, or set DHRL_BIN)" >&2; exit 2; }
work=${out:-$(mktemp -d)}
mkdir -p "$work"
warmup=$((steps / 3))
flags=(--task "$task" --algo "$algo" --delay "$delay" --steps "$steps" --warmup-steps "$warmup"
       --eval-every "$steps" --eval-episodes 1 --threads 1 --no-tensorboard)
echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//'), $cores cores"
echo "$algo on $task, delay $delay, $steps steps ($warmup of warm-up), 1 update per step"
printf '%4s  %22s  %22s  %6s\n' S "separate (steps/s)" "stacked (steps/s)" ratio
for s in $sizes; do
    rm -rf "$work/sep-$s" "$work/stack-$s"
    mkdir -p "$work/sep-$s" "$work/stack-$s"
    start=$(date +%s.%N)
    for ((seed = 0; seed < s; seed++)); do
        "$dhrl" train "${flags[@]}" --seed "$seed" --out "$work/sep-$s/run-$seed" >/dev/null 2>&1 &
        # At most `cores` processes at once, as a scheduler would place them.
        while (( $(jobs -rp | wc -l) >= cores )); do wait -n; done
    done
    wait
    separate=$(echo "$s * $steps / ($(date +%s.%N) - $start)" | bc -l)
    # One stack per core, the seeds split between them.
    groups=$(( s < cores ? s : cores ))
    start=$(date +%s.%N)
    for ((g = 0; g < groups; g++)); do
        seeds=$(seq -s, "$g" "$groups" $((s - 1)))
        "$dhrl" train "${flags[@]}" --seeds "$seeds" --out "$work/stack-$s/group-$g" >/dev/null 2>&1 &
    done
    wait
    stacked=$(echo "$s * $steps / ($(date +%s.%N) - $start)" | bc -l)
    printf '%4d  %22.1f  %22.1f  %6.2f\n' "$s" "$separate" "$stacked" "$(echo "$stacked / $separate" | bc -l)"
done
