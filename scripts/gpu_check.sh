#!/usr/bin/env bash
# dhrl's GPU paths on a machine with a real GPU, in under 8 minutes: our WGSL delay layer and
# burn's wgpu learner checked against the CPU reference (the same tests CI runs on Mesa's
# software Vulkan, here required to find a real adapter), then timed against the CPU:
#   - the delay layer alone (HalfCheetah sizes, 1k to 64k copies, Δ = 5 and 20);
#   - one learner update, CPU against wgpu, for SAC on InvertedPendulum and D2HPG on
#     HalfCheetah (Δ = 5), at a run's batch of 256 rows and at 4,096 rows (the rows a stack of
#     16 runs would hand the device at once);
#   - SAC trained end to end on InvertedPendulum with the learner on wgpu (1 update per step);
#   - stacked runs (`dhrl train --seeds`) on wgpu, S = 1, 8, 64, 256: env steps per second
#     summed over the runs, 1 update per step, SAC on InvertedPendulum and D2HPG on HalfCheetah
#     (Δ = 5; every algorithm's runs share one stacked learner pass).
#
#   scripts/gpu_check.sh                 build here (cargo, feature wgpu-learner) and run
#   scripts/gpu_check.sh --pack DIR      build here and pack what a machine without a Rust
#                                        toolchain needs into DIR (binaries, libmujoco, XMLs)
#   scripts/gpu_check.sh --bundle DIR    run from such a DIR (no cargo there)
#
# Every section prints its wall time. On a machine's first run, burn's wgpu kernels are compiled
# and autotuned at first use (CubeCL caches both under target/environment of the working
# directory's cargo project), so the first wgpu figures of a fresh machine include that cost;
# each step has a time limit so that one slow step cannot eat the others' time.
set -euo pipefail
cd "$(dirname "$0")/.."

mode=${1:-build}
dir=${2:-}
start=$SECONDS
stage() { printf '\n== %s (at %ds)\n' "$1" $((SECONDS - start)); }

# The three executables the checks use, from this checkout's release build.
built_binaries() {
    cargo build --release --features wgpu-learner --bin dhrl >&2
    local tests
    tests=$(cargo test --release --features wgpu-learner --no-run --test wgpu_learner --test delay \
        --message-format=json 2>/dev/null |
        sed -n 's/.*"executable":"\([^"]*\)".*/\1/p')
    echo "target/release/dhrl"
    grep '/wgpu_learner-' <<<"$tests"
    grep '/delay-' <<<"$tests"
}

case "$mode" in
--pack)
    [[ -n "$dir" ]] || { echo "gpu_check: --pack needs a folder" >&2; exit 2; }
    mkdir -p "$dir"
    mapfile -t binaries < <(built_binaries)
    for name_path in "dhrl:${binaries[0]}" "wgpu_learner:${binaries[1]}" "delay:${binaries[2]}"; do
        strip -o "$dir/${name_path%%:*}" "${name_path#*:}"
    done
    cp -L .deps/mujoco/lib/libmujoco.so.3.17.0 "$dir/"
    cp -rL .deps/mujoco-assets "$dir/assets"
    # The test binaries run `dhrl` from the path cargo built it at (CARGO_BIN_EXE_dhrl).
    echo "$PWD/${binaries[0]}" >"$dir/dhrl_path"
    (cd "$dir" && tar -cf - dhrl wgpu_learner delay libmujoco.so.3.17.0 assets dhrl_path |
        xz -6 -T0 >bundle.tar.xz && rm -rf dhrl wgpu_learner delay libmujoco.so.3.17.0 assets dhrl_path)
    ls -la "$dir"
    exit 0
    ;;
--bundle)
    [[ -n "$dir" ]] || { echo "gpu_check: --bundle needs a folder" >&2; exit 2; }
    work=$(mktemp -d)
    tar -xJf "$dir/bundle.tar.xz" -C "$work"
    export LD_LIBRARY_PATH="$work${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" DHRL_ASSETS_DIR="$work/assets"
    dhrl="$work/dhrl" wgpu_learner="$work/wgpu_learner" delay="$work/delay"
    baked=$(cat "$work/dhrl_path")
    if [[ ! -e "$baked" ]]; then
        mkdir -p "$(dirname "$baked")" && ln -s "$dhrl" "$baked"
    fi
    ;;
build)
    mapfile -t binaries < <(built_binaries)
    dhrl=${binaries[0]} wgpu_learner=${binaries[1]} delay=${binaries[2]}
    ;;
*)
    echo "gpu_check: unknown mode '$mode'; accepted: (none), --pack DIR, --bundle DIR" >&2
    exit 2
    ;;
esac

# A real adapter only: no software fallback, and a test that finds none fails.
unset DHRL_WGPU_SOFTWARE DHRL_SKIP_GPU_TESTS
export DHRL_REQUIRE_WGPU_LEARNER=1
# The Vulkan loader complains on every instance without one.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"

failed=()
stage "machine"
grep -m1 'model name' /proc/cpuinfo || true
echo "cores: $(nproc)"
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || true

stage "tests: the WGSL delay layer against the CPU reference"
timeout 60 "$delay" gpu_matches_cpu --test-threads 1 --nocapture || failed+=("the delay-layer tests")

stage "tests: burn's wgpu learner against the CPU learner, and SAC learning on wgpu"
timeout 240 "$wgpu_learner" --test-threads 1 --nocapture || failed+=("the wgpu learner tests")

stage "delay layer: CPU ($(nproc) threads) against the WGSL kernels, HalfCheetah sizes"
timeout 60 "$dhrl" bench delay --task half-cheetah --envs 1024,4096,16384,65536 --delay 5,20 --steps 20 ||
    failed+=("bench delay")

stage "one learner update: CPU against wgpu"
for config in "sac inverted-pendulum 0" "d2hpg half-cheetah 5"; do
    read -r algo task delay <<<"$config"
    for rows in 256 4096; do
        for device in cpu wgpu; do
            printf '%-6s %-18s delay %-2s batch %-5s %-5s ' "$algo" "$task" "$delay" "$rows" "$device"
            timeout 30 "$dhrl" bench update --algo "$algo" --task "$task" --delay "$delay" --batch-size "$rows" \
                --device "$device" --updates 200 --json || failed+=("bench update $algo $rows $device")
        done
    done
done

stage "SAC on InvertedPendulum, learner on wgpu, 1 update per env step"
run=$(mktemp -d)
for device in cpu wgpu; do
    printf '%-5s ' "$device"
    timeout 60 "$dhrl" train --task inverted-pendulum --algo sac --device "$device" --steps 6000 --warmup-steps 1000 \
        --eval-every 6000 --eval-episodes 2 --threads 1 --out "$run/sac-$device" | tail -n 1 ||
        failed+=("train on $device")
done

stage "stacked runs on wgpu: env steps/s summed over S runs, 1 update per step"
for config in "sac inverted-pendulum 0" "d2hpg half-cheetah 5"; do
    read -r algo task delay <<<"$config"
    for runs in 1 8 64 256; do
        printf '%-6s %-18s S = %-4s ' "$algo" "$task" "$runs"
        begin=$(date +%s.%N)
        if timeout 60 "$dhrl" train --task "$task" --algo "$algo" --delay "$delay" --device wgpu \
            --seeds "0..$runs" --steps 300 --warmup-steps 100 --eval-every 300 --eval-episodes 1 \
            --threads 1 --no-tensorboard --out "$run/stack-$algo-$runs" >/dev/null 2>&1; then
            awk -v runs="$runs" -v begin="$begin" -v end="$(date +%s.%N)" \
                'BEGIN { printf "%.0f env steps/s\n", runs * 300 / (end - begin) }'
        else
            echo "did not finish within 60 s"
        fi
    done
done

stage "done"
if ((${#failed[@]})); then
    echo "gpu_check: FAILED: ${failed[*]}" >&2
    exit 1
fi
