#!/bin/sh
# SPDX-License-Identifier: BSD-3-Clause
# Scatter-gather overhead sweep behind perf/RESULTS.md: an empty query through 1, 2, 4, 8 workers
# over inproc, ipc and tcp loopback, rounds spaced like the collision loop (--gap-us).
# Usage: perf/scatter_sweep.sh [BUILD_DIR] [CSV] [extra spheretouch-bench scatter options...]
set -eu
build="${1:-build}"
csv="${2:-perf/scatter.csv}"
[ $# -ge 2 ] && shift 2 || shift $#
for t in inproc ipc tcp; do
  for n in 1 2 4 8; do
    "$build/perf/spheretouch-bench" scatter --workers "$n" --transport "$t" --csv "$csv" "$@"
  done
done
