#!/usr/bin/env bash
# Runs every doctest suite through meson and closes with one line "tests: N passed, N failed"
# (test cases summed over the suites). Expects a configured build in build/.
set -uo pipefail
cd "$(dirname "$0")/.."
build="${1:-build}"
meson test -C "$build" --print-errorlogs --num-processes 1 "${@:2}"
status=$?
passed=0; failed=0
log="$build/meson-logs/testlog.txt"
if [ -f "$log" ]; then
  while read -r p f; do passed=$((passed + p)); failed=$((failed + f)); done < <(
    grep -E '^\[doctest\] test cases:' "$log" | sed -E 's/.*\| *([0-9]+) passed \| *([0-9]+) failed.*/\1 \2/')
fi
if [ $status -ne 0 ] && [ $failed -eq 0 ]; then failed=1; fi  # a suite crashed before its summary
echo "tests: $passed passed, $failed failed"
exit $status
