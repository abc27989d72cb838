#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Before/after check of two build directories of this project, for a change that must not alter
# behaviour: `spheretouch query` output byte-identical on every perf pose file, then
# `spheretouch-bench collide` (hand_L2 x elephant, perf/poses/hand_elephant.txt, 1000 runs) for
# both builds interleaved ABAB in one run. Prints, per pose, the median over rounds of each
# round's p50 and the minimum over rounds of min_us. Models from scripts/models.sh.
#   usage: perf/compare_builds.sh BUILD_A BUILD_B [ROUNDS]   (e.g. ../old/build build 6)
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 2 ] || { sed -n 2,7p "$0"; exit 2; }
a=$1 b=$2 rounds=${3:-6}
m=.cache/models
[ -f $m/hand_L2.off ] || { echo "no $m/hand_L2.off: run scripts/models.sh"; exit 2; }
out=$(mktemp -d); trap 'rm -rf "$out"' EXIT
for pf in perf/poses/hand_elephant.txt perf/results/poses/*.txt; do
  obj=$(basename "$pf" .txt); obj=${obj#hand_}; obj=${obj#table3_}
  case "$obj" in icosphere) objf=perf/results/icosphere.off ;; *) objf=$m/$obj.off ;; esac
  [ -f "$objf" ] || { echo "skipped: $pf (no $objf)"; continue; }
  "$a/spheretouch" query $m/hand_L2.off "$objf" --poses "$pf" >"$out/a" 2>/dev/null
  "$b/spheretouch" query $m/hand_L2.off "$objf" --poses "$pf" >"$out/b" 2>/dev/null
  if cmp -s "$out/a" "$out/b"; then
    echo "identical: $pf x $(basename "$objf") ($(grep -c '^pose' "$out/a") poses, $(grep -vc '^pose' "$out/a") pair lines, sha256 $(sha256sum <"$out/a" | cut -c1-16))"
  else
    echo "DIFFERENT: $pf x $(basename "$objf")"; exit 1
  fi
done
for r in $(seq "$rounds"); do
  for w in a b; do
    d=$a; [ $w = b ] && d=$b
    "$d/perf/spheretouch-bench" collide --probe $m/hand_L2.off --object $m/elephant.off \
      --poses perf/poses/hand_elephant.txt --runs 1000 --json >"$out/$w.$r.json"
  done
done
python3 - "$out" "$rounds" <<'PY'
import json, sys, statistics as S
out, n = sys.argv[1], int(sys.argv[2])
d = {w: [json.load(open(f"{out}/{w}.{r}.json"))["poses"] for r in range(1, n + 1)] for w in "ab"}
print(f"{'contacts':>8} {'A p50 us':>9} {'B p50 us':>9} {'B/A':>6} {'A min us':>9} {'B min us':>9}")
for i, p in enumerate(d["a"][0]):
    pa = S.median(r[i]["p50_us"] for r in d["a"]); pb = S.median(r[i]["p50_us"] for r in d["b"])
    ma = min(r[i]["min_us"] for r in d["a"]); mb = min(r[i]["min_us"] for r in d["b"])
    print(f"{p['contacts']:>8} {pa:>9.1f} {pb:>9.1f} {pb/pa:>6.3f} {ma:>9.1f} {mb:>9.1f}")
PY
