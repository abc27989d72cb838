#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# One API, one way: the engine, the workers, the CLI and the Python module collide through the
# public façade (<spheretouch/collide.hpp>: ComputeCollision), so what a library user calls is
# what the project runs. geom::collide() is called only in src/spheretouch/geom and the façade
# (src/spheretouch/collide.cpp). Part of the test run (scripts/run_tests.sh).
#   scripts/check_api.sh     list the calls outside them; fail if any
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t hits < <(git grep -n -E 'geom::collide\(' -- 'src/*.cpp' 'src/*.hpp' 'src/*.inl' 'python/*.cpp' 'daemons/*.cpp' |
  grep -v -E '^src/spheretouch/geom/|^src/spheretouch/collide\.cpp:' | grep -v -E '^[^:]+:[0-9]+:\s*//' || true)
if ((${#hits[@]})); then
  printf 'api: %d calls of geom::collide( outside src/spheretouch/geom and the façade (use st::ComputeCollision):\n' \
    "${#hits[@]}" >&2
  printf '  %s\n' "${hits[@]}" >&2
  exit 1
fi
echo "api: geom::collide() is called only in src/spheretouch/geom and the façade"
