#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# A device in the process against the UDP bridge, in the same run (docs/tutorials/bring-your-own-device.md):
#   1. examples/custom_device on configs/small.toml: a vendor-SDK-style servo callback ticks the
#      engine (RunOptions::device_clocked) for SECONDS; then the same scene with the engine's own
#      simulated device (--compare): ticks, misses, and the callback's pose-to-force time (SDK pose
#      sample -> force handed back to it);
#   2. the UDP bridge on the same scene (configs/udp_small.toml: small.toml with [device] kind =
#      "udp"), driven by examples/udp_device_emulator.py at 1 kHz on loopback: its pose-to-force time
#      (driver sends a pose -> receives the force computed from it).
# usage: perf/device_bench.sh [SECONDS] [OUT]   (default 5 s, perf/results); writes OUT/device.json
set -euo pipefail
cd "$(dirname "$0")/.."
secs="${1:-5}"
results="${2:-perf/results}"
for exe in build/spheretouch build/examples/custom_device; do
  [ -x "$exe" ] || { echo "device_bench: $exe missing (scripts/setup.sh build)" >&2; exit 2; }
done
work=$(mktemp -d)
trap 'pkill -P $$ 2>/dev/null || true; rm -rf "$work"' EXIT
mkdir -p "$results"

echo "device_bench: in-process device (callback-clocked), then the built-in simulated device, ${secs} s each" >&2
build/examples/custom_device configs/small.toml --seconds "$secs" --compare --json >"$work/inproc.json" 2>"$work/inproc.log" ||
  { cat "$work/inproc.log" >&2; exit 1; }

echo "device_bench: the UDP bridge with the emulator at 1 kHz, ${secs} s" >&2
build/spheretouch run configs/udp_small.toml --duration $((secs + 3)) --out "$work/udp" >"$work/udp.log" 2>&1 &
upid=$!
for _ in $(seq 300); do grep -q "listening on" "$work/udp.log" 2>/dev/null && break; sleep 0.05; done
python3 examples/udp_device_emulator.py --key "$work/udp/bridge.key" --seconds "$secs" --from 0,0,56 --to-point 0,0,46 --json >"$work/udp.json"
wait "$upid" || true

python3 - "$work/inproc.json" "$work/udp.json" "$results/device.json" <<'PY'
import json, sys
inp = json.load(open(sys.argv[1]))
udp = json.load(open(sys.argv[2]))
out = {"in_process": inp, "udp": udp,
       "p99_ratio_in_process_to_udp": inp["pose_to_force_us_p99"] / udp["pose_to_force_us_p99"],
       "p50_ratio_in_process_to_udp": inp["pose_to_force_us_p50"] / udp["pose_to_force_us_p50"]}
json.dump(out, open(sys.argv[3], "w"), indent=1)
rate = lambda m, t: 100.0 * m / max(1, t)
print(f"in-process device (callback-clocked): {inp['vendor_ticks']} ticks, {inp['vendor_misses']} misses "
      f"({rate(inp['vendor_misses'], inp['vendor_ticks']):.2f} %); pose-to-force p50 {inp['pose_to_force_us_p50']:.1f} us, "
      f"p99 {inp['pose_to_force_us_p99']:.1f} us, max {inp['pose_to_force_us_max']:.1f} us")
print(f"built-in simulated device (same scene): {inp['builtin_ticks']} ticks, {inp['builtin_misses']} misses "
      f"({rate(inp['builtin_misses'], inp['builtin_ticks']):.2f} %)")
print(f"UDP bridge (emulator, loopback): pose-to-force p50 {udp['pose_to_force_us_p50']:.0f} us, "
      f"p99 {udp['pose_to_force_us_p99']:.0f} us, max {udp['pose_to_force_us_max']:.0f} us")
print(f"in-process / UDP: p50 {out['p50_ratio_in_process_to_udp']:.4f}x, p99 {out['p99_ratio_in_process_to_udp']:.4f}x")
PY
