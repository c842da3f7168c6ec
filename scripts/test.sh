#!/usr/bin/env bash
# Sets up, builds and runs the whole test suite on the Vulkan device (lavapipe where there is
# no GPU) with the validation layer on.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$root/scripts/build.sh"
cd "$root"
meson test -C build --print-errorlogs "$@"
