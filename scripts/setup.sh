#!/usr/bin/env bash
# Installs everything vkrt needs on a fresh Debian (bookworm) machine.
# Idempotent: a second run installs nothing and fetches nothing it already has.
# Where each dependency comes from is listed in DEVELOPERS.md.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi

packages=(
  gcc g++ meson ninja-build pkg-config        # toolchain and build system
  libvulkan-dev mesa-vulkan-drivers           # Vulkan loader and lavapipe
  vulkan-validationlayers                     # tests fail on any validation message
  glslang-dev glslang-tools spirv-tools       # run-time GLSL -> SPIR-V, and glslangValidator for the shader test
  libstb-dev libtinyobjloader-dev             # PNG writer and OBJ loader
  dpkg-dev                                    # apt-get source, for cgltf.h
  clang libclang-rt-14-dev                    # scripts/fuzz: libFuzzer and the sanitizers for clang
  valgrind                                    # test_valgrind: memcheck on CPU-backend runs
  libembree-dev                               # vkrt bench --compare embree (optional in the build)
  python3-matplotlib                          # scripts/bench's plots (scripts/bench_plots.py)
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
apt_updated=0
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  $sudo apt-get update -qq
  apt_updated=1
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# cgltf is not packaged in this Debian release. Prefer a system cgltf.h; otherwise take the
# copy that Debian's meshoptimizer *source* package carries (extern/cgltf.h) into a git-ignored
# cache, so no other project's source is ever committed.
cache="$root/third_party/cache"
if [ -f /usr/include/cgltf.h ] || [ -f "$cache/cgltf/cgltf.h" ]; then
  :
else
  # A deb-src entry derived from the system's own apt sources (no host name is written here).
  srclist=/etc/apt/sources.list.d/vkrt-deb-src.sources
  if ! grep -rqsE '^(Types:.*deb-src|deb-src )' /etc/apt/sources.list /etc/apt/sources.list.d/; then
    tmp=$(mktemp)
    for f in /etc/apt/sources.list.d/*.sources; do
      [ -f "$f" ] || continue
      case "$f" in *vkrt-deb-src*) continue;; esac
      sed -e 's/^Types:.*/Types: deb-src/' "$f" >>"$tmp"
      echo >>"$tmp"
    done
    if [ -f /etc/apt/sources.list ]; then
      grep -E '^deb ' /etc/apt/sources.list | sed -e 's/^deb /deb-src /' >"${tmp}.list" || true
      [ -s "${tmp}.list" ] && $sudo cp "${tmp}.list" /etc/apt/sources.list.d/vkrt-deb-src.list
      rm -f "${tmp}.list"
    fi
    [ -s "$tmp" ] && $sudo cp "$tmp" "$srclist"
    rm -f "$tmp"
    apt_updated=0
  fi
  [ "$apt_updated" = 1 ] || $sudo apt-get update -qq
  work=$(mktemp -d)
  (cd "$work" && apt-get source -qq --download-only meshoptimizer >/dev/null 2>&1 \
     || apt-get source -qq --download-only meshoptimizer)
  orig=$(ls "$work"/meshoptimizer_*.orig.tar.* 2>/dev/null | head -n 1)
  if [ -z "$orig" ]; then echo "setup: could not fetch the meshoptimizer source package" >&2; exit 1; fi
  mkdir -p "$cache/cgltf"
  tar -xf "$orig" -C "$work" --wildcards '*/extern/cgltf.h'
  cp "$(find "$work" -path '*/extern/cgltf.h' | head -n 1)" "$cache/cgltf/cgltf.h"
  rm -rf "$work"
  echo "setup: cgltf.h taken from Debian's meshoptimizer source package into third_party/cache/cgltf"
fi
# cgltf 1.12 sets a primitive's attribute count before allocating the array, so when that
# allocation fails its own cleanup walks a NULL array (tests/test_api.c, out of memory at every
# allocation). One line in the cached copy (idempotent) keeps the count 0 on failure.
cached="$cache/cgltf/cgltf.h"
if [ -f "$cached" ] && ! grep -q 'vkrt: cgltf_free must not walk' "$cached"; then
  sed -i 's|^\(\t\*out_attributes = (cgltf_attribute\*)cgltf_calloc(options, sizeof(cgltf_attribute), \*out_attributes_count);\)$|\1\n\tif (!*out_attributes) *out_attributes_count = 0; /* vkrt: cgltf_free must not walk a NULL array */|' "$cached"
fi
