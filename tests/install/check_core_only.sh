#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# The core-only build needs nothing but a C++20 compiler, meson, ninja, pkg-config and Eigen.
# Checked without a container: pkg-config is shown a directory holding eigen3.pc alone and CMake
# lookups are switched off, so a dependency() on anything else would fail the configure; then the
# build, its install, and the example built against that install (pkg-config) must work, and no
# installed library may link assimp, ZeroMQ, libsodium or toml++.
# usage: check_core_only.sh BUILD_DIR   (configures it if needed; CI runs it in the background)
set -euo pipefail
cd "$(dirname "$0")/../.."
build=$1
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
fail() { echo "check_core_only: $*" >&2; exit 1; }

mkdir "$scratch/pc"
eigen_pc="$(pkg-config --variable=pcfiledir eigen3)/eigen3.pc"
[ -f "$eigen_pc" ] || fail "eigen3.pc not found (apt-get install libeigen3-dev)"
ln -s "$eigen_pc" "$scratch/pc/eigen3.pc"
export PKG_CONFIG_LIBDIR="$scratch/pc" PKG_CONFIG_PATH=""
rm -rf "$build"
# --buildtype=plain: no optimisation, quickest to compile; this checks dependencies, not speed.
# -Dunity=on: four sources to a file (~2/3 of the CPU time); the release build compiles each
# source on its own, so a missing #include still shows there.
meson setup "$build" -Dcore_only=true --buildtype=plain -Dunity=on -Dcmake_prefix_path="$scratch/none" \
  >"$scratch/setup.log" 2>&1 || { cat "$scratch/setup.log"; fail "meson setup -Dcore_only=true failed with only eigen3 visible"; }
deps=$(grep -E '^(Run-time dependency|Dependency|Library) ' "$build/meson-logs/meson-log.txt" | grep -E 'found: YES' | sed -E 's/ found: YES.*//' | sort -u | tr '\n' ';')
echo "core-only configure found: $deps"
ninja -C "$build" -j"${ST_JOBS:-2}" >"$scratch/build.log" 2>&1 || { tail -40 "$scratch/build.log"; fail "the core-only build failed"; }
meson install -C "$build" --destdir "$scratch/root" --no-rebuild --quiet >/dev/null 2>&1 || fail "the core-only install failed"
for so in $(find "$scratch/root" -name 'libspheretouch*.so.*' -type f); do
  needed=$(readelf -d "$so" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p' | tr '\n' ' ')
  for lib in assimp zmq sodium toml; do
    case "$needed" in *"$lib"*) fail "$(basename "$so") links $lib ($needed)";; esac
  done
done
pcdir=$(dirname "$(find "$scratch/root" -name spheretouch.pc | head -1)")
for name in spheretouch spheretouch-meshio spheretouch-rt; do [ -f "$pcdir/$name.pc" ] || fail "$name.pc not installed"; done
[ -f "$pcdir/spheretouch-net.pc" ] && fail "a core-only build installed spheretouch-net"
export PKG_CONFIG_LIBDIR="$scratch/pc:$pcdir"
libdir=$(pkg-config --variable=libdir spheretouch)
# shellcheck disable=SC2046
c++ -std=c++20 -o "$scratch/touch_boxes" examples/touch_boxes.cpp $(pkg-config --cflags --libs spheretouch) \
  -Wl,-rpath,"$libdir" || fail "the example does not build against the core-only install"
out=$("$scratch/touch_boxes")
[ "$(grep -c 'colliding 1' <<<"$out")" = 3 ] || { echo "$out"; fail "the example should see 3 touching steps"; }
echo "core-only build: configured with eigen3 alone, built, installed; the example finds its 3 touching steps"
