#!/usr/bin/env bash
# The whole test suite, on a fresh machine too: set-up (idempotent), Mesa's software Vulkan
# where no Vulkan driver is installed (so the WGSL kernels and burn's wgpu learner run without a
# GPU), then every test in release mode. The GPU tests fail when no adapter is found; set
# DHRL_SKIP_GPU_TESTS=1 to skip them knowingly (they then say so on stderr).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
scripts/setup.sh
if [[ "${DHRL_SKIP_GPU_TESTS:-}" != 1 ]] && ! ls /usr/share/vulkan/icd.d/*.json >/dev/null 2>&1; then
    if [[ "$(id -u)" == 0 ]] && command -v apt-get >/dev/null 2>&1; then
        echo "test: installing Mesa's software Vulkan (mesa-vulkan-drivers) for the GPU delay-layer tests" >&2
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null
    else
        echo "test: no Vulkan driver found; install mesa-vulkan-drivers (Debian/Ubuntu) or set DHRL_SKIP_GPU_TESTS=1" >&2
    fi
fi
# Everything is built once, with burn's wgpu learner: tests/wgpu_learner.rs checks it against
# the CPU learner on a real GPU, or on Mesa's software Vulkan (lavapipe) where there is none.
if [[ "${DHRL_SKIP_GPU_TESTS:-}" != 1 ]]; then
    export DHRL_WGPU_SOFTWARE="${DHRL_WGPU_SOFTWARE:-vulkan}" DHRL_REQUIRE_WGPU_LEARNER=1
fi
cargo test --release --features wgpu-learner "$@"
