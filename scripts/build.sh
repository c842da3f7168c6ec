#!/usr/bin/env bash
# Sets up a fresh machine (scripts/setup.sh) and builds vkrt into build/.
# VKRT_WERROR=1 (as CI sets it) turns every warning into an error.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
bash scripts/setup.sh
werror=false
[ "${VKRT_WERROR:-0}" = 1 ] && werror=true
if [ -f build/build.ninja ]; then
  meson configure build -Dwerror=$werror >/dev/null
else
  meson setup build -Dwerror=$werror >/dev/null
fi
ninja -C build
