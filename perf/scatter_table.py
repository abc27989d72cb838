#!/usr/bin/env python3
"""Markdown table of perf/scatter.csv (spheretouch-bench scatter --csv): p50/p99 round trip by
transport and worker count, and the ratio to the same run's single request-reply baseline."""
import csv
import sys

rows = list(csv.DictReader(open(sys.argv[1] if len(sys.argv) > 1 else "perf/scatter.csv")))
gaps = sorted({int(r["gap_us"]) for r in rows})
for gap in gaps:
    print(f"\nRounds spaced {gap} us apart:\n")
    print("| transport | workers | p50 | p99 | max | incomplete | baseline req-rep p50 / p99 | p50 / baseline |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        if int(r["gap_us"]) != gap:
            continue
        p50, p99, b50, b99 = (float(r[k]) for k in ("p50_us", "p99_us", "baseline_p50_us", "baseline_p99_us"))
        print(f"| {r['transport']} | {r['workers']} | {p50:.0f} us | {p99:.0f} us | {float(r['max_us']):.0f} us | "
              f"{r['incomplete']}/{r['rounds']} | {b50:.0f} / {b99:.0f} us | {p50 / b50:.1f}x |")
