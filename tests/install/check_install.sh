#!/usr/bin/env bash
# The 'install' test: `meson install` into a scratch directory, then use what was installed the
# way a user does. Checks that
#  * the core library (libspheretouch.so) needs neither assimp, libzmq, libsodium nor toml++;
#  * examples/touch_boxes.cpp compiles against the installed headers and links through
#    pkg-config (`pkg-config --cflags --libs spheretouch`), runs, and finds what it should;
#  * the installed Python module imports (`python3 -c "import spheretouch"`) and works.
# The .pc files name the configured prefix; they are copied with prefix= pointing into the
# scratch directory (nothing else in them changes).
# usage: check_install.sh BUILD_DIR EXAMPLES_DIR
set -euo pipefail
build=$1 examples=$2
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
fail() { echo "check_install: $*" >&2; echo "[install] test cases: 1 | 0 passed | 1 failed"; exit 1; }

meson install -C "$build" --destdir "$scratch/root" --no-rebuild --quiet >"$scratch/install.log" 2>&1 ||
  { cat "$scratch/install.log"; fail "meson install failed"; }

pcdir=$(dirname "$(find "$scratch/root" -name spheretouch.pc | head -1)")
[ -f "$pcdir/spheretouch.pc" ] || fail "no spheretouch.pc installed"
prefix=$(sed -n 's/^prefix=//p' "$pcdir/spheretouch.pc")
mkdir "$scratch/pc"
for pc in "$pcdir"/spheretouch*.pc; do
  sed "s|^prefix=.*|prefix=$scratch/root$prefix|" "$pc" >"$scratch/pc/$(basename "$pc")"
done
for name in spheretouch spheretouch-meshio spheretouch-rt spheretouch-net; do
  [ -f "$scratch/pc/$name.pc" ] || fail "$name.pc not installed"
done
export PKG_CONFIG_PATH="$scratch/pc"

# The core's shared library: Eigen only (header-only), so no assimp, ZeroMQ, sodium or toml++.
core=$(find "$scratch/root" -name 'libspheretouch.so.*' -type f | head -1)
[ -n "$core" ] || fail "libspheretouch.so not installed"
needed=$(readelf -d "$core" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p' | tr '\n' ' ')
echo "libspheretouch.so needs: $needed"
for lib in assimp zmq sodium toml; do
  case "$needed" in *"$lib"*) fail "the core library links $lib ($needed)";; esac
done
[ -f "$scratch/root$prefix/include/spheretouch/collide.hpp" ] || fail "spheretouch/collide.hpp not installed"

# The example, built against the installed library only.
libdir=$(pkg-config --variable=libdir spheretouch)
# shellcheck disable=SC2046
c++ -std=c++20 -o "$scratch/touch_boxes" "$examples/touch_boxes.cpp" $(pkg-config --cflags --libs spheretouch) \
  -Wl,-rpath,"$libdir" 2>"$scratch/cc.log" || { cat "$scratch/cc.log"; fail "the example does not build through pkg-config"; }
out=$("$scratch/touch_boxes") || { echo "$out"; fail "the example failed"; }
echo "$out"
[ "$(grep -c 'colliding 1' <<<"$out")" = 3 ] || fail "the example should see 3 touching steps"
# Not `ldd | grep -q`: grep -q exits at the first match, ldd may then die of SIGPIPE, and
# pipefail turns that into a failure.
linked=$(ldd "$scratch/touch_boxes")
grep -q "$libdir/libspheretouch.so" <<<"$linked" || fail "the example did not link the installed library ($linked)"

# The Python module from the install tree.
pyso=$(find "$scratch/root" -name 'spheretouch*.so' -path '*-packages*' | head -1)
if [ -n "$pyso" ]; then
  PYTHONPATH=$(dirname "$pyso") /usr/bin/python3 -c "
import numpy as np, spheretouch as st
assert st.__file__.startswith('$scratch'), st.__file__
v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
f = np.array([[0,1,3],[0,3,2],[4,6,7],[4,7,5],[0,4,5],[0,5,1],[2,3,7],[2,7,6],[0,2,6],[0,6,4],[1,5,7],[1,7,3]])
m = st.Mesh(v, f)
c = st.Collider(st.Body(m), st.Body(m))
t = np.eye(4); t[:3, 3] = (0.5, 0.25, 0.125)
far = t.copy(); far[0, 3] = 3.5
assert c.query(t).colliding and not c.query(far).colliding
print('python module from the install tree:', st.__file__)
" || fail "the installed Python module does not work"
else
  echo "no Python module installed (python_bindings disabled): skipped"
fi
echo "[install] test cases: 1 | 1 passed | 0 failed"
