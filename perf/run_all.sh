#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# The perf harness: regenerates the paper's Tables 1-3, the peers, the speed/accuracy
# trade, the force rendering quality (paper vs patch contact model), the collision core per SIMD
# instruction set, the hostile-client, scale-out, live-view and device benches, their CSVs, PNG
# plots, a JSON summary and perf/RESULTS.md (written whole: the current results, each table with
# its command; earlier runs are in git history).
#   perf/run_all.sh            full run (<= 15 min on the 2-core dev VM): perf/results/, perf/RESULTS.md
#   perf/run_all.sh --quick    every benchmark with tiny counts (<= 2 min), for CI; asserts nothing
#                              about speed; writes build/perf-quick/ and leaves perf/ untouched
# Options: --build DIR (default build), --out DIR (override the output directory), --no-plots.
# Env: ST_MODEL_DIR (default .cache/models), ST_JOBS (ninja jobs, default 1).
set -euo pipefail
cd "$(dirname "$0")/.."
quick=0; build=build; out=""; plots=1
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=1 ;;
    --build) build="$2"; shift ;;
    --out) out="$2"; shift ;;
    --no-plots) plots=0 ;;
    -h|--help) sed -n '2,9p' "$0"; exit 0 ;;
    *) echo "run_all.sh: unknown option $1" >&2; exit 2 ;;
  esac
  shift
done
if [ -z "$out" ]; then
  if [ $quick = 1 ]; then out="$build/perf-quick"; else out=perf/results; fi
fi
t_start=$(date +%s)
models="${ST_MODEL_DIR:-.cache/models}"
bench="$build/perf/spheretouch-bench"
worker="$build/daemons/spheretouch-worker"
log() { printf '[run_all %4ds] %s\n' $(( $(date +%s) - t_start )) "$*"; }

# gnuplot for the PNGs: a Debian package, installed the way scripts/setup.sh installs its own.
if [ $plots = 1 ] && ! command -v gnuplot >/dev/null 2>&1; then
  if [[ "$(dpkg-query -W -f='${Status}' gnuplot-nox 2>/dev/null)" != *"install ok installed"* ]]; then
    log "installing gnuplot-nox"
    sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"
    { $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends gnuplot-nox; } \
      || echo "run_all.sh: could not install gnuplot-nox; no plots this run" >&2
  fi
fi
command -v gnuplot >/dev/null 2>&1 || plots=0

[ -f "$build/build.ninja" ] || meson setup "$build" --buildtype=release >/dev/null
log "building"
ninja -C "$build" -j"${ST_JOBS:-1}" perf/spheretouch-bench spheretouch daemons/spheretouch-worker >/dev/null
for m in hand_L2 elephant armadillo armadillo_L1 armadillo_L2; do
  [ -s "$models/$m.off" ] || { log "model set incomplete: scripts/models.sh"; scripts/models.sh; break; }
done

mkdir -p "$out/poses"
rm -f "$out"/*.csv "$out"/*.json "$out"/*.png "$out/rerun.txt"; rm -rf "$out/force"
hand="$models/hand_L2.off"

# Machine and load, for the report.
{
  echo "cpu=$(lscpu | sed -n 's/^Model name: *//p' | head -1)"
  echo "cores=$(nproc)"
  echo "kernel=$(uname -sr)"
  echo "compiler=$(c++ --version | head -1)"
  echo "load_start=$(cut -d' ' -f1-3 /proc/loadavg)"
  echo "mode=$([ $quick = 1 ] && echo quick || echo full)"
  echo "command=perf/run_all.sh$([ $quick = 1 ] && echo ' --quick')"
  echo "git=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
  echo "date=$(date -u +%Y-%m-%dT%H:%M:%SZ)"
} > "$out/machine.txt"

# Counts: full | quick.
if [ $quick = 1 ]; then
  t1_targets=100,1000; t3_targets=100; ico_targets=100; workers=0,1,2; rounds1=5; rounds3=3; t2_seconds=0.4
  peer_runs=2; rt_seconds=1; trade_seconds=0.6; trade_samples=20; trade_probe="$models/hand.off"
  t2_models=(icosphere "$models/elephant.off")
  t3_models=(icosphere "$models/elephant.off")
else
  # The 980-face ball tops out near 300 contacts with the fingertip push (its faces are ~8 mm wide,
  # so contacts are mostly hand faces along the intersection curve): 100 and 300 there.
  t1_targets=100,200,300,400,500,1000,1500; t3_targets=100,1500; ico_targets=100,300; workers=0,1,2,4,8; rounds1=300; rounds3=150
  t2_seconds=5; peer_runs=20; rt_seconds=10; trade_seconds=5; trade_samples=200; trade_probe="$hand"
  t2_models=(icosphere "$models/elephant.off" "$models/armadillo_L1.off" "$models/armadillo_L2.off")
  t3_models=("${t2_models[@]}")
fi

"$bench" icosphere "$out/icosphere.off" >/dev/null
objpath() { if [ "$1" = icosphere ]; then echo "$out/icosphere.off"; else echo "$1"; fi; }
objname() { basename "$1" .off; }

# Poses at given contact counts, per model (fingertip pushed along the normal, seeded, deterministic).
find_poses() {  # object targets
  local o; o=$(objpath "$1")
  "$bench" collide --probe "$hand" --object "$o" --find-poses "$out/poses/hand_$(objname "$o").txt" \
    --targets "$2" >/dev/null
}
log "finding poses"
find_poses "$models/elephant.off" "$t1_targets"
for m in "${t3_models[@]}"; do
  case "$(objname "$(objpath "$m")")" in
    elephant) ;;
    icosphere) find_poses "$m" "$ico_targets" ;;
    *) find_poses "$m" "$t3_targets" ;;
  esac
done

# The collision core on each instruction set the CPU has (AVX-512 and AVX2 where present): the
# certified triangle filter against today's path (every candidate through the exact test), same run.
isas=()
flags=$(grep -m1 '^flags' /proc/cpuinfo || true)
[[ " $flags " == *" avx512f "* && " $flags " == *" avx512vl "* ]] && isas+=(avx512)
[[ " $flags " == *" avx2 "* && " $flags " == *" fma "* ]] && isas+=(avx2)
isas+=(sse2)
if [ $quick = 1 ]; then isas=("${isas[0]}"); collide_runs=5; collide_objects=(elephant); else collide_runs=300; collide_objects=(elephant armadillo_L2); fi
log "collision core: filter vs exact test, ISAs ${isas[*]}"
for o in "${collide_objects[@]}"; do
  if [ "$o" = elephant ]; then pf="$out/poses/hand_elephant.txt"; else
    pf="$out/poses/hand_${o}_targets.txt"
    "$bench" collide --probe "$hand" --object "$models/$o.off" --find-poses "$pf" --targets 100,500,1000,1500 >/dev/null
  fi
  for isa in "${isas[@]}"; do
    "$bench" collide --probe "$hand" --object "$models/$o.off" --poses "$pf" --runs "$collide_runs" --isa "$isa" --json \
      > "$out/collide_${o}_${isa}.json"
  done
done

# The coherent collider along slides and a jerk, against today's path and the filter (same run).
if [ $quick = 1 ]; then slide_args=(--rounds 60 --reps 1 --steps 0.01,0.1); else slide_args=(--rounds 200 --reps 9); fi
log "collision core: coherent collider along slides (${collide_objects[*]})"
for o in "${collide_objects[@]}"; do
  if [ "$o" = elephant ]; then pf="$out/poses/hand_elephant.txt"; else pf="$out/poses/hand_${o}_targets.txt"; fi
  "$bench" slides --probe "$hand" --object "$models/$o.off" --poses "$pf" "${slide_args[@]}" --json > "$out/slides_${o}.json"
  # The same series kept on the surface (each round's pose moved along the normal to the start's depth).
  "$bench" slides --probe "$hand" --object "$models/$o.off" --poses "$pf" "${slide_args[@]}" --follow --json \
    > "$out/slides_follow_${o}.json"
  # The probe withdrawn from each pose, long enough to leave contact from the deepest.
  if [ $quick = 1 ]; then withdraw_args=(--rounds 60 --reps 1); else withdraw_args=(--rounds 1200 --reps 3); fi
  "$bench" slides --probe "$hand" --object "$models/$o.off" --poses "$pf" --steps '' --jerk 0 --withdraw 0.01 \
    "${withdraw_args[@]}" --json > "$out/withdraw_${o}.json"
done

log "table 1: hand x elephant, contacts x workers ($workers)"
"$bench" table1 --probe "$hand" --object "$models/elephant.off" --poses "$out/poses/hand_elephant.txt" \
  --workers "$workers" --worker-bin "$worker" --rounds "$rounds1" --csv "$out/table1.csv" > "$out/table1.txt"

log "table 2: haptic and collision rates, single thread vs spheretouch (press 3 mm and 30 mm)"
objs=(); for m in "${t2_models[@]}"; do objs+=("$(objpath "$m")"); done
for press in 3 30; do
  "$bench" table2 --probe "$hand" "${objs[@]}" --seconds "$t2_seconds" --press-mm "$press" --csv "$out/table2.csv" \
    >> "$out/table2.txt"
done

log "table 3: rounds/s vs workers x contacts x models"
for m in "${t3_models[@]}"; do
  o=$(objpath "$m")
  pf="$out/poses/hand_$(objname "$o").txt"
  if [ "$(objname "$o")" = elephant ]; then  # the 100 and 1,500 (quick: 100) targets of Table 1's file
    awk -v want=",$t3_targets," 'BEGIN{keep=0} /^# contacts/{t=$NF; gsub(/[()]/,"",t); keep=index(want, "," t ",")>0}
         /^#/{ if (keep) print; next } { if (keep) print; keep=0 }' "$pf" > "$out/poses/table3_elephant.txt"
    pf="$out/poses/table3_elephant.txt"
  fi
  "$bench" table3 --probe "$hand" --object "$o" --poses "$pf" --workers "$workers" --worker-bin "$worker" \
    --rounds "$rounds3" --csv "$out/table3.csv" >> "$out/table3.txt"
done

log "peers: FCL, mutex vs triple buffer, bare clock_nanosleep vs haptic loop"
"$bench" peers --probe "$hand" --object "$models/elephant.off" --poses "$out/poses/hand_elephant.txt" \
  --runs "$peer_runs" --csv "$out/peers_fcl.csv" > "$out/peers_fcl.txt" \
  || echo "peers: FCL comparison unavailable (built without libfcl-dev?)" | tee "$out/peers_fcl.txt" >&2
"$bench" exchange --seconds "$rt_seconds" --json > "$out/exchange.json"
"$bench" haptic --seconds "$rt_seconds" --round "$(( rt_seconds < 5 ? 1 : 5 ))" --json > "$out/haptic.json"

log "speed/accuracy trade (offline, simulated time)"
"$bench" trade --probe "$trade_probe" \
  --levels "$models/armadillo.off,$models/armadillo_L1.off,$models/armadillo_L2.off" \
  --seconds "$trade_seconds" --samples "$trade_samples" --csv "$out/trade.csv" --trace-csv "$out/trade_trace.csv" \
  > "$out/trade.txt"

log "force rendering quality: paper vs patch contact model, open and closed loop (simulated time)"
# Per-tick traces go to $out/force/ (8 MB, not committed); force_slide.png is drawn from them.
force_args=(--json --trace-dir "$out/force" --poses "$out/poses/hand_elephant.txt")
[ $quick = 1 ] && force_args+=(--quick --scenes box,plate,hand_elephant,box_edge,crease,plate_through,release --workers-check 2)
"$bench" force "${force_args[@]}" > "$out/force.json"

log "hostile clients: the security reproducers against a live worker daemon, an honest client querying"
hostile_args=(--json)
[ $quick = 1 ] && hostile_args+=(--quick --quiet-rounds 50)
"$bench" hostile "${hostile_args[@]}" > "$out/hostile.json"

log "scenes of many objects: a round's cost at 1, 10, 100 objects, touching none or one"
"$bench" scene --json > "$out/scene.json"

echo "load_end=$(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/machine.txt"
echo "elapsed_s=$(( $(date +%s) - t_start ))" >> "$out/machine.txt"
log "scale-out model: worker shares timed alone per W and mapping, gather measured, 10/100 GbE predicted"
if [ $quick = 1 ]; then
  "$bench" scale --probe "$hand" --object "$models/elephant.off" --poses perf/poses/scale_hand_elephant.txt \
    --max-workers 4 --runs 3 --gather-rounds 40 --json > "$out/scale_elephant.json"
else
  for o in elephant armadillo_L1 armadillo_L2; do
    "$bench" scale --probe "$hand" --object "$models/$o.off" --poses "perf/poses/scale_hand_$o.txt" \
      --max-workers 64 --json > "$out/scale_$o.json"
    # The spread over 12 poses near 1,000 contacts: one pose's imbalance is one draw.
    "$bench" scale --probe "$hand" --object "$models/$o.off" --poses "perf/poses/scale_hand_${o}_1000x12.txt" \
      --max-workers 16 --no-validate --json > "$out/spread_$o.json"
  done
fi
[ $plots = 1 ] && python3 perf/scale_plot.py "$out/scale.png" "$out"/scale_*.json

if [ $quick = 0 ]; then  # needs the browser and ~3 minutes; the browser tests cover the page in CI
  log "live view and UDP bridge: haptic misses with and without a viewer, page frame rate, pose-to-force time"
  perf/view_bench.sh 12 3 > "$out/view.txt"
  log "in-process device (callback-clocked) against the UDP bridge, same run"
  ninja -C "$build" -j"${ST_JOBS:-1}" examples/custom_device >/dev/null
  perf/device_bench.sh 5 "$out" > "$out/device.txt"
  log "the demo's collision latency, coherent collider on and off"
  perf/demo_coherent.sh 6 3 "0 2" "$out" > "$out/demo_coherent.txt"
else
  perf/demo_coherent.sh 1 1 0 "$out" > "$out/demo_coherent.txt"
fi

log "report"
report_args=("$out")
[ $quick = 1 ] || report_args+=(--results-md perf/RESULTS.md)
[ $plots = 1 ] && report_args+=(--plots)
python3 perf/harness_report.py "${report_args[@]}"
log "done: $out ($(( $(date +%s) - t_start )) s)"
