#!/usr/bin/env python3
# SPDX-License-Identifier: BSD-3-Clause
"""Plots spheretouch-bench scale --json output: predicted speed-up against one thread vs the
number of workers W, one line per mapping, on the 10 GbE model (solid) and compute only (no
network, dashed), and for block-cyclic the 10 GbE round simulated event by event with the
replicated deal (dotted, where the JSON has it), for the pose closest to --contacts contacts. OUT.svg is written directly (no
dependencies); OUT.png through gnuplot (OUT.dat and OUT.gp beside it).

usage: scale_plot.py OUT.svg|OUT.png SCALE.json [SCALE.json ...] [--contacts 1500]"""
import json
import math
import subprocess
import sys

COLOURS = {'block-cyclic': '#1f77b4', 'contiguous': '#d62728', 'random': '#2ca02c'}
# The block-cyclic round simulated event by event with the replicated deal (one line, no compute-only twin).
SIMULATED = 'block-cyclic, simulated, replicas'
COLOURS[SIMULATED] = '#9467bd'


def load(paths, want):
    panels = []
    for p in paths:
        with open(p) as f:
            d = json.load(f)
        rows = d['rows']
        poses = sorted({(r['pose'], r['contacts']) for r in rows}, key=lambda pc: abs(pc[1] - want))
        pose, contacts = poses[0]
        name = d['object'].split('/')[-1].rsplit('.', 1)[0]
        lines = {}
        for r in rows:
            if r['pose'] != pose or r['speedup_10GbE'] is None or r['compute_speedup'] is None:
                continue  # null: a speed-up the bench could not compute (a zero time)
            lines.setdefault(r['mapping'], []).append((r['workers'], r['speedup_10GbE'], r['compute_speedup']))
            sim = r.get('speedup_10GbE_simulated_replicated')
            if r['mapping'] == 'block-cyclic' and sim is not None:
                lines.setdefault(SIMULATED, []).append((r['workers'], sim, None))
        panels.append((f"{name} ({d['object_faces']:,} faces), pose {pose}: {contacts:,} contacts", lines))
    return panels


def svg(panels, out):
    pw, ph, m = 420, 300, 50
    width, height = pw * len(panels), ph + 60
    o = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" '
         f'font-size="11"><rect width="100%" height="100%" fill="white"/>']
    for k, (title, lines) in enumerate(panels):
        x0 = k * pw + m
        x1, y0, y1 = x0 + pw - m - 20, ph - 10, 40
        ws = sorted({w for pts in lines.values() for w, _, _ in pts})
        ymax = max([max(s, c if c is not None else s) for pts in lines.values() for _, s, c in pts] + [1.0])
        ymax = 2 ** math.ceil(math.log2(max(ymax, 1.0)))
        lx = lambda w: x0 + (x1 - x0) * (math.log2(w) / max(math.log2(ws[-1]), 1))
        ly = lambda v: y0 - (y0 - y1) * (v / ymax)
        o.append(f'<text x="{x0}" y="22" font-size="12">{title}</text>')
        o.append(f'<line x1="{x0}" y1="{y0}" x2="{x1}" y2="{y0}" stroke="black"/>')
        o.append(f'<line x1="{x0}" y1="{y0}" x2="{x0}" y2="{y1}" stroke="black"/>')
        for w in ws:
            o.append(f'<text x="{lx(w):.1f}" y="{y0 + 14}" text-anchor="middle">{w}</text>')
        for i in range(0, 5):
            v = ymax * i / 4
            o.append(f'<text x="{x0 - 6}" y="{ly(v) + 4:.1f}" text-anchor="end">{v:g}</text>')
            o.append(f'<line x1="{x0}" y1="{ly(v):.1f}" x2="{x1}" y2="{ly(v):.1f}" stroke="#ddd"/>')
        o.append(f'<text x="{(x0 + x1) / 2}" y="{y0 + 30}" text-anchor="middle">workers W</text>')
        o.append(f'<text x="{x0 - 36}" y="{(y0 + y1) / 2}" transform="rotate(-90 {x0 - 36} {(y0 + y1) / 2})" '
                 f'text-anchor="middle">speed-up vs one thread</text>')
        # y = 1: where distribution starts to pay.
        o.append(f'<line x1="{x0}" y1="{ly(1):.1f}" x2="{x1}" y2="{ly(1):.1f}" stroke="#888" stroke-dasharray="2,3"/>')
        for j, (mapping, pts) in enumerate(sorted(lines.items())):
            pts.sort()
            col = COLOURS.get(mapping, 'black')
            for idx, dash in ((1, ' stroke-dasharray="1,3"' if mapping == SIMULATED else ''), (2, ' stroke-dasharray="5,4"')):
                if any(p[idx] is None for p in pts):
                    continue
                path = ' '.join(f'{"M" if i == 0 else "L"}{lx(p[0]):.1f},{ly(p[idx]):.1f}' for i, p in enumerate(pts))
                o.append(f'<path d="{path}" fill="none" stroke="{col}" stroke-width="1.8"{dash}/>')
            o.append(f'<text x="{x0 + 10}" y="{y1 + 14 * j + 4}" fill="{col}">{mapping}</text>')
        o.append(f'<text x="{x0 + 110}" y="{y1 + 4}">solid: 10 GbE model; dashed: compute only; dotted: simulated</text>')
    o.append('</svg>')
    with open(out, 'w') as f:
        f.write('\n'.join(o) + '\n')


def png(panels, out):
    base = out[:-4]
    blocks, plots = [], []
    for k, (title, lines) in enumerate(panels):
        cmds = []
        for mapping, pts in sorted(lines.items()):
            pts.sort()
            i = len(blocks)
            col = COLOURS.get(mapping, 'black')
            if mapping == SIMULATED:
                blocks.append('\n'.join(f'{w} {s:.4f}' for w, s, _ in pts))
                cmds.append(f"'{base}.dat' index {i} using 1:2 with linespoints dt 3 lw 2 lc rgb '{col}' title '{mapping}, 10 GbE'")
                continue
            blocks.append('\n'.join(f'{w} {s:.4f} {c:.4f}' for w, s, c in pts))
            cmds.append(f"'{base}.dat' index {i} using 1:2 with linespoints lw 2 lc rgb '{col}' title '{mapping}, 10 GbE'")
            cmds.append(f"'{base}.dat' index {i} using 1:3 with lines dt 2 lw 1.5 lc rgb '{col}' title '{mapping}, compute only'")
        plots.append((title, cmds))
    with open(base + '.dat', 'w') as f:
        f.write('\n\n\n'.join(blocks) + '\n')
    gp = [f"set terminal pngcairo size {460 * len(panels)},420 font 'DejaVu Sans,9'", f"set output '{out}'",
          f'set multiplot layout 1,{len(panels)}', 'set logscale x 2', 'set grid', 'set key left top font ",8"',
          "set xlabel 'workers W'", "set ylabel 'predicted speed-up vs one thread'"]
    for title, cmds in plots:
        escaped = title.replace('_', '\\_')
        gp.append(f"set title '{escaped}'")
        gp.append('plot ' + ', '.join(cmds) + ", 1 with lines lc rgb '#888888' dt 3 notitle")
    gp.append('unset multiplot')
    with open(base + '.gp', 'w') as f:
        f.write('# SPDX-License-Identifier: BSD-3-Clause\n' + '\n'.join(gp) + '\n')
    subprocess.run(['gnuplot', base + '.gp'], check=True)


def main(argv):
    if len(argv) < 3:
        sys.exit(__doc__)
    want = 1500
    if '--contacts' in argv:
        i = argv.index('--contacts')
        want = int(argv[i + 1])
        del argv[i:i + 2]
    panels = load(argv[2:], want)
    (png if argv[1].endswith('.png') else svg)(panels, argv[1])


if __name__ == '__main__':
    main(sys.argv)
