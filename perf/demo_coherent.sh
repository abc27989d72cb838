#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# The demo's collision latency with the coherent collider on and off (issue 30: "spheretouch
# run's collision latency p50 in the demo drops accordingly"): `spheretouch run configs/demo.toml`
# (the hand pressed into the elephant and slid along it, the built-in script) with [collision]
# coherent = true, then a copy with coherent = false, alternated RUNS times each, for each worker
# count of WORKERS (0: collide() in the collision thread; n: n in-process workers, the demo's 2).
# Every round's time comes from rounds.csv; the rounds with pairs are reported apart (most rounds
# of the script are out of contact, a sphere test or a few, and hide the contact rounds in an
# overall median). Both paths run the certified triangle filter.
# usage: perf/demo_coherent.sh [SECONDS] [RUNS] [WORKERS] [OUT]
#        (default 6 s, 3 runs, "0 2", perf/results); writes OUT/demo_coherent.json
set -euo pipefail
cd "$(dirname "$0")/.."
secs="${1:-6}"
runs="${2:-3}"
workers="${3:-0 2}"
results="${4:-perf/results}"
[ -x build/spheretouch ] || { echo "demo_coherent: build/spheretouch missing (scripts/setup.sh build)" >&2; exit 2; }
work=$(mktemp -d)
# The copy sits beside the original so that its relative paths resolve alike.
off="configs/.demo_coherent_off.$$.toml"
trap 'rm -rf "$work" "$off"' EXIT
mkdir -p "$results"
sed -E 's/^coherent = true /coherent = false/' configs/demo.toml >"$off"
grep -q '^coherent = false' "$off" || { echo "demo_coherent: configs/demo.toml has no 'coherent = true' line" >&2; exit 2; }

for w in $workers; do
  for r in $(seq "$runs"); do
    for v in on off; do
      cfg=configs/demo.toml
      [ "$v" = off ] && cfg="$off"
      echo "demo_coherent: workers $w, run $r of $runs, coherent $v (${secs} s)" >&2
      build/spheretouch run "$cfg" --duration "$secs" --workers "$w" --out "$work/w${w}_${v}_$r" >"$work/w${w}_${v}_$r.log" 2>&1 ||
        { tail -20 "$work/w${w}_${v}_$r.log" >&2; exit 1; }
    done
  done
done

python3 - "$work" "$results/demo_coherent.json" "$secs" "$runs" $workers <<'PY'
import csv, json, statistics, sys
work, out, secs, runs, workers = sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), [int(w) for w in sys.argv[5:]]

def q(xs, p):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p * len(xs)))] if xs else None

rows = []
for w in workers:
    row = {"workers": w}
    for v in ("on", "off"):
        per_run = []
        for r in range(1, runs + 1):
            rounds = list(csv.DictReader(open(f"{work}/w{w}_{v}_{r}/rounds.csv")))
            us = [(int(x["end_ns"]) - int(x["start_ns"])) / 1e3 for x in rounds]
            contact = [u for u, x in zip(us, rounds) if int(x["pairs"]) > 0]
            per_run.append({"rounds": len(us), "contact_rounds": len(contact), "p50_us": q(us, 0.5),
                            "contact_p50_us": q(contact, 0.5), "contact_p90_us": q(contact, 0.9),
                            "contact_mean_us": statistics.fmean(contact) if contact else None})
        # A run too short to reach the contact has no rounds with pairs: its figures are null.
        med = lambda key: statistics.median(x[key] for x in per_run) if all(x[key] is not None for x in per_run) else None
        row[v] = {"runs": per_run, "p50_us": med("p50_us"), "contact_p50_us": med("contact_p50_us"),
                  "contact_p90_us": med("contact_p90_us")}
    ratio = lambda key: row["on"][key] / row["off"][key] if row["on"][key] and row["off"][key] else None
    row["contact_p50_ratio"] = ratio("contact_p50_us")
    row["contact_p90_ratio"] = ratio("contact_p90_us")
    rows.append(row)
json.dump({"seconds": secs, "runs": runs, "rows": rows}, open(out, "w"), indent=1)
for row in rows:
    on, off = row["on"], row["off"]
    if row["contact_p50_ratio"] is None or row["contact_p90_ratio"] is None:
        print(f"workers {row['workers']}: no rounds with pairs in some run (too short to reach the contact)")
        continue
    print(f"workers {row['workers']}: rounds with pairs p50 {on['contact_p50_us']:.1f} us coherent on, "
          f"{off['contact_p50_us']:.1f} us off ({row['contact_p50_ratio']:.3f}x), p90 {on['contact_p90_us']:.1f} / "
          f"{off['contact_p90_us']:.1f} us ({row['contact_p90_ratio']:.3f}x); every round p50 {on['p50_us']:.1f} / "
          f"{off['p50_us']:.1f} us (median of {runs} runs each)")
PY
