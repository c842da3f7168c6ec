#!/usr/bin/env bash
# Embedding vkrt both documented ways, with examples/embed.c (the README's example, checked
# to be the same text):
#  1. installed: `meson install --destdir` of this build tree, then the example compiled with
#     `pkg-config --static` from the installed vkrt.pc, run, and its PNG checked;
#  2. meson subproject: a throwaway parent project whose subprojects/vkrt links to this source
#     tree, dependency('vkrt', fallback: ['vkrt', 'vkrt_dep']), tests of vkrt and Embree off
#     (whose command line then refuses `bench --compare embree`).
# Usage: test_embed.sh SOURCE_ROOT BUILD_ROOT VKRT_EXE B_SANITIZE
set -u
src=${1:?usage: test_embed.sh SOURCE_ROOT BUILD_ROOT VKRT_EXE B_SANITIZE}
build=${2:?}
vkrt=${3:?}
sanitize=${4:-none}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0
ok() { passed=$((passed + 1)); echo "ok   $1"; }
bad() { failed=$((failed + 1)); echo "FAIL $1"; [ -f "$tmp/log" ] && sed 's/^/     | /' "$tmp/log" | tail -n 40; }

if ! "$vkrt" devices >/dev/null 2>&1; then
  if [ -z "${CI:-}" ]; then echo "skip: no Vulkan device"; exit 77; fi
  echo "FAIL no Vulkan device (CI is set, so this is not a skip)"; exit 1
fi

# The README quotes examples/embed.c whole: the first ```c block after its name.
if python3 - "$src/README.md" "$src/examples/embed.c" <<'PY'
import sys
readme, code = open(sys.argv[1]).read(), open(sys.argv[2]).read()
start = readme.index("```c\n", readme.index("`examples/embed.c`")) + len("```c\n")
sys.exit(readme[start:readme.index("```\n", start)] != code)
PY
then ok "README quotes examples/embed.c exactly"; else bad "README quotes examples/embed.c exactly"; fi

png_size() { python3 -c 'import struct,sys; d=open(sys.argv[1],"rb").read(24); assert d[:8]==b"\x89PNG\r\n\x1a\n"; print("%dx%d"%struct.unpack(">II",d[16:24]))' "$1" 2>/dev/null; }

# run_example NAME EXE: renders to NAME.png with the validation layer on; no validation message,
# a 64x64 PNG.
run_example() {
  local name=$1 exe=$2
  VK_INSTANCE_LAYERS=VK_LAYER_KHRONOS_validation "$exe" "$tmp/$name.png" >"$tmp/log" 2>&1
  local got=$?
  if [ "$got" -ne 0 ]; then bad "$name: example exits $got"; return; fi
  if grep -qiE 'validation (error|warning)|VUID' "$tmp/log"; then bad "$name: validation messages"; return; fi
  if [ "$(png_size "$tmp/$name.png")" != 64x64 ]; then bad "$name: PNG is not 64x64"; return; fi
  ok "$name: example renders a 64x64 PNG"
}

# --- 1. installed, pkg-config ------------------------------------------------------------
dest="$tmp/dest"
if meson install -C "$build" --destdir "$dest" --no-rebuild --quiet >"$tmp/log" 2>&1; then
  ok "meson install --destdir"
else bad "meson install --destdir"; fi
pc=$(find "$dest" -name vkrt.pc | head -n 1)
lib=$(find "$dest" -name libvkrt.a | head -n 1)
if [ -n "$pc" ] && [ -n "$lib" ] && [ -n "$(find "$dest" -name vkrt.h)" ] && [ -x "$(find "$dest" -path '*/bin/vkrt' | head -n 1)" ]; then
  ok "installs libvkrt.a, vkrt.h, vkrt and vkrt.pc"
else bad "installs libvkrt.a, vkrt.h, vkrt and vkrt.pc"; fi
# link_whole put the third-party glue into the archive itself
members=$(ar t "$lib" 2>/dev/null)
if echo "$members" | grep -q cgltf_impl && echo "$members" | grep -q stb_impl && echo "$members" | grep -q tinyobj_shim; then
  ok "libvkrt.a holds the third-party glue objects"
else bad "libvkrt.a holds the third-party glue objects"; fi

if [ -n "$pc" ]; then
  export PKG_CONFIG_PATH="$(dirname "$pc")"
  prefix=$(pkg-config --variable=prefix vkrt)
  pkgflags=$(pkg-config --static --cflags --libs --define-variable=prefix="$dest$prefix" vkrt)
  unset PKG_CONFIG_PATH
  san=()
  [ "$sanitize" != none ] && san=("-fsanitize=$sanitize")
  if cc -std=c11 -Wall -Wextra -pedantic -Werror "${san[@]}" "$src/examples/embed.c" -o "$tmp/embed_installed" \
       $pkgflags >"$tmp/log" 2>&1; then
    ok "embed.c compiles and links with pkg-config --static"
    run_example installed "$tmp/embed_installed"
  else bad "embed.c compiles and links with pkg-config --static"; fi
fi

# --- 2. meson subproject -------------------------------------------------------------------
parent="$tmp/parent"
mkdir -p "$parent/subprojects"
ln -s "$src" "$parent/subprojects/vkrt"
cp "$src/examples/embed.c" "$parent/"
cat >"$parent/meson.build" <<'EOF'
project('parent', 'c', default_options: ['c_std=c11'])
vkrt_dep = dependency('vkrt', fallback: ['vkrt', 'vkrt_dep'], default_options: ['tests=false', 'embree=disabled'])
executable('embed', 'embed.c', dependencies: vkrt_dep)
EOF
if meson setup "$parent/build" "$parent" -Dbuildtype=release --force-fallback-for=vkrt >"$tmp/log" 2>&1 \
   && ninja -C "$parent/build" -j2 embed >>"$tmp/log" 2>&1; then
  ok "subproject: the parent project builds embed.c"
  if grep -q 'tests/test_' "$parent/build/build.ninja"; then bad "subproject: vkrt's tests were configured"; else ok "subproject: vkrt's tests are off"; fi
  run_example subproject "$parent/build/embed"
  # Built without Embree (embree=disabled), the command line refuses the comparison as a usage
  # error that says why.
  if ninja -C "$parent/build" -j2 subprojects/vkrt/vkrt >"$tmp/log" 2>&1; then
    "$parent/build/subprojects/vkrt/vkrt" bench --quick --compare embree >"$tmp/log" 2>&1
    got=$?
    if [ "$got" -eq 2 ] && grep -q 'built without Embree' "$tmp/log"; then ok "without Embree, bench --compare embree is a usage error (exit 2)"
    else bad "without Embree, bench --compare embree is a usage error (exit $got)"; fi
  else bad "subproject: vkrt without Embree builds"; fi
else bad "subproject: the parent project builds embed.c"; fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
