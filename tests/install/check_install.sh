#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# The 'install' test: `meson install` into a scratch directory, then use what was installed the
# way a user does. Checks that
#  * the core library (libspheretouch.so) needs neither assimp, libzmq, libsodium nor toml++;
#  * examples/touch_boxes.cpp compiles against the installed headers and links through
#    pkg-config (`pkg-config --cflags --libs spheretouch`), runs, and finds what it should;
#  * the installed Python module imports (`python3 -c "import spheretouch"`) and works.
#  * the .pc files are relocatable: used from the scratch tree as installed, nothing rewritten;
#  * the example builds three ways through pkg-config (no -march, -march=x86-64-v3, -march=native)
#    and prints the right pairs each time (the ABI's Eigen alignment travels in the Cflags), and a
#    build that bypasses those Cflags with a wider alignment fails to LINK (abi.hpp), never runs;
#  * it links statically too (pkg-config --static: Requires.private/Libs.private are complete);
#  * a CMake consumer builds with find_package(spheretouch 0.1 REQUIRED) and runs;
#  * examples/custom_device.cpp (a device of the program's own, clocked by its own callback)
#    builds through `pkg-config spheretouch-engine` and through CMake's spheretouch::engine, and
#    runs configs/small.toml for 5 s with the servo ticked from its callback;
#  * an installed header never includes another but as <spheretouch/...>.
set -euo pipefail
build=$1 examples=$2
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
fail() { echo "check_install: $*" >&2; echo "[install] test cases: 1 | 0 passed | 1 failed"; exit 1; }

meson install -C "$build" --destdir "$scratch/root" --no-rebuild --quiet >"$scratch/install.log" 2>&1 ||
  { cat "$scratch/install.log"; fail "meson install failed"; }

pcdir=$(dirname "$(find "$scratch/root" -name spheretouch.pc | head -1)")
[ -f "$pcdir/spheretouch.pc" ] || fail "no spheretouch.pc installed"
for name in spheretouch spheretouch-meshio spheretouch-rt spheretouch-net spheretouch-engine; do
  [ -f "$pcdir/$name.pc" ] || fail "$name.pc not installed"
done
grep -q -- '-march' "$pcdir"/spheretouch*.pc && fail "an installed .pc file carries -march: $(grep -l -- -march "$pcdir"/*.pc)"
export PKG_CONFIG_PATH="$pcdir"
incdir=$(pkg-config --variable=includedir spheretouch)
case "$incdir" in "$scratch"/*) ;; *) fail "spheretouch.pc is not relocatable: includedir $incdir";; esac

# The core's shared library: Eigen only (header-only), so no assimp, ZeroMQ, sodium or toml++.
core=$(find "$scratch/root" -name 'libspheretouch.so.*' -type f | head -1)
[ -n "$core" ] || fail "libspheretouch.so not installed"
needed=$(readelf -d "$core" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p' | tr '\n' ' ')
echo "libspheretouch.so needs: $needed"
for lib in assimp zmq sodium toml; do
  case "$needed" in *"$lib"*) fail "the core library links $lib ($needed)";; esac
done
[ -f "$incdir/spheretouch/collide.hpp" ] || fail "spheretouch/collide.hpp not installed"

# Installed headers include each other as <spheretouch/...> only: a user's own geom/mesh.hpp can
# never be picked up in place of ours.
if grep -rn '#include "' "$incdir/spheretouch"; then fail "an installed header includes with quotes (above)"; fi
# ... and opens its namespaces inside the ABI namespace (abi.hpp: Clang does not reopen it by name).
if grep -rnE '^namespace st::(geom|rt|net|engine|view|config|detail)\b' "$incdir/spheretouch"; then
  fail "an installed header opens a library namespace outside st::SPHERETOUCH_ABI (above)"
fi

# The example, built against the installed library only, three ways: whatever -march the user
# picks, the Cflags keep the library's layout of Pose, so the pairs are right.
libdir=$(pkg-config --variable=libdir spheretouch)
check_example() {  # label, extra flags...
  local label=$1; shift
  # shellcheck disable=SC2046
  c++ -std=c++20 "$@" -o "$scratch/touch_boxes" "$examples/touch_boxes.cpp" $(pkg-config --cflags --libs spheretouch) \
    -Wl,-rpath,"$libdir" 2>"$scratch/cc.log" || { cat "$scratch/cc.log"; fail "the example does not build through pkg-config ($label)"; }
  out=$("$scratch/touch_boxes") || { echo "$out"; fail "the example failed ($label)"; }
  [ "$(grep -c 'colliding 1' <<<"$out")" = 3 ] || { echo "$out"; fail "the example should see 3 touching steps ($label)"; }
  echo "example built with ${label}: $(grep -c 'colliding 1' <<<"$out") touching steps, as expected"
}
check_example "no -march"
check_example "-march=x86-64-v3" -march=x86-64-v3
check_example "-march=native" -march=native
out=$("$scratch/touch_boxes")
echo "$out"
# Not `ldd | grep -q`: grep -q exits at the first match, ldd may then die of SIGPIPE, and
# pipefail turns that into a failure.
linked=$(ldd "$scratch/touch_boxes")
grep -q "$libdir/libspheretouch.so" <<<"$linked" || fail "the example did not link the installed library ($linked)"

# Bypassing the Cflags (only -I, a wider Eigen alignment): the names differ (st::v0_a32 against the
# library's st::v0_a16), so the link fails instead of a program that misreads a Pose.
if c++ -std=c++20 -mavx2 -o "$scratch/bypass" "$examples/touch_boxes.cpp" -I"$incdir" $(pkg-config --cflags-only-I eigen3) \
    -L"$libdir" -lspheretouch -Wl,-rpath,"$libdir" 2>"$scratch/bypass.log"; then
  fail "a program built with another Eigen alignment than the library linked (it must not)"
fi
grep -q 'undefined reference to .*st::v0_a32' "$scratch/bypass.log" || { cat "$scratch/bypass.log"; fail "the bypass build failed, but not at link time on the ABI namespace"; }
echo "example built without the Cflags at -mavx2: refused at link time (st::v0_a32 is not st::v0_a16), as it must be"

# Static: the archives and pkg-config --static (Requires.private, Libs.private).
# shellcheck disable=SC2046
c++ -std=c++20 -static -o "$scratch/touch_boxes_static" "$examples/touch_boxes.cpp" \
  $(pkg-config --static --cflags --libs spheretouch) 2>"$scratch/static.log" || { cat "$scratch/static.log"; fail "the example does not link statically"; }
out=$("$scratch/touch_boxes_static") || fail "the static example failed"
[ "$(grep -c 'colliding 1' <<<"$out")" = 3 ] || fail "the static example should see 3 touching steps"
ldd "$scratch/touch_boxes_static" >/dev/null 2>&1 && fail "the static example is dynamically linked"
echo "example linked statically: right pairs"

# CMake: find_package(spheretouch 0.1 REQUIRED) from the installed tree (relocatable config).
if command -v cmake >/dev/null; then
  mkdir -p "$scratch/cmake-src"
  cp "$examples/touch_boxes.cpp" "$examples/custom_device.cpp" "$scratch/cmake-src/"
  cat >"$scratch/cmake-src/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.16)
project(touch_boxes CXX)
find_package(spheretouch 0.1 REQUIRED COMPONENTS core net engine)
add_executable(touch_boxes touch_boxes.cpp)
target_link_libraries(touch_boxes PRIVATE spheretouch::core)
add_executable(custom_device custom_device.cpp)
target_link_libraries(custom_device PRIVATE spheretouch::engine)
CMAKE
  cmake -S "$scratch/cmake-src" -B "$scratch/cmake-build" -G Ninja -DCMAKE_PREFIX_PATH="$(cd "$incdir/.." && pwd)" \
    -DCMAKE_BUILD_RPATH="$libdir" >"$scratch/cmake.log" 2>&1 && cmake --build "$scratch/cmake-build" >>"$scratch/cmake.log" 2>&1 ||
    { cat "$scratch/cmake.log"; fail "a CMake consumer does not build with find_package(spheretouch 0.1 REQUIRED)"; }
  out=$("$scratch/cmake-build/touch_boxes") || fail "the CMake-built example failed"
  [ "$(grep -c 'colliding 1' <<<"$out")" = 3 ] || fail "the CMake-built example should see 3 touching steps"
  [ -x "$scratch/cmake-build/custom_device" ] || fail "the CMake consumer did not build custom_device (spheretouch::engine)"
  echo "CMake consumer (find_package(spheretouch 0.1 REQUIRED COMPONENTS core net engine)): right pairs; custom_device built"
else
  fail "cmake not found (scripts/setup.sh installs it)"
fi

# A device of the program's own through the installed engine (pkg-config spheretouch-engine).
c++ -std=c++20 -O1 -o "$scratch/custom_device" "$examples/custom_device.cpp" $(pkg-config --cflags --libs spheretouch-engine) \
  -Wl,-rpath,"$libdir" 2>"$scratch/cc.log" || { cat "$scratch/cc.log"; fail "custom_device does not build through pkg-config spheretouch-engine"; }
# The engine's own library dependencies are found the way an installed system finds them (here
# LD_LIBRARY_PATH; an executable's RUNPATH covers only its direct ones).
LD_LIBRARY_PATH="$libdir" "$scratch/custom_device" "$examples/../configs/small.toml" --seconds 5 >"$scratch/device.out" 2>"$scratch/device.err" ||
  { cat "$scratch/device.err" "$scratch/device.out"; fail "custom_device failed on configs/small.toml"; }
grep -q "^vendor callback device: [1-9][0-9]* ticks" "$scratch/device.out" ||
  { cat "$scratch/device.out"; fail "custom_device: the callback did not tick the servo"; }
grep -q "the device's own callback" "$scratch/device.err" || fail "custom_device: the run's summary does not say the device clocked the servo"
echo "custom_device (pkg-config spheretouch-engine): $(cat "$scratch/device.out")"

# The Python module from the install tree.
pyso=$(find "$scratch/root" -name '_core*.so' -path '*-packages/spheretouch/*' | head -1)
if [ -n "$pyso" ]; then
  PYTHONPATH=$(dirname "$(dirname "$pyso")") /usr/bin/python3 -c "
import numpy as np, spheretouch as st
assert st.__file__.startswith('$scratch'), st.__file__
v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
f = np.array([[0,1,3],[0,3,2],[4,6,7],[4,7,5],[0,4,5],[0,5,1],[2,3,7],[2,7,6],[0,2,6],[0,6,4],[1,5,7],[1,7,3]])
m = st.Mesh(v, f)
c = st.ComputeCollision(st.Body(m), st.Body(m))
t = np.eye(4); t[:3, 3] = (0.5, 0.25, 0.125)
far = t.copy(); far[0, 3] = 3.5
assert c.query(t).colliding and not c.query(far).colliding
print('python module from the install tree:', st.__file__)
" || fail "the installed Python module does not work"
else
  echo "no Python module installed (python_bindings disabled): skipped"
fi
echo "[install] test cases: 1 | 1 passed | 0 failed"
