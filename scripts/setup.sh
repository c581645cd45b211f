#!/usr/bin/env bash
# One-time, idempotent set-up of what dhrl links against and tests with:
#   .deps/venv            Python venv with mujoco==3.17.0 and gymnasium[mujoco] (the parity oracle)
#   .deps/mujoco/lib      libmujoco.so.3.17.0 from that wheel, plus the libmujoco.so link mujoco-rs needs
#   .deps/mujoco-assets   the task XMLs shipped inside the installed gymnasium package
# Re-running it when everything is in place takes well under a second.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
deps="$root/.deps"
venv="$deps/venv"
stamp="$deps/setup.stamp"
requirements="mujoco==3.17.0 gymnasium[mujoco]==1.4.0"

if ! command -v pkg-config >/dev/null 2>&1; then
    echo "setup: pkg-config is missing; the build finds MuJoCo through it (Debian/Ubuntu: apt-get install pkgconf)" >&2
    exit 1
fi

if [[ -f "$stamp" && "$(cat "$stamp")" == "$requirements" && -e "$deps/mujoco/lib/libmujoco.so" && -d "$deps/mujoco-assets" ]]; then
    exit 0
fi

python="${PYTHON:-python3}"
if ! command -v "$python" >/dev/null 2>&1; then
    echo "setup: $python not found; dhrl needs Python 3.9+ with venv to fetch MuJoCo and Gymnasium" >&2
    exit 1
fi

mkdir -p "$deps"
if [[ ! -x "$venv/bin/python" ]]; then
    echo "setup: creating $venv" >&2
    "$python" -m venv "$venv"
fi
echo "setup: installing $requirements" >&2
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check $requirements

site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
lib="$site/mujoco/libmujoco.so.3.17.0"
assets="$site/gymnasium/envs/mujoco/assets"
[[ -f "$lib" ]] || { echo "setup: $lib is missing from the mujoco wheel" >&2; exit 1; }
[[ -f "$assets/half_cheetah.xml" ]] || { echo "setup: no task XMLs under $assets" >&2; exit 1; }

mkdir -p "$deps/mujoco/lib"
ln -sfn "$lib" "$deps/mujoco/lib/libmujoco.so.3.17.0"
ln -sfn libmujoco.so.3.17.0 "$deps/mujoco/lib/libmujoco.so"
ln -sfn "$assets" "$deps/mujoco-assets"
echo "$requirements" > "$stamp"
echo "setup: done (MuJoCo 3.17.0 in $deps/mujoco/lib, task XMLs in $deps/mujoco-assets)" >&2
