#!/usr/bin/env bash
# Sets up, builds and renders: with no arguments the built-in scene to render.png; any
# arguments are passed to `vkrt render` (e.g. a mesh file, -o out.png, --mode heatmap).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$root/scripts/build.sh" >/dev/null
exec "$root/build/vkrt" render "$@"
