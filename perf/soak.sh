#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# Soak: `spheretouch run` for MINUTES with 4 worker daemons over tcp loopback; every minute one
# worker (in turn) is killed with SIGKILL and restarted on its port 5 s later. Records the run's
# summary (ticks, misses, incomplete rounds, telemetry drops) and the resident memory of every
# process: the run at 10 s and just before its end, each worker incarnation 10 s after it
# started and just before it was killed (or the end).
# Usage: perf/soak.sh [MINUTES=30] [SCENE=perf/soak.toml] [BUILD=build]
# Output: runs/soak-<stamp>/ (run directory, worker logs, rss.csv, soak.txt); prints soak.txt.
set -euo pipefail
cd "$(dirname "$0")/.."
minutes="${1:-30}"
scene="${2:-perf/soak.toml}"
build="${3:-build}"
for b in "$build/spheretouch" "$build/daemons/spheretouch-worker"; do
  [ -x "$b" ] || { echo "soak: $b missing (build first: ninja -C $build)" >&2; exit 2; }
done
out="runs/soak-$(date +%Y%m%d-%H%M%S)"
mkdir -p "$out"
seconds=$((minutes * 60 + 20))

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
rss_kb() { awk '/^VmRSS:/ {print $2}' "/proc/$1/status" 2>/dev/null || echo 0; }
# CPU time of the whole VM so far, "total steal" in clock ticks (/proc/stat): on a shared host
# the hypervisor runs other guests on our vCPUs (steal), and no priority inside can help that.
cpu_ticks() { awk '/^cpu / { t = 0; for (i = 2; i <= 9; i++) t += $i; print t, $9 }' /proc/stat; }

declare -a ports pids born life
for i in 0 1 2 3; do ports[$i]=$(free_port); life[$i]=0; done
echo "process,incarnation,pid,rss_start_kb,rss_end_kb,seconds" >"$out/rss.csv"
declare -A rss_start

start_worker() {  # index
  local i=$1
  life[$i]=$((life[$i] + 1))
  "$build/daemons/spheretouch-worker" --bind "tcp://127.0.0.1:${ports[$i]}" --id "$i" --log-level info \
    >>"$out/worker$i.log" 2>&1 &
  pids[$i]=$!
  born[$i]=$SECONDS
}
end_worker() {  # index: records its memory, then kills it
  local i=$1
  local p=${pids[$i]}
  echo "worker$i,${life[$i]},$p,${rss_start[$p]:-0},$(rss_kb "$p"),$((SECONDS - born[$i]))" >>"$out/rss.csv"
  kill -9 "$p" 2>/dev/null || true
  wait "$p" 2>/dev/null || true
}
cleanup() { for i in 0 1 2 3; do kill -9 "${pids[$i]}" 2>/dev/null || true; done; }
trap cleanup EXIT

for i in 0 1 2 3; do start_worker "$i"; done
read -r cpu0 steal0 < <(cpu_ticks)
sleep 1
eps="tcp://127.0.0.1:${ports[0]},tcp://127.0.0.1:${ports[1]},tcp://127.0.0.1:${ports[2]},tcp://127.0.0.1:${ports[3]}"
echo "soak: $minutes min, 4 workers ($eps), one killed and restarted every minute; output $out"
"$build/spheretouch" run "$scene" --connect "$eps" --duration "$seconds" --out "$out/run" >"$out/run.log" 2>&1 &
run=$!
t0=$SECONDS
run_rss_start=0
run_rss_end=0
victim=0
next_kill=60
while kill -0 "$run" 2>/dev/null; do
  sleep 1
  t=$((SECONDS - t0))
  [ "$run_rss_start" = 0 ] && [ $t -ge 10 ] && run_rss_start=$(rss_kb "$run")
  for w in 0 1 2 3; do
    p=${pids[$w]}
    [ -z "${rss_start[$p]:-}" ] && [ $((SECONDS - born[$w])) -ge 10 ] && rss_start[$p]=$(rss_kb "$p")
  done
  [ $t -le $((seconds - 5)) ] && run_rss_end=$(rss_kb "$run")  # the last sample before it winds down
  if [ $t -ge $next_kill ] && [ $t -lt $((seconds - 30)) ]; then
    echo "t $t s: kill -9 worker $victim (pid ${pids[$victim]})" | tee -a "$out/events.txt"
    end_worker "$victim"
    sleep 5
    start_worker "$victim"
    echo "t $((SECONDS - t0)) s: restarted worker $victim (pid ${pids[$victim]})" | tee -a "$out/events.txt"
    victim=$(((victim + 1) % 4))
    next_kill=$((next_kill + 60))
  fi
done
wait "$run" || { echo "soak: spheretouch run failed (see $out/run.log)"; tail -20 "$out/run.log"; exit 1; }
for i in 0 1 2 3; do end_worker "$i"; done
read -r cpu1 steal1 < <(cpu_ticks)
echo "run,1,$run,$run_rss_start,$run_rss_end,$((SECONDS - t0))" >>"$out/rss.csv"
{
  echo "soak: $minutes min, scene $scene, 4 workers, $(grep -c 'kill -9' "$out/events.txt") kills and restarts"
  echo "host: load average $(cut -d' ' -f1-3 /proc/loadavg) at the end; steal $(awk -v c="$((cpu1 - cpu0))" -v s="$((steal1 - steal0))" 'BEGIN { printf "%.1f", (c > 0 ? 100 * s / c : 0) }') % of CPU time during the soak (the hypervisor ran others on our vCPUs)"
  sed -n '/^summary/,$p' "$out/run.log"
  echo "memory (rss.csv, KiB; start = 10 s after start, end = just before kill or end):"
  awk -F, 'NR > 1 { d = $5 - $4; printf "  %-8s #%-3s start %7d end %7d growth %+6d KiB over %5d s\n", $1, $2, $4, $5, d, $6;
                    if ($1 == "run") run = d; else if (d > wmax) wmax = d }
           END { printf "  largest worker growth %+d KiB; run growth %+d KiB\n", wmax, run }' "$out/rss.csv"
} | tee "$out/soak.txt"
