#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# perf/big_scene.sh [BUILD_DIR]: the million-face scenes of issue 17, measured.
#   1. load and sphere-tree build times of armadillo_L3 (3.3 M faces) and armadillo_L4 (13.3 M);
#   2. configs/big_armadillo.toml (the hand touching armadillo_L4 at 1 kHz) run with 4 in-process
#      workers, then with 4 worker daemons on loopback tcp;
#   3. every process's memory: the run's peak (max RSS), each daemon's resident set before its
#      block set arrives, after it (steady) and at its peak (VmHWM).
# Needs the big models: scripts/models.sh --big. Writes perf/results/big/ (override: ST_OUT).
set -euo pipefail
cd "$(dirname "$0")/.."
build="${1:-build}"
models="${ST_MODEL_DIR:-.cache/models}"
out="${ST_OUT:-perf/results/big}"
for m in armadillo_L3 armadillo_L4; do
  [ -s "$models/$m.off" ] || { echo "big_scene: $models/$m.off missing: run scripts/models.sh --big first" >&2; exit 2; }
done
mkdir -p "$out"
tmp=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT
log() { printf '[big_scene %3ds] %s\n' "$SECONDS" "$*" >&2; }
kib() { awk -v k="$2" '$1 == k":" { print $2 }' "/proc/$1/status"; }  # pid field -> KiB

report="$out/report.txt"
: >"$report"
say() { echo "$*" | tee -a "$report"; }
say "# perf/big_scene.sh, $(date -u '+%Y-%m-%d %H:%M UTC'), commit $(git rev-parse --short HEAD 2>/dev/null || echo '?')"

for m in armadillo_L3 armadillo_L4; do
  log "loading and building $m"
  say "## $m"
  "$build/perf/spheretouch-bench" load "$models/$m.off" --runs 1 | tee -a "$report"
  /usr/bin/time -f "build: %e s wall, max RSS %M KiB" "$build/spheretouch" build "$models/$m.off" -o "$tmp/$m.tree" \
    2>&1 | tee -a "$report"
  rm -f "$tmp/$m.tree"
done

scene=configs/big_armadillo.toml
log "run, 4 in-process workers"
say "## run: $scene, 4 in-process workers"
/usr/bin/time -f "run process: %e s wall, max RSS %M KiB" "$build/spheretouch" run "$scene" --workers 4 \
  --out "$tmp/run-inproc" 2>&1 | grep -v "^\[" | tee -a "$report"
cat "$tmp/run-inproc/summary.txt" >>"$report"

log "run, 4 worker daemons"
say "## run: $scene, 4 worker daemons on loopback tcp"
eps=()
for i in 0 1 2 3; do
  port=$((26100 + RANDOM % 2000 + i * 2000))
  "$build/daemons/spheretouch-worker" --bind "tcp://127.0.0.1:$port" --id "$i" --log-level warning &
  pids+=($!)
  eps+=("tcp://127.0.0.1:$port")
done
sleep 1
idle=()
for p in "${pids[@]}"; do idle+=("$(kib "$p" VmRSS)"); done
connect=$(IFS=,; echo "${eps[*]}")
/usr/bin/time -f "run process: %e s wall, max RSS %M KiB" "$build/spheretouch" run "$scene" --connect "$connect" \
  --out "$tmp/run-daemons" 2>&1 | grep -v "^\[" | tee -a "$report"
cat "$tmp/run-daemons/summary.txt" >>"$report"
for i in 0 1 2 3; do
  p=${pids[$i]}
  say "daemon $i: resident $(kib "$p" VmRSS) KiB after the run (idle before its block set: ${idle[$i]} KiB), peak $(kib "$p" VmHWM) KiB"
done
log "done: $report"
