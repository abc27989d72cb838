#!/usr/bin/env python3
# SPDX-License-Identifier: BSD-3-Clause
"""Markdown table of perf/scatter.csv (spheretouch-bench scatter --csv): p50/p99 round trip by
transport and worker count, the same run's single request-reply baseline, and the ratio to the
same run's raw ZeroMQ fan-out floor."""
import csv
import sys

rows = list(csv.DictReader(open(sys.argv[1] if len(sys.argv) > 1 else "perf/scatter.csv")))
gaps = sorted({int(r["gap_us"]) for r in rows})
for gap in gaps:
    print(f"\nRounds spaced {gap} us apart:\n")
    print("| transport | workers | p50 | p99 | max | incomplete | baseline req-rep p50 / p99 | raw fan-out floor p50 / p99 | p50 / floor | p99 / floor |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        if int(r["gap_us"]) != gap:
            continue
        p50, p99, b50, b99 = (float(r[k]) for k in ("p50_us", "p99_us", "baseline_p50_us", "baseline_p99_us"))
        f50, f99 = float(r.get("floor_p50_us") or 0), float(r.get("floor_p99_us") or 0)
        floor = f"{f50:.0f} / {f99:.0f} us | {p50 / f50:.2f}x | {p99 / f99:.2f}x" if f50 > 0 and f99 > 0 else "— | — | —"
        print(f"| {r['transport']} | {r['workers']} | {p50:.0f} us | {p99:.0f} us | {float(r['max_us']):.0f} us | "
              f"{r['incomplete']}/{r['rounds']} | {b50:.0f} / {b99:.0f} us | {floor} |")
