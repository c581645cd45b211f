#!/usr/bin/env bash
# The whole test suite, on a fresh machine too: set-up (idempotent), then every test in release mode.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
scripts/setup.sh
cargo test --release "$@"
