#!/usr/bin/env bash
# The vkrt command line on the Vulkan device with the validation layer on: renders and their
# files, `info` and `devices`, and every kind of bad input answered with a message naming the
# file, the documented exit code and no output file.
set -u
vkrt=${1:?usage: test_cli.sh path/to/vkrt [embree|no-embree]}
embree=${2:-no-embree} # whether the build has Embree (bench --compare embree)
models=../shared/models
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
export VKRT_VALIDATION=1
passed=0
failed=0

ok() { passed=$((passed + 1)); echo "ok   $1"; }
bad() { failed=$((failed + 1)); echo "FAIL $1"; [ -f "$tmp/err" ] && sed 's/^/     | /' "$tmp/err"; }

# expect NAME CODE CMD...: runs CMD, checks its exit code.
expect() {
  local name=$1 code=$2
  shift 2
  "$@" >"$tmp/out" 2>"$tmp/err"
  local got=$?
  if [ "$got" -eq "$code" ]; then ok "$name"; else bad "$name (exit $got, wanted $code)"; fi
}

# bad_input NAME FILE PATTERN: rendering FILE fails with exit 3, a message naming the file and
# matching PATTERN, and no output file.
bad_input() {
  local name=$1 file=$2 pattern=$3
  rm -f "$tmp/never.png"
  "$vkrt" render "$file" -o "$tmp/never.png" --size 16x16 >"$tmp/out" 2>"$tmp/err"
  local got=$?
  if [ "$got" -ne 3 ]; then bad "$name: exit $got, wanted 3"; return; fi
  if ! grep -qF -- "$(basename "$file")" "$tmp/err"; then bad "$name: message does not name the file"; return; fi
  if ! grep -qiE -- "$pattern" "$tmp/err"; then bad "$name: message does not say /$pattern/"; return; fi
  if [ -e "$tmp/never.png" ] || ls "$tmp" | grep -q 'never.png'; then bad "$name: an output file was written"; return; fi
  ok "$name"
}

png_size() { python3 -c 'import struct,sys; d=open(sys.argv[1],"rb").read(24); assert d[:8]==b"\x89PNG\r\n\x1a\n"; print("%dx%d"%struct.unpack(">II",d[16:24]))' "$1"; }

# --- renders -------------------------------------------------------------------------
expect "render the built-in scene" 0 "$vkrt" render -o "$tmp/builtin.png" --size 96x64
if [ -f "$tmp/builtin.png" ] && [ "$(png_size "$tmp/builtin.png")" = "96x64" ]; then ok "built-in PNG is 96x64"; else bad "built-in PNG is 96x64"; fi

for mode in normal depth heatmap id albedo uv; do
  expect "render bunny --mode $mode" 0 "$vkrt" render "$models/meshes/bunny.obj" --mode "$mode" -o "$tmp/bunny_$mode.png" --size 48x48
done
# --- lighting modes --------------------------------------------------------------------
for mode in shaded ao path; do
  expect "render --mode $mode" 0 "$vkrt" render --mode "$mode" --spp 2 -o "$tmp/light_$mode.png" --size 32x24
done
expect "path with lights, sky, seed and adaptive sampling" 0 "$vkrt" render "$models/meshes/bunny.obj" --mode path \
  --light dir:-1,-2,-1:2,2,2 --light point:0.5,0.8,0.8:1,0.9,0.8 --sky 0.5,0.6,0.8:0.1,0.1,0.1 --spp 16 \
  --target-error 0.1 --bounces 4 --seed 7 -o "$tmp/lit.pfm" --size 24x24
if grep -qE "samples per pixel, [0-9]+ shadow rays, [0-9]+ bounce rays, 2 lights" "$tmp/err"; then ok "lighting render reports samples, rays and lights"
else bad "lighting render reports samples, rays and lights"; fi
# The same seed on the two backends: the same sample counts, and pixels that agree.
"$vkrt" render --mode ao --spp 4 -o "$tmp/ao_gpu.pfm" --size 24x16 >"$tmp/out" 2>"$tmp/err"
gpu_line=$(grep "samples per pixel" "$tmp/err")
"$vkrt" render --mode ao --spp 4 --backend cpu -o "$tmp/ao_cpu.pfm" --size 24x16 >"$tmp/out" 2>"$tmp/err"
cpu_line=$(grep "samples per pixel" "$tmp/err")
if [ -n "$gpu_line" ] && [ "$gpu_line" = "$cpu_line" ] && python3 - "$tmp/ao_gpu.pfm" "$tmp/ao_cpu.pfm" <<'PY'
import struct, sys
def read(p):
    f = open(p, "rb"); f.readline(); w, h = map(int, f.readline().split()); f.readline()
    return struct.unpack("<%df" % (w * h * 3), f.read())
a, b = read(sys.argv[1]), read(sys.argv[2])
sys.exit(0 if len(a) == len(b) and max(abs(x - y) for x, y in zip(a, b)) < 1e-4 else 1)
PY
then ok "ao on GPU and CPU: same samples and pixels"; else bad "ao on GPU and CPU: same samples and pixels ('$gpu_line' / '$cpu_line')"; fi
"$vkrt" render --mode shaded -v -o "$tmp/v.png" --size 16x16 >"$tmp/out" 2>"$tmp/err"
if grep -q "skipped: textures (no material has a texture)" "$tmp/err" && grep -q "skipped: random numbers" "$tmp/err" &&
   grep -q "compiled in: point and directional lights" "$tmp/err"; then ok "--verbose reports what was skipped and why"
else bad "--verbose reports what was skipped and why"; fi
"$vkrt" info tests/data/cornell.obj >"$tmp/out" 2>"$tmp/err"
if grep -q "lights        0 point or directional from the file, 2 emissive triangles" "$tmp/out"; then ok "info counts the Cornell box's emissive triangles"
else bad "info counts the Cornell box's emissive triangles"; fi
"$vkrt" info tests/data/lights.gltf >"$tmp/out" 2>"$tmp/err"
if grep -q "lights        3 point or directional from the file, 0 emissive triangles" "$tmp/out"; then ok "info counts a glTF's punctual lights"
else bad "info counts a glTF's punctual lights"; fi
"$vkrt" bench --modes --quick --max-spp 16 --backend cpu --cache "" --csv "$tmp/ladder.csv" >"$tmp/out" 2>"$tmp/err"
if python3 - "$tmp/ladder.csv" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
fixed = sorted({int(r["spp"]) for r in rows if float(r["target_error"] or 0) == 0})
sys.exit(0 if fixed == [1, 4, 16] and all(r["backend"] == "cpu" for r in rows) else 1)
PY
then ok "bench --modes --max-spp 16: the ladder 1, 4, 16"; else bad "bench --modes --max-spp 16: the ladder 1, 4, 16"; fi
"$vkrt" bench --modes --size 16x16 --repeat 1 --max-spp 16 --ref-spp 64 --backend cpu --cache "" --csv "$tmp/skips.csv" >"$tmp/out" 2>"$tmp/err"
if python3 - "$tmp/skips.csv" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
single = [r for r in rows if r["features"].startswith("+")]
spec = {(r["mode"], r["spp"]): r for r in rows if r["features"] == "specialised" and float(r["target_error"] or 0) == 0}
# Every single-feature row is a feature the specialised render left out, at the same spp.
for r in single:
    base = spec[(r["mode"], r["spp"])]
    name = r["features"][1:]
    assert int(r["feature_bits"]) & ~int(base["feature_bits"]), r
assert {r["mode"] for r in single} == {"shaded", "ao", "path"}, single
assert any(r["features"] == "+random" and r["mode"] == "shaded" for r in single)
PY
then ok "bench --modes: a row for each skip on its own"; else bad "bench --modes: a row for each skip on its own"; fi
# A PNG with an empty IDAT chunk before its data (legal, and once undefined behaviour inside
# stb_image) decodes to the same texture as the original.
mkdir -p "$tmp/idat"
cp tests/data/materials.obj tests/data/materials.mtl "$tmp/idat/"
python3 - tests/data/checker2x2.png "$tmp/idat/checker2x2.png" <<'PY'
import struct, sys, zlib
d = open(sys.argv[1], "rb").read()
i = d.index(b"IDAT") - 4
empty = struct.pack(">I", 0) + b"IDAT" + struct.pack(">I", zlib.crc32(b"IDAT"))
open(sys.argv[2], "wb").write(d[:i] + empty + d[i:])
PY
"$vkrt" render tests/data/materials.obj --mode albedo --backend cpu --size 16x16 -o "$tmp/idat_ref.pfm" >"$tmp/out" 2>"$tmp/err"
"$vkrt" render "$tmp/idat/materials.obj" --mode albedo --backend cpu --size 16x16 -o "$tmp/idat.pfm" >"$tmp/out" 2>"$tmp/err"
if ! grep -q "cannot be read" "$tmp/err" && cmp -s "$tmp/idat_ref.pfm" "$tmp/idat.pfm"; then ok "a PNG with an empty IDAT chunk decodes like the original"
else bad "a PNG with an empty IDAT chunk decodes like the original"; fi
expect "bad --light" 2 "$vkrt" render --mode shaded --light spot:0,1,0:1,1,1 -o "$tmp/x.png" --size 8x8
expect "negative --light colour" 2 "$vkrt" render --mode shaded --light point:0,1,0:-1,1,1 -o "$tmp/x.png" --size 8x8
expect "bad --sky" 2 "$vkrt" render --mode path --sky 1,1 -o "$tmp/x.png" --size 8x8
expect "bad --spp" 2 "$vkrt" render --mode path --spp 0 -o "$tmp/x.png" --size 8x8
expect "bad --target-error" 2 "$vkrt" render --mode path --target-error -1 -o "$tmp/x.png" --size 8x8
expect "directional light of zero direction" 2 "$vkrt" render --mode shaded --light dir:0,0,0:1,1,1 -o "$tmp/zero.png" --size 8x8
[ ! -e "$tmp/zero.png" ] && ok "no file for a refused light" || bad "no file for a refused light"

expect "render heatmap of leaves with the midpoint BVH" 0 "$vkrt" render "$models/meshes/bunny.obj" --mode heatmap --heat leaves --bvh midpoint -o "$tmp/heat.png" --size 32x32
# --counters: per-ray traversal work, the same on both backends for this small render
"$vkrt" render "$models/meshes/bunny.obj" --counters -o "$tmp/c.png" --size 32x32 >"$tmp/out" 2>"$tmp/err"
gpu_line=$(grep "per ray:" "$tmp/err")
"$vkrt" render "$models/meshes/bunny.obj" --counters --backend cpu -o "$tmp/c.png" --size 32x32 >"$tmp/out" 2>"$tmp/err"
cpu_line=$(grep "per ray:" "$tmp/err")
if echo "$gpu_line" | grep -qE "per ray: [0-9.]+ boxes entered, [0-9.]+ leaves entered, [0-9.]+ triangle tests" &&
   [ "$gpu_line" = "$cpu_line" ]; then ok "--counters prints per-ray work, equal on GPU and CPU"
else bad "--counters prints per-ray work, equal on GPU and CPU ('$gpu_line' / '$cpu_line')"; fi
# A render's camera rays take the binned traversal on a CPU device (README, "Binned traversal"),
# and -v -v says so; the counters keep to the BVH. A real GPU never bins.
"$vkrt" render "$models/meshes/dragon_11k.obj" -v -v -o "$tmp/binned.png" --size 160x120 >"$tmp/out" 2>"$tmp/err"
"$vkrt" render "$models/meshes/dragon_11k.obj" -v -v --counters -o "$tmp/bvh.png" --size 160x120 >"$tmp/out" 2>"$tmp/err2"
if grep -q " on llvmpipe" "$tmp/err"; then want_binned=1; else want_binned=0; fi
if [ "$(grep -c "traversal: binned.*: [1-9][0-9]* triangle tests, [0-9.]* a ray" "$tmp/err")" = "$want_binned" ] &&
   ! grep -q "traversal: binned" "$tmp/err2" && cmp -s "$tmp/binned.png" "$tmp/bvh.png"; then
  ok "render -v -v names the binned traversal where it ran, with its tests, the same image"
else bad "render -v -v names the binned traversal where it ran, with its tests, the same image"; fi
# bench --quick: a row per configuration in the table and a well-formed CSV with finite figures
# (at 32x32: its naive rows test every pixel against every triangle, a few seconds at 64x64)
expect "bench --quick --csv" 0 "$vkrt" bench --quick --size 32x32 --csv "$tmp/bench.csv"
if python3 - "$tmp/bench.csv" "$tmp/out" <<'PY'
import csv, math, sys
rows = list(csv.DictReader(open(sys.argv[1])))
table = [l for l in open(sys.argv[2]) if l.startswith("| ") and not l.startswith("| builder")]
assert len(rows) == len(table) == 24, (len(rows), len(table))
seen = {(r["builder"], r["backend"], r["traversal"], r["intersector"], r["precision"]) for r in rows}
assert len(seen) == 24, seen
sah_cost = {float(r["sah_cost"]) for r in rows if r["builder"] == "sah"}
assert len(sah_cost) == 1 and all(float(r["sah_cost"]) <= min(sah_cost) for r in rows if r["builder"] == "sbvh"), rows
for r in rows:
    for k in ("build_ms", "sah_cost", "bytes_per_triangle", "trace_ms", "total_ms", "mrays_per_s", "boxes_per_ray",
              "tests_per_ray", "depth_rel_rmse", "depth_rel_max"):
        v = float(r[k])
        assert math.isfinite(v) and v >= 0, (k, r[k])
    assert float(r["trace_ms"]) > 0 and float(r["mrays_per_s"]) > 0 and int(r["mismatched_pixels"]) >= 0
    assert r["binned"] == "0", r  # 32x32: too few rays for the binned traversal's lists
    if r["traversal"] == "naive":
        assert float(r["tests_per_ray"]) == float(r["triangles"]) and float(r["boxes_per_ray"]) == 0, r
    else:
        assert 0 < float(r["boxes_per_ray"]) < 200, r
    if r["precision"] == "double" and r["intersector"] == "watertight" and r["builder"] == "sah":
        assert int(r["mismatched_pixels"]) == 0 and float(r["depth_rel_max"]) == 0, r  # the reference itself
PY
then ok "bench CSV: 24 configurations, finite figures, the reference row exact"; else bad "bench CSV: 24 configurations, finite figures, the reference row exact"; fi
expect "bench with a FILE that does not exist fails as input" 3 "$vkrt" bench "$tmp/missing.obj" --quick
expect "bench --compare with an unknown engine is a usage error" 2 "$vkrt" bench --quick --compare nothing
# bench --modes: the lighting modes against converged references kept in a cache; a second run
# reads them back and measures the same errors. Errors finite (PSNR infinite only where the
# image is exact), timings unchecked.
expect "bench --quick --modes --csv" 0 "$vkrt" bench --quick --modes --cache "$tmp/refs" --csv "$tmp/modes.csv"
cp "$tmp/out" "$tmp/modes.md"
expect "bench --quick --modes from the cache" 0 "$vkrt" bench --quick --modes --backend cpu --cache "$tmp/refs" \
  --csv "$tmp/modes_cpu.csv"
if python3 - "$tmp/modes.csv" "$tmp/modes.md" "$tmp/modes_cpu.csv" "$tmp/out" "$tmp/refs" <<'PY'
import csv, math, os, sys
rows = list(csv.DictReader(open(sys.argv[1])))
table = [l for l in open(sys.argv[2]) if l.startswith("| ") and not l.startswith("| mode")]
# per mode and backend: spp 1 and 4, two adaptive targets, every feature compiled in
assert len(rows) == len(table) == 3 * 2 * 5, (len(rows), len(table))
keys = {(r["mode"], r["backend"], r["spp"], r["target_error"], r["features"]) for r in rows}
assert len(keys) == 30, keys
for r in rows:
    for k in ("trace_ms", "total_ms", "mrays_per_s", "spp_taken", "rmse", "rel_mse", "reference_noise"):
        v = float(r[k])
        assert math.isfinite(v) and v >= 0, (k, r)
    assert float(r["trace_ms"]) > 0 and int(r["reference_spp"]) == 256, r
    psnr = float(r["psnr_db"])
    assert (math.isinf(psnr) and float(r["rmse"]) == 0) or (math.isfinite(psnr) and psnr > 0), r
    assert 1 <= float(r["spp_taken"]) <= int(r["spp"]), r
    if r["mode"] != "shaded":  # shaded under the default rig is exact at one sample
        assert 0 < float(r["rmse"]) < 0.5, r
# more samples, less error: each backend's 4 spp row beats its 1 spp row
err = {(r["mode"], r["backend"], r["spp"]): float(r["rmse"]) for r in rows if r["features"] == "specialised"
       and float(r["target_error"]) == 0}
for mode in ("ao", "path"):
    for b in ("gpu", "cpu"):
        assert err[(mode, b, "4")] < err[(mode, b, "1")], (mode, b, err)
# the second run read all three references from the cache and measured the same errors
header = open(sys.argv[4]).read()
assert header.count("read from the cache") == 3, header
assert len([f for f in os.listdir(sys.argv[5]) if f.startswith("ref-")]) == 3, os.listdir(sys.argv[5])
again = {(r["mode"], r["spp"], r["target_error"], r["features"]): r["rmse"] for r in csv.DictReader(open(sys.argv[3]))}
for r in rows:
    if r["backend"] == "cpu":
        assert again[(r["mode"], r["spp"], r["target_error"], r["features"])] == r["rmse"], r
PY
then ok "bench --modes CSV: 30 rows, finite errors falling with spp, references cached"
else bad "bench --modes CSV: 30 rows, finite errors falling with spp, references cached"; fi
# bench --procedural N: the scaling series' scene, named by its exact triangle count
expect "bench --quick --procedural" 0 "$vkrt" bench --quick --procedural 2000 --backend cpu --csv "$tmp/proc.csv"
if python3 - "$tmp/proc.csv" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert rows and all(r["scene"] == "procedural-" + r["triangles"] for r in rows), rows[0]
assert abs(int(rows[0]["triangles"]) - 2000) < 200 and all(int(r["mismatched_pixels"]) == 0 for r in rows), rows
assert all(r["backend"] == "cpu" for r in rows), [r["backend"] for r in rows]
PY
then ok "bench --procedural: about N triangles, named by the count, no mismatched pixel, CPU rows only"
else bad "bench --procedural: about N triangles, named by the count, no mismatched pixel, CPU rows only"; fi
# The GPU holds one builder's scene at a time: 1e5 triangles take about 9.7 MiB on the device
# with the SAH BVH and 12.2 MiB with the midpoint one, the context's own buffers some 8 MiB more
# (20 MiB fail the midpoint scene), so 25 MiB hold any one but not two (two at once once
# overflowed lavapipe's 2 GiB heap at 1e7 triangles, and the bench failed).
expect "bench --device-memory 25 holds one GPU scene at a time" 0 "$vkrt" bench --quick --procedural 100000 \
  --backend gpu --device-memory 25 --csv "$tmp/one_scene.csv"
if python3 - "$tmp/one_scene.csv" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
gpu = {r["builder"] for r in rows if r["backend"] == "gpu"}
assert gpu == {"sah", "midpoint", "sbvh"}, gpu
assert all(r["backend"] == "gpu" for r in rows), [r["backend"] for r in rows]
PY
then ok "bench --device-memory 25: every builder's GPU rows, and (--backend gpu) no CPU row"
else bad "bench --device-memory 25: every builder's GPU rows, and (--backend gpu) no CPU row"; fi
# A scene beyond the device's memory skips the GPU rows with a note (40,000 triangles' traversal
# arrays in 1 MiB); so does a scene that fits where its renders' arrays do not (20,000
# triangles' do, and then a normal render's 64-byte shading triangles do not); the CPU rows still
# run (at 16x16, where naive traversal is cheap).
for tris in 40000 20000; do
  expect "bench --device-memory 1 skips the GPU ($tris triangles)" 0 "$vkrt" bench --quick --procedural $tris \
    --device-memory 1 --size 16x16 --csv "$tmp/no_gpu.csv"
  why="out of device memory: vkrt BVH nodes needs"
  [ $tris = 20000 ] && why="out of device memory: vkrt triangles needs"
  if grep -q "the GPU backend was not run: $why" "$tmp/out" && ! grep -q ",gpu," "$tmp/no_gpu.csv" &&
    grep -q ",cpu," "$tmp/no_gpu.csv"; then ok "bench --device-memory 1 ($tris triangles): a note, CPU rows only"
  else bad "bench --device-memory 1 ($tris triangles): a note, CPU rows only"; fi
done
expect "render --device-memory 0 is a usage error" 2 "$vkrt" render --device-memory 0
rm -f "$tmp/small.png"
expect "render --device-memory 1 is out of device memory" 4 "$vkrt" render --device-memory 1 --size 16x16 -o "$tmp/small.png"
if grep -q "out of device memory: .* 1048576-byte budget" "$tmp/err" && [ ! -e "$tmp/small.png" ]; then
  ok "render --device-memory 1: says so, writes no image"
else bad "render --device-memory 1: says so, writes no image"; fi
expect "bench --procedural with a FILE is a usage error" 2 "$vkrt" bench "$models/meshes/bunny.obj" --procedural 2000
expect "bench --modes with --compare is a usage error" 2 "$vkrt" bench --quick --modes --compare embree
expect "bench --ref-spp 0 is a usage error" 2 "$vkrt" bench --quick --modes --ref-spp 0
# bench --compare embree: the same rays through Embree and vkrt's backends, every query; the
# checksums agree and (nearly) every ray gets the same answer. Timings are not checked beyond
# being positive and finite; --repeat 3 times three builds of each engine, in turn.
if [ "$embree" = embree ]; then
  expect "bench --quick --compare embree --repeat 3 --csv" 0 "$vkrt" bench --quick --compare embree --repeat 3 \
    --csv "$tmp/embree.csv"
  if python3 - "$tmp/embree.csv" "$tmp/out" <<'PY'
import csv, math, sys
rows = list(csv.DictReader(open(sys.argv[1])))
table = [l for l in open(sys.argv[2]) if l.startswith("| ") and not l.startswith("| rays")]
assert len(rows) == len(table) == 9, (len(rows), len(table))
assert {(r["rays"], r["query"], r["engine"]) for r in rows} == \
    {(s, q, e) for s, q in (("primary", "closest"), ("ao", "closest"), ("ao", "any"))
     for e in ("embree", "vkrt-cpu", "vkrt-gpu")}, rows
ref = {(r["rays"], r["query"]): r for r in rows if r["engine"] == "embree"}
for r in rows:
    for k in ("build_ms", "bytes_per_triangle", "trace_ms", "mrays_per_s", "ratio_to_embree", "t_rel_max"):
        v = float(r[k])
        assert math.isfinite(v) and v >= 0, (k, r)
    assert float(r["trace_ms"]) > 0 and float(r["bytes_per_triangle"]) > 0 and float(r["build_ms"]) > 0, r
    e = ref[(r["rays"], r["query"])]
    n, hits = int(r["ray_count"]), int(r["hits"])
    assert n == int(e["ray_count"]) and n > 0, r
    assert abs(hits - int(e["hits"])) <= 2 + n // 1000, (r, e)
    assert int(r["mismatches"]) <= 2 + n // 1000, r
    if r["query"] == "closest":
        assert abs(float(r["sum_t"]) - float(e["sum_t"])) <= 1e-4 * float(e["sum_t"]), (r, e)
        assert float(r["t_rel_max"]) < 1e-2, r
    else:
        assert r["sum_t"] == "", r
    if r["engine"] == "embree":
        assert float(r["ratio_to_embree"]) == 1 and int(r["mismatches"]) == 0, r
    # The GPU's device time is part of each call's wall-clock time (lavapipe has timestamps).
    if r["engine"] == "vkrt-gpu":
        assert 0 < float(r["device_ms"]) <= float(r["trace_ms"]), r
    else:
        assert r["device_ms"] == "", r
primary = ref[("primary", "closest")]
assert int(primary["ray_count"]) == 64 * 64 and int(ref[("ao", "closest")]["ray_count"]) == 4 * int(primary["hits"])
PY
  then ok "bench --compare embree CSV: 9 rows, Embree's checksums met by both backends, the GPU's device time within its calls"
  else bad "bench --compare embree CSV: 9 rows, Embree's checksums met by both backends, the GPU's device time within its calls"; fi
  if grep -Eq "vkrt's CPU backend \((x86-64-v3|baseline) code\) on [0-9]+ threads?" "$tmp/out"
  then ok "bench --compare embree names the CPU backend's machine code"
  else bad "bench --compare embree names the CPU backend's machine code"; fi
else
  "$vkrt" bench --quick --compare embree >"$tmp/out" 2>"$tmp/err"
  got=$?
  if [ "$got" -eq 2 ] && grep -q 'built without Embree' "$tmp/err"; then ok "bench --compare embree without Embree: a usage error"
  else bad "bench --compare embree without Embree: a usage error (exit $got)"; fi
fi
expect "render glb with camera flags" 0 "$vkrt" render "$models/gltf/draco/Box/Box.glb" --eye 1,1,1.5 --target 0,0,0 --up 0,1,0 --fov 60 -o "$tmp/box.ppm" --size 32x24
if head -c 2 "$tmp/box.ppm" 2>/dev/null | grep -q P6; then ok "PPM output"; else bad "PPM output"; fi

# id PFM from both backends: identical ids on (nearly) every pixel
expect "render id PFM on the GPU" 0 "$vkrt" render "$models/meshes/teapot.obj" --mode id -o "$tmp/gpu.pfm" --size 40x40
expect "render id PFM on the CPU" 0 "$vkrt" render "$models/meshes/teapot.obj" --mode id -o "$tmp/cpu.pfm" --size 40x40 --backend cpu
if python3 - "$tmp/gpu.pfm" "$tmp/cpu.pfm" <<'PY'
import struct, sys
def load(p):
    d = open(p, "rb").read()
    head = d.split(b"\n", 3)
    assert head[0] == b"PF"
    w, h = map(int, head[1].split())
    px = struct.unpack("<%df" % (w * h * 3), head[3][: w * h * 12])
    return w, h, px[0::3]
wa, ha, a = load(sys.argv[1]); wb, hb, b = load(sys.argv[2])
assert (wa, ha) == (wb, hb) == (40, 40)
same = sum(x == y for x, y in zip(a, b))
assert same >= 0.999 * len(a) - 1, same
assert any(x >= 0 for x in a) and any(x == -1 for x in a)
PY
then ok "GPU and CPU id PFMs agree"; else bad "GPU and CPU id PFMs agree"; fi

# .hdr: Radiance RGBE of the raw values (negatives as 0), equal to the PFM's floats within
# RGBE's 8-bit shared mantissa; a width of 40 is written run-length encoded.
expect "render depth .hdr" 0 "$vkrt" render --mode depth --backend cpu -o "$tmp/depth.hdr" --size 40x30
expect "render depth .pfm" 0 "$vkrt" render --mode depth --backend cpu -o "$tmp/depth.pfm" --size 40x30
if python3 - "$tmp/depth.hdr" "$tmp/depth.pfm" <<'PY'
import struct, sys
d = open(sys.argv[1], "rb").read()
head = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 30 +X 40\n"
assert d.startswith(head), d[:60]
w, h, pos, rows = 40, 30, len(head), []
for y in range(h):
    assert d[pos:pos + 4] == bytes([2, 2, 0, w]), (y, d[pos:pos + 4])
    pos += 4
    comps = []
    for k in range(4):
        c = b""
        while len(c) < w:
            n = d[pos]; pos += 1
            if n > 128:
                c += bytes([d[pos]]) * (n - 128); pos += 1
            else:
                c += d[pos:pos + n]; pos += n
        comps.append(c)
    rows.append(comps)
assert pos == len(d), (pos, len(d))  # exactly the header and 30 rows of 40 pixels
p = open(sys.argv[2], "rb").read().split(b"\n", 3)
pfm = struct.unpack("<%df" % (w * h * 3), p[3][: w * h * 12])
hits = 0
for y in range(h):
    r, g, b, e = rows[y]
    for x in range(w):
        want = max(pfm[((h - 1 - y) * w + x) * 3], 0.0)  # PFM rows are bottom to top
        got = 0.0 if e[x] == 0 else (r[x] + 0.5) * 2.0 ** (e[x] - 136)
        assert abs(got - want) <= want / 128 + 1e-30, (x, y, got, want)
        hits += want > 0
assert 0 < hits < w * h, hits
PY
then ok ".hdr header, size and values match the PFM"; else bad ".hdr header, size and values match the PFM"; fi

# --- per-command help -----------------------------------------------------------------
for cmd in render info devices bench stress; do
  "$vkrt" "$cmd" --help >"$tmp/help" 2>"$tmp/err"
  got=$?
  if [ "$got" -eq 0 ] && grep -q "^usage: vkrt $cmd" "$tmp/help" && grep -q '^examples:' "$tmp/help" \
     && grep -qE "^  vkrt $cmd( |\$)" "$tmp/help" && grep -q '^exit codes' "$tmp/help"; then
    ok "$cmd --help: usage, examples, exit codes"
  else bad "$cmd --help (exit $got)"; fi
done
"$vkrt" --help >"$tmp/help" 2>&1
if grep -q 'render --help' "$tmp/help" && ! grep -q -- '--heat-max' "$tmp/help"; then ok "vkrt --help is the overview"; else bad "vkrt --help is the overview"; fi

# --- progress bar: over a second of work, on a terminal only ---------------------------------
# A single-threaded naive render takes a few seconds; script(1) gives it a terminal.
slow=("$vkrt" render "$models/meshes/bunny.obj" --backend cpu --threads 1 --traverse naive --size 256x256 -o "$tmp/slow.png")
if command -v script >/dev/null; then
  env -u CI script -qec "$(printf '%q ' "${slow[@]}")" /dev/null >"$tmp/tty" 2>&1
  if grep -q 'ETA' "$tmp/tty" && grep -q '100%' "$tmp/tty" && grep -q "$(printf '\r\033\\[K')vkrt: " "$tmp/tty"; then
    ok "progress bar with ETA on a terminal, cleared before the summary"
  else bad "progress bar with ETA on a terminal"; cat -v "$tmp/tty" | tail -c 600; fi
  CI=1 script -qec "$(printf '%q ' "${slow[@]}")" /dev/null >"$tmp/tty" 2>&1
  if grep -q 'vkrt: ' "$tmp/tty" && ! grep -q 'ETA' "$tmp/tty"; then ok "no progress bar with CI set"; else bad "no progress bar with CI set"; fi
else
  echo "skip progress bar on a terminal: no script(1)"
fi
env -u CI "${slow[@]}" >"$tmp/out" 2>"$tmp/err"
if grep -q 'vkrt: ' "$tmp/err" && ! grep -q "$(printf '\r')" "$tmp/err"; then ok "no progress bar in a pipe"; else bad "no progress bar in a pipe"; fi

# --- info and devices ------------------------------------------------------------------
"$vkrt" info "$models/meshes/bunny.obj" >"$tmp/info" 2>"$tmp/err"
if grep -qE '^triangles +3674$' "$tmp/info" && grep -q '^sah cost' "$tmp/info" && grep -q '^leaf sizes' "$tmp/info" \
   && grep -q '^build' "$tmp/info" && grep -q '^bytes' "$tmp/info" && grep -q '^depth' "$tmp/info"; then
  ok "info prints triangles, depth, SAH cost, leaf sizes, build time, bytes"
else bad "info output"; cat "$tmp/info"; fi
if grep -qE '^memory +host [0-9.]+ bytes per triangle; device' "$tmp/info" && ! grep -q '^device ' "$tmp/info"; then
  ok "info prints host and device memory per triangle, no device line on the CPU"
else bad "info memory line"; cat "$tmp/info"; fi
"$vkrt" info "$models/meshes/bunny.obj" --backend gpu --validation >"$tmp/info_gpu" 2>"$tmp/err"
# The bunny through the wide BVH holds its binary arrays on the host until a mode reads them.
if grep -qE '^device +[0-9]+ bytes on .*: the wide BVH alone, [0-9.]+ per triangle more once a mode reads the binary nodes and triangles$' "$tmp/info_gpu" \
   && grep -qE '^memory +host [0-9.]+ bytes per triangle; device [0-9.]+, [0-9.]+ more once a mode reads the surfaces$' "$tmp/info_gpu"; then
  ok "info --backend gpu measures the device memory"
else bad "info --backend gpu"; cat "$tmp/info_gpu" "$tmp/err"; fi
# --bvh sbvh: the spatial-split builder; info shows its triangle copies, and the GPU renders
# with it the image the SAH BVH gives
"$vkrt" info "$models/meshes/homer_10k.obj" --bvh sbvh >"$tmp/info_sbvh" 2>"$tmp/err"
sah_cost() { sed -nE 's/^sah cost +([0-9.]+) .*/\1/p' "$1"; }
"$vkrt" info "$models/meshes/homer_10k.obj" >"$tmp/info_sah" 2>"$tmp/err"
if grep -qE '^builder +sbvh$' "$tmp/info_sbvh" && grep -qE '^triangles +9856$' "$tmp/info_sbvh" \
   && grep -qE '^references +[0-9]+ \(spatial splits: [0-9.]+% more than the triangles\)$' "$tmp/info_sbvh" \
   && ! grep -q '^references' "$tmp/info_sah" \
   && awk -v a="$(sah_cost "$tmp/info_sbvh")" -v b="$(sah_cost "$tmp/info_sah")" 'BEGIN { exit !(a < b) }'; then
  ok "info --bvh sbvh shows the references and a lower SAH cost than sah"
else bad "info --bvh sbvh"; cat "$tmp/info_sbvh" "$tmp/info_sah"; fi
"$vkrt" render "$models/meshes/homer_10k.obj" --bvh sbvh --mode depth -o "$tmp/sbvh.pfm" --size 48x48 2>"$tmp/err"
"$vkrt" render "$models/meshes/homer_10k.obj" --mode depth -o "$tmp/sah.pfm" --size 48x48 2>>"$tmp/err"
if [ -s "$tmp/sbvh.pfm" ] && cmp -s "$tmp/sbvh.pfm" "$tmp/sah.pfm"; then ok "render --bvh sbvh gives the SAH BVH's depth image"
else bad "render --bvh sbvh"; cat "$tmp/err"; fi
expect "unknown --bvh" 2 "$vkrt" info "$models/meshes/bunny.obj" --bvh sbvh2
"$vkrt" devices >"$tmp/devices" 2>"$tmp/err"
if grep -qE '^0: ' "$tmp/devices"; then ok "devices lists a device"; else bad "devices lists a device"; fi
expect "render on --device 0" 0 "$vkrt" render --device 0 -o "$tmp/d0.png" --size 16x16
expect "--device out of range" 4 "$vkrt" render --device 99 -o "$tmp/d99.png" --size 16x16
[ ! -e "$tmp/d99.png" ] && ok "no file after a device error" || bad "no file after a device error"

# no Vulkan device at all (the loader finds no driver): a device error, no file; the CPU
# backend needs no Vulkan and still renders
VK_ICD_FILENAMES=/nonexistent/icd.json VK_DRIVER_FILES=/nonexistent/icd.json \
  "$vkrt" render -o "$tmp/nodev.png" --size 8x8 >"$tmp/out" 2>"$tmp/err"
got=$?
if [ "$got" -eq 4 ] && grep -qiE 'no vulkan (driver|device)' "$tmp/err" && [ ! -e "$tmp/nodev.png" ]; then
  ok "no Vulkan driver: exit 4, a clear message, no file"
else bad "no Vulkan driver: exit $got"; fi
expect "no Vulkan driver: the CPU backend still renders" 0 env VK_ICD_FILENAMES=/nonexistent/icd.json \
  VK_DRIVER_FILES=/nonexistent/icd.json "$vkrt" render --backend cpu -o "$tmp/cpu_nodev.png" --size 8x8

# --- usage errors -------------------------------------------------------------------------
expect "--help" 0 "$vkrt" render --help
expect "unknown option" 2 "$vkrt" render --frobnicate
expect "unknown mode" 2 "$vkrt" render --mode sepia
expect "bad size" 2 "$vkrt" render --size 0x10
expect "bad fov" 2 "$vkrt" render --fov 180
expect "--eye and --target at one point" 2 "$vkrt" render --eye 1,2,3 --target 1,2,3 -o "$tmp/same_point.png" --size 8x8
grep -q "same point (1,2,3)" "$tmp/err" && ok "the message names the point" || bad "the message names the point"
expect "--eye at the default target" 2 "$vkrt" render --eye 0,0,0 -o "$tmp/same_point.png" --size 8x8
expect "--up of zero length" 2 "$vkrt" render --up 0,-0,0 -o "$tmp/same_point.png" --size 8x8
expect "--target at the default eye" 2 "$vkrt" render --target 0,0,1.5 -o "$tmp/same_point.png" --size 8x8
[ ! -e "$tmp/same_point.png" ] && ok "no file for a view without direction" || bad "no file for a view without direction"
# --target alone keeps --help's default eye (0, 0, 1.5); it used to look from the origin.
"$vkrt" render --backend cpu --target 0.2,0,0 -o "$tmp/target_only.pfm" --size 16x16 -q &&
  "$vkrt" render --backend cpu --eye 0,0,1.5 --target 0.2,0,0 -o "$tmp/target_eye.pfm" --size 16x16 -q &&
  cmp -s "$tmp/target_only.pfm" "$tmp/target_eye.pfm" && ok "--target alone looks from the default eye" ||
  bad "--target alone looks from the default eye"
expect "unknown command" 2 "$vkrt" paint
expect "unknown output format" 2 "$vkrt" render -o "$tmp/out.bmp" --size 8x8
[ ! -e "$tmp/out.bmp" ] && ok "no file for an unknown format" || bad "no file for an unknown format"

# --- bad inputs -------------------------------------------------------------------------
bad_input "missing file" "$tmp/does_not_exist.obj" "no such file|cannot open|not found"
head -c 4096 /dev/urandom >"$tmp/garbage.obj"
printf '\x00\x01\x02' >>"$tmp/garbage.obj"
bad_input "garbage bytes" "$tmp/garbage.obj" "not an obj|binary|malformed|parse|invalid"
head -c 4096 /dev/urandom >"$tmp/garbage.glb"
bad_input "garbage glb" "$tmp/garbage.glb" "gltf|glb|malformed|parse|invalid"
printf '# nothing here\nv 0 0 0\nv 1 0 0\n' >"$tmp/empty.obj"
bad_input "empty mesh" "$tmp/empty.obj" "no triangles|empty"
printf 'v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n' >"$tmp/nan.obj"
bad_input "NaN coordinate" "$tmp/nan.obj" "nan|finite"
printf 'v 3e38 0 0\nv -3e38 0 0\nv 0 1 0\nf 1 2 3\n' >"$tmp/huge.obj"
bad_input "coordinates whose extent overflows float" "$tmp/huge.obj" "float range"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n' >"$tmp/index.obj"
bad_input "index out of range" "$tmp/index.obj" "index|range"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2 3\np 1\n' >"$tmp/lines.obj"
bad_input "only points and lines" "$tmp/lines.obj" "points|lines"
bad_input "glTF requiring an unsupported extension" tests/data/draco_required.gltf "KHR_draco_mesh_compression"
cp "$models/gltf/assimp/Mesh_PrimitiveMode/Mesh_PrimitiveMode_00.gltf" "$models/gltf/assimp/Mesh_PrimitiveMode/Mesh_PrimitiveMode_00.bin" "$tmp/"
bad_input "glTF with only points" "$tmp/Mesh_PrimitiveMode_00.gltf" "points|lines|no triangles"

# an existing output is not replaced by a failed render
echo keep >"$tmp/keep.png"
"$vkrt" render "$tmp/nan.obj" -o "$tmp/keep.png" --size 8x8 >/dev/null 2>&1
[ "$(cat "$tmp/keep.png")" = keep ] && ok "failed render keeps an existing output" || bad "failed render keeps an existing output"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
