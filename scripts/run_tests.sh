#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Runs every doctest suite: the release build, then (unless ST_SANITIZERS=0) the whole suite
# under ASan+UBSan and the concurrent suites (rt, net) under TSan, then each libFuzzer target for
# ST_FUZZ seconds (default 30, 0 skips). Closes with one line "tests: N passed, N failed"
# (doctest test cases summed over every run, with the Python and install checks).
set -uo pipefail
cd "$(dirname "$0")/.."
jobs="${ST_JOBS:-2}"
passed=0; failed=0; status=0; failed_steps=""
failures=$(mktemp); bg=$(mktemp -d); trap 'rm -rf "$failures" "$bg"' EXIT
# Section headers carry the time since this script started (m:ss), so a slow CI run shows
# which step the time went to.
say() { printf '== [%d:%02d] %s\n' $((SECONDS / 60)) $((SECONDS % 60)) "$*"; }

run_suites() {  # build-dir [suite...]
  local dir=$1; shift
  local args=()
  for s in "$@"; do args+=(--suite "$s"); done
  say "meson test -C $dir ${*:-(all suites)}"
  meson test -C "$dir" --print-errorlogs --num-processes 1 --no-rebuild "${args[@]}" || { status=1; failed_steps+=" tests($dir)"; }
  local log="$dir/meson-logs/testlog.txt" p f
  if [ -f "$log" ]; then
    while read -r p f; do passed=$((passed + p)); failed=$((failed + f)); done < <(
      grep -E '^\[(doctest|python|install)\] test cases:' "$log" | sed -E 's/.*\| *([0-9]+) passed \| *([0-9]+) failed.*/\1 \2/')
    # Each failed check's doctest block (file:line, test case, what failed), repeated at the end.
    awk -v dir="$dir" '/^={20,}$/ { if (blk ~ /ERROR|FATAL|sanitizer|SUMMARY/) printf "[%s]%s\n", dir, blk; blk = ""; next }
                       { if (length(blk) < 4000) blk = blk "\n" $0 }' "$log" >>"$failures"
  fi
}

build_targets() {  # build-dir target... (targets this build does not define are skipped)
  local dir=$1; shift
  local have want=()
  have=$(ninja -C "$dir" -t targets all 2>/dev/null | cut -d: -f1)
  for t in "$@"; do grep -qx "$t" <<<"$have" && want+=("$t"); done
  ninja -C "$dir" -j"$jobs" "${want[@]}"
}

configure() {  # build-dir meson-args...
  local dir=$1; shift
  [ -f "$dir/build.ninja" ] || meson setup "$dir" "$@" >/dev/null || { echo "meson setup $dir failed"; status=1; return 1; }
}

say "scripts/format.sh --check"
scripts/format.sh --check || { status=1; failed=$((failed + 1)); failed_steps+=" format"; }
say "scripts/check_spdx.sh"
scripts/check_spdx.sh || { status=1; failed=$((failed + 1)); failed_steps+=" spdx"; }
say "scripts/check_api.sh"
scripts/check_api.sh || { status=1; failed=$((failed + 1)); failed_steps+=" api"; }
say "scripts/check_docs.sh"
ST_DOCS_OUT="${ST_DOCS_OUT:-build-docs}" scripts/check_docs.sh || { status=1; failed=$((failed + 1)); failed_steps+=" docs"; }

say "release build"
ninja -C build -j"$jobs" || exit 1

# The sanitizer and fuzz builds compile in the background at the lowest CPU priority while the
# suites before them run (those mostly wait on sleeps and child processes); each suite waits for
# its own build. Build logs are printed when the suite that needs them starts.
fuzz_secs="${ST_FUZZ:-30}"
sanitizers="${ST_SANITIZERS:-1}"
# -Dunity=on: each target's sources compile four to a file. CLI11 costs 10-15 s per file that
# includes it under ASan, and the sanitizer builds are most of CI's compile time: unity saves
# about a sixth of the ASan build (measured 13.3 against 16 CPU-minutes). Release builds stay
# one file per source (each test suite is one unity file in every build: tests/meson.build). Two
# files' internal helpers of the same name break these builds: share the helper
# (tests/test_util.hpp) or rename one.
# -fno-sanitize=alignment,null,object-size: three of UBSan's checks that more than double what
# the build costs (the engine's largest file: 71 CPU-s with them, 35 without, 20 with no sanitizer;
# alignment alone is 13-20 s of it, its checks on every Eigen reference) and that ASan or another
# build covers: a null or out-of-bounds access is ASan's report here, and the libFuzzer build
# (tests/fuzz/run_fuzz.sh, clang, every UBSan check) checks alignment where bytes become values,
# in the decoders of every outside input. Every other UBSan check stays (overflow, shifts,
# bounds, bool/enum loads, vptr, return, pointer overflow, unreachable).
asan_args=(--buildtype=plain -Doptimization=1 -Db_sanitize=address,undefined -Db_lundef=false -Dnative=false -Dunity=on
           -Dcpp_args=-fno-sanitize=alignment,null,object-size)
# -Wno-tsan: gcc warns that TSan does not model atomic_thread_fence (SeqLock); its payload words
# are relaxed atomics, so TSan has no data race to miss there, only orderings it cannot check.
tsan_args=(--buildtype=plain -Doptimization=1 -Db_sanitize=thread -Db_lundef=false -Dnative=false -Dcpp_args=-Wno-tsan -Dunity=on)
finished() {  # name rc: records when a background build ended, then its exit status
  printf '%d:%02d' $((SECONDS / 60)) $((SECONDS % 60)) >"$bg/$1.done"
  echo "$2" >"$bg/$1.rc"
}
if [ "$sanitizers" != 0 ]; then
  (
    renice -n 19 -p "$BASHPID" >/dev/null 2>&1
    # Sanitizer builds compile only the test programs and the executables the tests start, at -O1
    # without debug info to keep CI within its time on 2 cores (reports keep function names).
    { configure build-asan "${asan_args[@]}" &&
      build_targets build-asan spheretouch daemons/spheretouch-worker tests/net/zmq_ping tests/test_geom tests/test_rt tests/test_net tests/test_app \
        tests/fuzz/fuzz_wire_replay tests/fuzz/fuzz_mesh_replay tests/fuzz/fuzz_scene_replay tests/fuzz/fuzz_pose_replay \
        tests/fuzz/fuzz_worker_replay tests/fuzz/fuzz_tree_replay tests/fuzz/fuzz_shm_replay
    } >"$bg/asan.log" 2>&1
    finished asan $?
    { configure build-tsan "${tsan_args[@]}" &&
      build_targets build-tsan daemons/spheretouch-worker tests/net/zmq_ping tests/test_rt tests/test_net
    } >"$bg/tsan.log" 2>&1
    finished tsan $?
    # The core-only build with nothing but eigen3 visible to pkg-config (tests/install).
    ST_JOBS="$jobs" tests/install/check_core_only.sh build-core >"$bg/core.log" 2>&1
    finished core $?
    # pip install . into a venv (pyproject.toml, meson-python), offline.
    tests/install/check_pip.sh >"$bg/pip.log" 2>&1
    finished pip $?
    if [ "$fuzz_secs" != 0 ]; then ST_JOBS="$jobs" tests/fuzz/run_fuzz.sh 0 >"$bg/fuzz.log" 2>&1; finished fuzz $?; fi
  ) &
  bg_pid=$!
fi
built() {  # name: waits for the background build, prints its log; false if it failed
  say "waiting for the $1 build"
  while [ ! -f "$bg/$1.rc" ]; do
    kill -0 "$bg_pid" 2>/dev/null || [ -f "$bg/$1.rc" ] || { echo "$1 build: the background builder died"; status=1; return 1; }
    sleep 2
  done
  say "$1 build (in the background, done at $(cat "$bg/$1.done"))"
  cat "$bg/$1.log"
  [ "$(cat "$bg/$1.rc")" = 0 ] || { echo "$1 build failed"; status=1; failed_steps+=" $1-build"; return 1; }
}

run_suites build

# Every benchmark once, small (perf/run_all.sh --quick): proves they run; asserts nothing about speed.
if [ "${ST_PERF_QUICK:-1}" != 0 ]; then
  say "perf/run_all.sh --quick"
  perf/run_all.sh --quick || { echo "perf smoke run failed"; status=1; failed_steps+=" perf-smoke"; }
fi

if [ "$sanitizers" != 0 ]; then
  if built asan; then
    UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 ASAN_OPTIONS=detect_leaks=1 LSAN_OPTIONS=suppressions=$PWD/tests/lsan.supp run_suites build-asan
  fi
  if built tsan; then
    TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1:suppressions=$PWD/tests/tsan.supp run_suites build-tsan rt net
  fi
  built core || true  # built() prints the log and marks the run failed
  built pip || true
  # libFuzzer targets (clang, ASan+UBSan, LeakSanitizer): each runs ST_FUZZ seconds (default 30;
  # 0 skips) from a copy of its committed corpus, four at a time; any crash, leak, UBSan report,
  # timeout or violated property fails the run (tests/fuzz/run_fuzz.sh).
  if [ "$fuzz_secs" != 0 ] && built fuzz; then
    # Four targets at a time on two cores (each gets half a core for ST_FUZZ seconds): CI's
    # fuzzing is a regression check of the corpora; the long runs are in perf/RESULTS.md.
    say "tests/fuzz/run_fuzz.sh $fuzz_secs (${ST_FUZZ_PARALLEL:-4} at a time)"
    ST_JOBS="$jobs" ST_FUZZ_PARALLEL="${ST_FUZZ_PARALLEL:-4}" tests/fuzz/run_fuzz.sh "$fuzz_secs" || { echo "fuzzing failed (reproducers and logs named above)"; status=1; failed_steps+=" fuzz"; }
  fi
fi
wait

if [ $status -ne 0 ] && [ $failed -eq 0 ]; then failed=1; fi  # a suite crashed before its summary
if [ -s "$failures" ]; then
  say "failures (repeated from the logs above)"
  cat "$failures"
fi
# One line per suite run and the reasons of any that did not pass, last: CI shows the end.
say "suites"
dirs=(build); [ "$sanitizers" != 0 ] && dirs+=(build-asan build-tsan)
python3 scripts/test_summary.py "${dirs[@]}"
[ -n "$failed_steps" ] && echo "failed steps:$failed_steps"
echo "tests: $passed passed, $failed failed"
exit $status
