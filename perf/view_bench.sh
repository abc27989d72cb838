#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# The live view's and the UDP bridge's costs, measured (docs/user-guide/devices.md: "Live view", "A bridge for real
# devices"; perf/RESULTS.md):
#   1. haptic misses of the same run (configs/demo.toml: hand_L2 x elephant) without a viewer and
#      with the live view open in headless Chromium, interleaved, PAIRS times; also with the
#      haptic thread at SCHED_FIFO 80 (what a deployment would set);
#   2. the page's own frame rate while it draws that run (frames it counted / seconds), with the
#      object drawn once per camera move (the default) and every frame (?cache=0), same session;
#   3. the UDP bridge's pose-to-force time on loopback (examples/udp_device_emulator.py at 1 kHz).
# usage: perf/view_bench.sh [SECONDS] [PAIRS]    (default 12 s, 3 pairs); writes perf/results/view.json
# and perf/results/view.png (the page's snapshot: README's screenshot).
set -euo pipefail
cd "$(dirname "$0")/.."
secs="${1:-12}"
pairs="${2:-3}"
[ -x build/spheretouch ] || { echo "view_bench: build first (scripts/setup.sh build)" >&2; exit 2; }
[ -x /usr/bin/chromium ] || { echo "view_bench: needs Debian's chromium (scripts/setup.sh installs it)" >&2; exit 2; }
work=$(mktemp -d)
trap 'pkill -P $$ 2>/dev/null || true; rm -rf "$work"' EXIT
mkdir -p perf/results

sed 's/^fifo_priority = 0 /fifo_priority = 80 /' configs/demo.toml > "$work/demo_fifo.toml"
grep -q '^fifo_priority = 80 ' "$work/demo_fifo.toml" || { echo "view_bench: could not set fifo_priority" >&2; exit 1; }
# model: paths resolve against the scene's directory; the copy lives elsewhere.
cp "$work/demo_fifo.toml" configs/.view_bench_fifo.toml
trap 'pkill -P $$ 2>/dev/null || true; rm -rf "$work" configs/.view_bench_fifo.toml' EXIT

port=18080
run_one() {  # scene viewer(0|1) label [page query] -> appends "label ticks misses fps frames secs" to $work/rows
  local scene=$1 viewer=$2 label=$3 query=${4:-snapshot=1&follow=1} out="$work/run$RANDOM"
  local args=(run "$scene" --duration "$secs" --out "$out")
  [ "$viewer" = 1 ] && args+=(--view "127.0.0.1:$port")
  build/spheretouch "${args[@]}" > "$out.log" 2>&1 &
  local pid=$!
  local browser=""
  if [ "$viewer" = 1 ]; then
    for _ in $(seq 300); do grep -q "view: http" "$out.log" 2>/dev/null && break; sleep 0.05; done
    /usr/bin/chromium --headless=new --no-sandbox --disable-gpu --enable-unsafe-swiftshader --use-angle=swiftshader \
      --disable-quic --no-first-run --disable-background-networking --disable-component-update --disable-sync \
      --window-size=800,600 --remote-debugging-port=0 --user-data-dir="$work/profile$RANDOM" \
      "http://127.0.0.1:$port/?t=$(sed -n 's/.*view: http[^ ]*?t=\([0-9a-f]*\).*/\1/p' "$out.log")&$query" > "$work/chromium.log" 2>&1 &
    browser=$!
  fi
  wait "$pid" || true
  [ -n "$browser" ] && { kill -9 "$browser" 2>/dev/null || true; wait "$browser" 2>/dev/null || true; }
  local ticks misses fps="" frames="" vsecs=""
  ticks=$(sed -n 's/^  haptic  *\([0-9]*\) ticks.*/\1/p' "$out.log")
  misses=$(sed -n 's/^  haptic  *[0-9]* ticks ([^)]*), \([0-9]*\) misses.*/\1/p' "$out.log")
  if [ "$viewer" = 1 ]; then
    frames=$(sed -n 's/.*last second; \([0-9]*\) frames in \([0-9.]*\) s, \([0-9.]*\) fps.*/\1/p' "$out.log")
    vsecs=$(sed -n 's/.*last second; \([0-9]*\) frames in \([0-9.]*\) s, \([0-9.]*\) fps.*/\2/p' "$out.log")
    fps=$(sed -n 's/.*last second; \([0-9]*\) frames in \([0-9.]*\) s, \([0-9.]*\) fps.*/\3/p' "$out.log")
    [ -f "$out/view.png" ] && [ "$label" = viewer ] && cp "$out/view.png" perf/results/view.png
  fi
  echo "$label ${ticks:-0} ${misses:-0} ${fps:-0} ${frames:-0} ${vsecs:-0}" >> "$work/rows"
  echo "view_bench: $label: ${ticks:-?} ticks, ${misses:-?} misses${fps:+, page ${fps} fps}" >&2
  port=$((port + 1))
}

for i in $(seq "$pairs"); do
  run_one configs/demo.toml 0 plain
  run_one configs/demo.toml 1 viewer
  run_one configs/demo.toml 1 nocache_viewer "follow=1&cache=0"  # the page drawing the object every frame
  run_one configs/.view_bench_fifo.toml 0 fifo_plain
  run_one configs/.view_bench_fifo.toml 1 fifo_viewer
done

# The UDP bridge: the emulator at 1 kHz against the small scene, in-process servo.
build/spheretouch run configs/udp_small.toml --duration $((secs > 8 ? secs : 8)) --out "$work/udp" > "$work/udp.log" 2>&1 &
upid=$!
for _ in $(seq 300); do grep -q "listening on" "$work/udp.log" 2>/dev/null && break; sleep 0.05; done
python3 examples/udp_device_emulator.py --key "$work/udp/bridge.key" --seconds $((secs > 8 ? secs - 3 : 5)) --from 0,0,56 --to-point 0,0,46 --json \
  > "$work/udp.json"
wait "$upid" || true

python3 - "$work/rows" "$work/udp.json" "$secs" <<'EOF'
import json, sys
rows = [l.split() for l in open(sys.argv[1])]
udp = json.load(open(sys.argv[2]))
out = {"seconds": float(sys.argv[3]), "runs": [], "udp": udp}
agg = {}
for label, ticks, misses, fps, frames, vsecs in rows:
    r = {"label": label, "ticks": int(ticks), "misses": int(misses)}
    if label.endswith("viewer"):
        r.update(page_fps=float(fps), page_frames=int(frames), page_seconds=float(vsecs))
    out["runs"].append(r)
    a = agg.setdefault(label, [0, 0, 0, 0.0])
    a[0] += int(ticks); a[1] += int(misses); a[2] += int(frames) if label.endswith("viewer") else 0
    a[3] += float(vsecs) if label.endswith("viewer") else 0.0
out["totals"] = {k: {"ticks": v[0], "misses": v[1], "misses_per_10k": 1e4 * v[1] / max(1, v[0]),
                     **({"page_fps": v[2] / v[3]} if v[3] > 0 else {})} for k, v in agg.items()}
json.dump(out, open("perf/results/view.json", "w"), indent=1)
print("run             ticks   misses  misses/10k  page fps")
for k, v in out["totals"].items():
    print(f"{k:15s} {v['ticks']:7d} {v['misses']:7d} {v['misses_per_10k']:10.1f}  {v.get('page_fps', float('nan')):8.1f}")
for a, b in (("plain", "viewer"), ("fifo_plain", "fifo_viewer")):
    t = out["totals"]
    print(f"viewer adds {t[b]['misses_per_10k'] - t[a]['misses_per_10k']:.1f} misses per 10,000 ticks ({a} -> {b})")
print(f"udp bridge: {udp['poses_sent']} poses at 1 kHz, {udp['forces_received']} forces ({udp['forces_per_s']:.1f}/s), "
      f"{udp['force_seq_gaps']} gaps; pose-to-force p50 {udp['pose_to_force_us_p50']:.0f} us, "
      f"p99 {udp['pose_to_force_us_p99']:.0f} us, max {udp['pose_to_force_us_max']:.0f} us; "
      f"of which pose -> servo tick p50 {udp['pose_to_servo_us_p50']:.0f} / p99 {udp['pose_to_servo_us_p99']:.0f} us, "
      f"servo -> driver p50 {udp['servo_to_driver_us_p50']:.0f} / p99 {udp['servo_to_driver_us_p99']:.0f} us")
EOF
