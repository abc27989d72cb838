#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Runs the libFuzzer targets (tests/fuzz/fuzz_*.cpp) for SECONDS each, two at a time (2 cores),
# each from a copy of its committed corpus (tests/fuzz/corpus/TARGET; the repo is never written),
# with ASan + UBSan (halting on the first report) and LeakSanitizer. Configures and builds
# build-fuzz with clang when needed, building only the fuzz targets.
#   tests/fuzz/run_fuzz.sh SECONDS [TARGET...]     (default: every target; SECONDS 0: build only)
# Prints one line per target (runs, coverage, corpus, ok or CRASH with the reproducer's path)
# and exits non-zero if any target crashed, leaked, hit a UBSan report, a timeout or OOM.
# Work directories (logs, grown corpus, artifacts): build-fuzz/fuzz-runs/<time>/<target>/.
# Environment: ST_FUZZ_BUILD (build dir, default build-fuzz), ST_JOBS (ninja -j, default 2),
# ST_FUZZ_PARALLEL (targets at once, default 2).
set -uo pipefail
cd "$(dirname "$0")/../.."
secs="${1:-}"
[[ "$secs" =~ ^[0-9]+$ ]] || { echo "usage: tests/fuzz/run_fuzz.sh SECONDS [TARGET...]" >&2; exit 2; }
shift
all=(fuzz_wire fuzz_mesh fuzz_scene fuzz_pose fuzz_worker fuzz_tree fuzz_shm)
targets=("$@"); ((${#targets[@]})) || targets=("${all[@]}")
dir="${ST_FUZZ_BUILD:-build-fuzz}"
jobs="${ST_JOBS:-2}"
par="${ST_FUZZ_PARALLEL:-2}"

if [ ! -f "$dir/build.ninja" ]; then
  command -v clang++ >/dev/null || { echo "run_fuzz: clang++ not found (scripts/setup.sh installs clang)"; exit 1; }
  # -O1 with line tables only: fast enough to build in CI, stack traces still name file:line.
  # -Dunity=on as in the other sanitizer builds (scripts/run_tests.sh).
  CC=clang CXX=clang++ meson setup "$dir" -Dfuzz=true -Db_sanitize=address,undefined -Db_lundef=false \
    -Dnative=false --buildtype=plain -Doptimization=1 -Dcpp_args=-gline-tables-only -Dunity=on \
    -Dfcl=disabled -Dsystemd=disabled >/dev/null || { echo "run_fuzz: meson setup $dir failed"; exit 1; }
fi
ninja -C "$dir" -j"$jobs" "${targets[@]/#/tests/fuzz/}" || { echo "run_fuzz: build failed"; exit 1; }
[ "$secs" = 0 ] && exit 0  # build only (scripts/run_tests.sh builds ahead, runs later)

runs="$dir/fuzz-runs/$(date +%Y%m%d-%H%M%S)"
mkdir -p "$runs"
runs="$(cd "$runs" && pwd)"
echo "== fuzzing ${targets[*]} for ${secs} s each, $par at a time (work dirs: $runs)"

run_one() {  # target
  local t=$1 w="$runs/$1" dict=()
  mkdir -p "$w/corpus" "$w/artifacts"
  cp -r "tests/fuzz/corpus/$t/." "$w/corpus/"
  [ -f "tests/fuzz/$t.dict" ] && dict=(-dict="$PWD/tests/fuzz/$t.dict")
  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:symbolize=1 \
  UBSAN_OPTIONS=halt_on_error=1:abort_on_error=1:print_stacktrace=1 \
    "$dir/tests/fuzz/$t" -max_total_time="$secs" -detect_leaks=1 -timeout=25 -rss_limit_mb=2048 \
      -print_final_stats=1 -artifact_prefix="$w/artifacts/" "${dict[@]}" "$w/corpus" >"$w/log" 2>&1
  echo $? >"$w/rc"
}

summary() {  # target -> one line; returns non-zero on a finding
  local t=$1 w="$runs/$1" rc execs eps cov corp art
  rc=$(cat "$w/rc" 2>/dev/null || echo 255)
  execs=$(sed -nE 's/^stat::number_of_executed_units: *([0-9]+).*/\1/p' "$w/log" | tail -1)
  eps=$(sed -nE 's/^stat::average_exec_per_sec: *([0-9]+).*/\1/p' "$w/log" | tail -1)
  cov=$(grep -oE 'cov: [0-9]+ ft: [0-9]+' "$w/log" | tail -1)
  corp=$(grep -oE 'corp: [0-9]+/[0-9]+[bKM]b' "$w/log" | tail -1)
  art=$(find "$w/artifacts" -type f | head -1)
  if [ "$rc" = 0 ] && [ -z "$art" ]; then
    echo "$t: ok, ${secs} s, ${execs:-?} runs (${eps:-?}/s), ${cov:-cov ?}, ${corp:-corp: ?} (files/bytes in the work corpus)"
    return 0
  fi
  local what
  what=$(grep -m1 -oE 'ERROR: (AddressSanitizer|LeakSanitizer|libFuzzer): [^ ]+( [^ ]+)?|runtime error: .*|fuzz property violated: .*' "$w/log" | head -1)
  echo "$t: CRASH (exit $rc): ${what:-see log} after ${execs:-?} runs; reproducer: ${art:-none}; log: $w/log"
  return 1
}

pids=()
for t in "${targets[@]}"; do
  while (($(jobs -rp | wc -l) >= par)); do wait -n; done
  run_one "$t" &
done
wait

status=0
for t in "${targets[@]}"; do summary "$t" || status=1; done
exit $status
