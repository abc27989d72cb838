#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Builds the paper-sized model set from Debian's libcgal-demo meshes (no root needed):
#   apt-get download libcgal-demo; dpkg -x; take four meshes from its data.tar.gz; scale to mm and
#   Loop-subdivide with `spheretouch export`. Output in $ST_MODEL_DIR (default .cache/models).
#   hand_L2.off        38,240 faces  (hand, diagonal 100 mm, 2 Loop levels; paper's hand 37,248)
#   elephant.off       88,928 faces  (refined_elephant, diagonal 200 mm; paper's horse 96,966)
#   armadillo.off      52,000 faces  (diagonal 200 mm, level 0, for the level-of-detail study)
#   armadillo_L1.off  208,000 faces  (1 Loop level; paper's boat 194,092)
#   armadillo_L2.off  832,000 faces  (2 Loop levels; paper's subdivided boat 776,368)
#   bunny.off          75,408 faces  (bunny00, diagonal 200 mm)
#   hand.off            2,390 faces  (the hand at level 0, for quick tests)
# The diagonal is set before subdividing, so all levels of a model share one frame (subdivided
# levels shrink slightly inside it).
# With --big (or ST_BIG_MODELS=1), also the million-face levels (not in the default set-up: about
# 1 GB of OFF files and a minute or two of subdividing):
#   armadillo_L3.off  3,328,000 faces  (3 Loop levels)
#   armadillo_L4.off 13,312,000 faces  (4 Loop levels)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${ST_MODEL_DIR:-.cache/models}"
cache="${ST_CACHE_DIR:-.cache}/cgal"
exe="${ST_EXE:-build/spheretouch}"
mkdir -p "$out" "$cache"
want=(hand.off hand_L2.off elephant.off armadillo.off armadillo_L1.off armadillo_L2.off bunny.off)
big="${ST_BIG_MODELS:-0}"
for arg in "$@"; do
  case "$arg" in
    --big) big=1 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "models: unknown argument '$arg' (expected --big)" >&2; exit 2 ;;
  esac
done
[ "$big" = 1 ] && want+=(armadillo_L3.off armadillo_L4.off)
done_all=1
for f in "${want[@]}"; do [ -s "$out/$f" ] || done_all=0; done
if [ "$done_all" = 1 ]; then echo "models: up to date in $out"; exit 0; fi

src="$cache/data/meshes"
if [ ! -s "$src/hand.off" ]; then
  if ! ls "$cache"/libcgal-demo_*.deb >/dev/null 2>&1; then
    echo "models: downloading Debian package libcgal-demo into $cache"
    (cd "$cache" && apt-get download libcgal-demo 2>&1 | grep -v '^W: Download is performed unsandboxed' || true)
    ls "$cache"/libcgal-demo_*.deb >/dev/null 2>&1 || {
      echo "models: apt-get download libcgal-demo failed (run 'apt-get update' once?)" >&2; exit 1; }
  fi
  rm -rf "$cache/pkg"
  dpkg -x "$cache"/libcgal-demo_*.deb "$cache/pkg"
  tar -xzf "$cache/pkg/usr/share/doc/libcgal-dev/data.tar.gz" -C "$cache" \
    data/meshes/hand.off data/meshes/refined_elephant.off data/meshes/armadillo.off data/meshes/bunny00.off
  rm -rf "$cache/pkg"
fi

build() {  # name input diagonal levels
  [ -s "$out/$1" ] && return 0
  echo "models: $1"
  local tmp="$out/${1%.off}.tmp.off"  # export picks the format by extension: keep .off last
  "$exe" export "$src/$2" -o "$tmp" --diagonal "$3" --subdivide "$4"
  mv "$tmp" "$out/$1"
}
build hand.off         hand.off             100 0
build hand_L2.off      hand.off             100 2
build elephant.off     refined_elephant.off 200 0
build armadillo.off    armadillo.off        200 0
build armadillo_L1.off armadillo.off        200 1
build armadillo_L2.off armadillo.off        200 2
build bunny.off        bunny00.off          200 0
if [ "$big" = 1 ]; then
  build armadillo_L3.off armadillo.off        200 3
  build armadillo_L4.off armadillo.off        200 4
fi
echo "models: ready in $out"
