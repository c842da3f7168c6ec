#!/usr/bin/env bash
# First figures (README): BVH build time per builder, GPU trace time per builder, CPU trace time,
# and naive GPU trace time where it finishes within a minute, for bunny, dragon_200k and the full
# dragon at 1024x1024 in normal mode. Every time is the median of REPEAT renders after a warm-up
# render (lavapipe compiles a pipeline at its first dispatch). Prints a markdown table.
# Usage: scripts/figures.sh [REPEAT]   (run after scripts/build.sh)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
vkrt="$root/build/vkrt"
models="$root/../shared/models/meshes"
repeat=${1:-3}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

trace_ms() { sed -n 's/.*: trace \([0-9.]*\) ms.*/\1/p' "$1"; }
build_ms() { sed -n 's/^build *\([0-9.]*\) ms/\1/p' "$1"; }

echo "device: $("$vkrt" devices | head -n 1 | sed 's/^0: //'); CPU: $(nproc) threads; $repeat timed renders after a warm-up"
echo
echo "| mesh | triangles | builder | build ms | SAH cost | GPU trace ms | CPU trace ms | naive GPU trace ms |"
echo "|---|---|---|---|---|---|---|---|"
for mesh in bunny.obj dragon_200k.obj dragon_871k.glb; do
  for bvh in sah midpoint; do
    "$vkrt" info "$models/$mesh" --bvh "$bvh" >"$out/info"
    tris=$(sed -n 's/^triangles *//p' "$out/info")
    sah=$(sed -n 's/^sah cost *\([0-9.]*\).*/\1/p' "$out/info")
    "$vkrt" render "$models/$mesh" --bvh "$bvh" --repeat "$repeat" -o "$out/gpu.png" 2>"$out/gpu"
    "$vkrt" render "$models/$mesh" --bvh "$bvh" --repeat "$repeat" --backend cpu -o "$out/cpu.png" 2>"$out/cpu"
    naive="over a minute (not run)"
    # Naive cost grows with triangles x pixels: only the bunny finishes within a minute on lavapipe.
    if [ "$mesh" = bunny.obj ] && [ "$bvh" = sah ]; then
      if timeout 60 "$vkrt" render "$models/$mesh" --traverse naive -o "$out/naive.png" 2>"$out/naive"; then
        naive=$(trace_ms "$out/naive")
      else
        naive="over a minute"
      fi
    elif [ "$bvh" = midpoint ]; then
      naive="(same as sah)"
    fi
    echo "| $mesh | $tris | $bvh | $(build_ms "$out/info") | $sah | $(trace_ms "$out/gpu") | $(trace_ms "$out/cpu") | $naive |"
  done
done
