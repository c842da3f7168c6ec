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
# The lighting modes, on the CPU backend (the GPU renders the same images, statistically equal,
# see test_lighting_gpu; the CPU is the faster of the two on lavapipe).
rc() { "$vkrt" render "$@" --size "$size" -q --backend cpu; }
rc -o "$out/builtin_shaded.png" --mode shaded
rc -o "$out/builtin_ao.png" --mode ao --spp 16
rc -o "$out/builtin_path.png" --mode path --spp 256
rc "$root/tests/data/cornell.obj" -o "$out/cornell_path.png" --mode path --spp 512 --eye 0,0,1.7 --fov 40
rc "$models/dragon_200k.obj" -o "$out/dragon_path_sky.png" --mode path --spp 128 \
  --sky 0.45,0.5,0.6:0.12,0.11,0.1 --light dir:-0.5,-1,-0.3:1.2,1.1,1.0
rc "$models/bunny.obj" -o "$out/bunny_shaded_lights.png" --mode shaded \
  --light point:0.6,0.6,0.6:0.8,0.5,0.3 --light point:-0.6,0.4,0.5:0.2,0.3,0.6
