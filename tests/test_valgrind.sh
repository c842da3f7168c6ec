#!/usr/bin/env bash
# valgrind memcheck on CPU-backend runs of the command line (no Vulkan: lavapipe's LLVM code is
# not what is checked): loading an OBJ, an OBJ with an .mtl and a PNG texture, and a glTF with
# two PNG textures, building their BVHs and tracing them; the lighting modes on files with
# emitters, lights, a sky and textures. Any invalid read or write, use of
# uninitialised memory or leak (definite, indirect or possible) fails the test.
set -u
vkrt=${1:?usage: test_valgrind.sh path/to/vkrt}
models=../shared/models
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failed=0
passed=0
# check NAME CODE CMD...: CMD under memcheck exits with CODE (memcheck's own findings exit 99).
check() {
  local name=$1 code=$2
  shift 2
  valgrind --error-exitcode=99 --leak-check=full --show-leak-kinds=definite,indirect,possible \
    --errors-for-leak-kinds=definite,indirect,possible -q "$@" >"$tmp/out" 2>"$tmp/err"
  local got=$?
  if [ $got -eq "$code" ]; then
    passed=$((passed + 1)); echo "ok   $name"
  else
    failed=$((failed + 1)); echo "FAIL $name (exit $got, wanted $code)"; sed 's/^/     | /' "$tmp/err" | head -40
  fi
}
check "render bunny.obj (normal, CPU, 2 threads)" 0 "$vkrt" render "$models/meshes/bunny.obj" --backend cpu --size 48x48 --threads 2 -o "$tmp/a.png"
check "render materials.obj (albedo, .mtl and PNG)" 0 "$vkrt" render tests/data/materials.obj --backend cpu --mode albedo --size 32x32 -o "$tmp/b.png"
check "render a glTF with two PNG textures (albedo)" 0 "$vkrt" render "$models/gltf/draco/three_meshes_two_materials_one_no_material/three_meshes_two_materials_one_no_material.gltf" --backend cpu --mode albedo --size 32x32 -o "$tmp/c.pfm"
check "path-trace the Cornell box (Ke lamp, NEE, MIS, adaptive)" 0 "$vkrt" render tests/data/cornell.obj --backend cpu --mode path --spp 8 --target-error 0.2 --size 24x24 --threads 2 -o "$tmp/e.pfm"
check "shaded and ao with lights, sky and textures" 0 "$vkrt" render tests/data/pbr_textures.gltf --backend cpu --mode shaded --light point:0,1,1:1,1,1 --sky 0.3,0.3,0.3 --size 24x24 -o "$tmp/f.png"
check "ao of the built-in scene" 0 "$vkrt" render --backend cpu --mode ao --spp 2 --size 24x24 -o "$tmp/g.png"
check "info dragon_11k.obj (midpoint)" 0 "$vkrt" info "$models/meshes/dragon_11k.obj" --bvh midpoint
check "a file that fails to load (exit 3)" 3 "$vkrt" render tests/fuzz/regressions/misaligned_indices.glb --backend cpu -o "$tmp/d.png"
echo "$passed passed, $failed failed"
[ $failed -eq 0 ]
