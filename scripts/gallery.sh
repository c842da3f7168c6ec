#!/usr/bin/env bash
# Regenerates the README gallery (docs/gallery/*.png) with the project's own renderer.
# Usage: scripts/gallery.sh   (after scripts/build.sh)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
vkrt="$root/build/vkrt"
models="$root/../shared/models/meshes"
out="$root/docs/gallery"
mkdir -p "$out"
size=320x320
r() { "$vkrt" render "$@" --size "$size" -q; }
r -o "$out/builtin_normal.png"
r -o "$out/builtin_depth.png" --mode depth
r -o "$out/builtin_albedo.png" --mode albedo
r -o "$out/builtin_uv.png" --mode uv
r "$models/bunny.obj" -o "$out/bunny_normal.png"
r "$models/dragon_200k.obj" -o "$out/dragon_normal.png"
r "$models/dragon_200k.obj" -o "$out/dragon_id.png" --mode id
r "$models/dragon_200k.obj" -o "$out/dragon_heat_leaves_sah.png" --mode heatmap --heat leaves --heat-max 12
r "$models/dragon_200k.obj" -o "$out/dragon_heat_leaves_midpoint.png" --mode heatmap --heat leaves --bvh midpoint --heat-max 12
r "$models/dragon_200k.obj" -o "$out/dragon_heat_nodes_sah.png" --mode heatmap --heat nodes
r "$models/armadillo_52k.obj" -o "$out/armadillo_depth.png" --mode depth
r "$root/../shared/models/gltf/draco/three_meshes_two_materials_one_no_material/three_meshes_two_materials_one_no_material.gltf" \
  -o "$out/three_meshes_uv.png" --mode uv --eye 1.2,0.4,0.6
r "$root/../shared/models/gltf/draco/three_meshes_two_materials_one_no_material/three_meshes_two_materials_one_no_material.gltf" \
  -o "$out/three_meshes_albedo.png" --mode albedo --eye 1.2,0.4,0.6
