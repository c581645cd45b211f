#!/usr/bin/env bash
# The runs behind docs/experiments.md's D2HPG comparison and lifting-settings tables, and their plots.
#
#   scripts/comparison.sh SET [--jobs N] [--seeds "0 1 2"] [--algos "A B"] [--conditions "C D"]
#                         [--steps N] [--runs DIR] [--dry-run]
#
# SET: ip-delay5    InvertedPendulum, Δ = 5, 100k steps: d2hpg, bpql, vdpo, delayed-sac,
#                   augmented-sac, naive-sac
#      hc-delay10   HalfCheetah, Δ = 10, 200k steps: d2hpg, bpql, vdpo, delayed-sac, augmented-sac
#      lifting-ip   d2hpg on InvertedPendulum, Δ = 10, 25k steps: λ ∈ {0.1, 1, 10, 100} at K = 10,
#                   K ∈ {2, 5, 20} at λ = 1, and λ = 10 with K = 2
#      lifting-hc   the same settings on HalfCheetah, Δ = 10, 50k steps
#      principled-choices
#                   d2hpg-principled on InvertedPendulum, Δ = 10, actuator noise σ = 0.2, 25k
#                   steps, with each of HPG's three departures from the paper's L_lax alone (the
#                   paper's own are principled-ip's runs at σ = 0.2)
#      principled-hc-settings
#                   d2hpg-principled on HalfCheetah, Δ = 10, no noise, 30k steps: λ = 0.1 and
#                   0.01 (λ = 0 is BPQL), and each of HPG's three departures from the paper's
#                   L_lax alone, each on top of the defaults (so the mean is the default's run)
#      principled-ip  d2hpg-principled, d2hpg and bpql on InvertedPendulum, Δ = 10, 25k steps,
#                   without noise, with actuator noise σ = 0.1 and 0.2, and under random delays
#                   in 1..=10 (conservative agent)
#      principled-hc  the same on HalfCheetah, 50k steps
#                   (conditions, for --conditions: none, noise0.1, noise0.2, random)
#
# Every run learns on one thread (RAYON_NUM_THREADS=1), N runs at a time (default: the number of
# cores). A run folder that already exists is continued with `dhrl train --resume`, so the script
# can be stopped and started again; a finished run is left as it is. --algos keeps only the
# named algorithms of the set (ip-delay5, hc-delay10, principled-ip, principled-hc), --conditions
# the named conditions (principled-ip, principled-hc), --steps replaces the set's budget. The plot
# goes to DIR/SET.svg (DIR defaults to runs/), with the final-return table printed beside it.
# DHRL_BIN=PATH runs that program instead of building and running the checkout's.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

usage() { sed -n '2,33p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
[[ $# -ge 1 ]] || usage
set_name=$1
shift
case $set_name in
    ip-delay5 | hc-delay10 | lifting-ip | lifting-hc | principled-choices | principled-hc-settings | principled-ip | principled-hc) ;;
    *) echo "comparison.sh: unknown set '$set_name' (accepted: ip-delay5, hc-delay10, lifting-ip, lifting-hc, principled-choices, principled-hc-settings, principled-ip, principled-hc)" >&2; exit 2 ;;
esac
jobs=$(nproc)
seeds="0 1 2"
algos=""
conditions=""
steps=""
runs=runs
dry_run=false
while [[ $# -gt 0 ]]; do
    case $1 in
        --jobs) jobs=$2; shift 2 ;;
        --seeds) seeds=$2; shift 2 ;;
        --algos) algos=$2; shift 2 ;;
        --conditions) conditions=$2; shift 2 ;;
        --steps) steps=$2; shift 2 ;;
        --runs) runs=$2; shift 2 ;;
        --dry-run) dry_run=true; shift ;;
        *) echo "comparison.sh: unknown option $1" >&2; usage ;;
    esac
done

# One line per run: folder name, then the flags of `dhrl train`.
plan() {
    local seed algo setting
    for seed in $seeds; do
        case $set_name in
            ip-delay5)
                for algo in ${algos:-d2hpg bpql vdpo delayed-sac augmented-sac naive-sac}; do
                    echo "ip-$algo-d5-s$seed --task inverted-pendulum --algo $algo --delay 5 --warmup zeros --steps 100000 --seed $seed"
                done ;;
            hc-delay10)
                for algo in ${algos:-d2hpg bpql vdpo delayed-sac augmented-sac}; do
                    echo "hc-$algo-d10-s$seed --task half-cheetah --algo $algo --delay 10 --steps 200000 --seed $seed"
                done ;;
            lifting-ip | lifting-hc)
                local task=inverted-pendulum prefix=ip extra="--warmup zeros --steps 25000"
                if [[ $set_name == lifting-hc ]]; then task=half-cheetah prefix=hc extra="--steps 50000"; fi
                for setting in "0.1 10" "1 10" "10 10" "100 10" "1 2" "1 5" "1 20" "10 2"; do
                    set -- $setting
                    echo "lift-$prefix-w$1-k$2-s$seed --task $task --algo d2hpg --delay 10 --lifting-weight $1 --lifting-samples $2 $extra --seed $seed"
                done ;;
            principled-choices)
                for setting in "mean metric_reduction=mean" "huber distance=huber" \
                    "stop stop_transition_gradient=true"; do
                    set -- $setting
                    echo "choice-$1-s$seed --task inverted-pendulum --algo d2hpg-principled --delay 10 --actuator-noise 0.2 --warmup zeros --steps 25000 --eval-every 2500 --seed $seed --set $2"
                done ;;
            principled-hc-settings)
                for setting in "w0.1 lifting_weight=0.1" "w0.01 lifting_weight=0.01" \
                    "mean metric_reduction=mean" "huber distance=huber" \
                    "stop stop_transition_gradient=true"; do
                    set -- $setting
                    echo "hc-setting-$1-s$seed --task half-cheetah --algo d2hpg-principled --delay 10 --steps 30000 --eval-every 2500 --seed $seed --set $2"
                done ;;
            principled-ip | principled-hc)
                local task=inverted-pendulum prefix=ip extra="--warmup zeros --steps 25000 --eval-every 2500"
                if [[ $set_name == principled-hc ]]; then task=half-cheetah prefix=hc extra="--steps 50000 --eval-every 2500"; fi
                for condition in "none --delay 10" "noise0.1 --delay 10 --actuator-noise 0.1" \
                    "noise0.2 --delay 10 --actuator-noise 0.2" "random --random-delay --max-delay 10"; do
                    set -- $condition
                    local name=$1
                    shift
                    [[ -z $conditions || " $conditions " == *" $name "* ]] || continue
                    for algo in ${algos:-d2hpg-principled d2hpg bpql}; do
                        echo "$prefix-$algo-$name-s$seed --task $task --algo $algo $* $extra --seed $seed"
                    done
                done ;;
        esac
    done
}

if [[ -n $conditions ]]; then
    [[ $set_name == principled-ip || $set_name == principled-hc ]] || { echo "comparison.sh: --conditions applies to principled-ip and principled-hc only, not '$set_name'" >&2; exit 2; }
    for condition in $conditions; do
        case $condition in
            none | noise0.1 | noise0.2 | random) ;;
            *) echo "comparison.sh: unknown condition '$condition' (accepted: none, noise0.1, noise0.2, random)" >&2; exit 2 ;;
        esac
    done
fi
[[ -z $steps || $steps =~ ^[1-9][0-9]*$ ]] || { echo "comparison.sh: --steps takes a positive whole number of environment steps, not '$steps'" >&2; exit 2; }

lines=$(plan)
# --steps replaces the budget every run of the set names.
[[ -z $steps ]] || lines=$(printf '%s\n' "$lines" | sed -E "s/--steps [0-9]+/--steps $steps/")
# DHRL_BIN names a dhrl program built before (so that rebuilding the checkout cannot change the
# program under runs in flight); by default the checkout's, built first.
dhrl=${DHRL_BIN:-target/release/dhrl}
if ! $dry_run; then
    scripts/setup.sh
    [[ -n ${DHRL_BIN:-} ]] || cargo build --release --quiet
    mkdir -p "$runs"
fi

run_one() {
    local name=$1
    shift
    local dir="$runs/$name" steps
    steps=$(printf '%s\n' "$@" | grep -A1 -x -- --steps | tail -n1)
    if [[ -d $dir ]]; then
        set -- --resume "$dir" --steps "$steps"
    else
        set -- --out "$dir" "$@"
    fi
    if $dry_run; then
        echo "dhrl train $*"
    else
        echo "start $name" >&2
        RAYON_NUM_THREADS=1 "$dhrl" train "$@" >"$runs/$name.log" 2>&1 || { echo "failed: $name (see $runs/$name.log)" >&2; return 1; }
        echo "done  $name" >&2
    fi
}
export -f run_one
export runs dhrl dry_run

printf '%s\n' "$lines" | xargs -P "$jobs" -L 1 bash -c 'run_one "$@"' _
$dry_run && exit 0
folders=$(printf '%s\n' "$lines" | awk -v runs="$runs" '{print runs "/" $1}')
# shellcheck disable=SC2086
"$dhrl" plot $folders --out "$runs/$set_name.svg" --title "$set_name"
