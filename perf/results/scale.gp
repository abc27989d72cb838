# SPDX-License-Identifier: BSD-3-Clause
set terminal pngcairo size 1380,420 font 'DejaVu Sans,9'
set output 'perf/results/scale.png'
set multiplot layout 1,3
set logscale x 2
set grid
set key left top font ",8"
set xlabel 'workers W'
set ylabel 'predicted speed-up vs one thread'
set title 'elephant (88,928 faces), pose 3: 1,564 contacts'
plot 'perf/results/scale.dat' index 0 using 1:2 with linespoints lw 2 lc rgb '#1f77b4' title 'block-cyclic, 10 GbE', 'perf/results/scale.dat' index 0 using 1:3 with lines dt 2 lw 1.5 lc rgb '#1f77b4' title 'block-cyclic, compute only', 'perf/results/scale.dat' index 1 using 1:2 with linespoints dt 3 lw 2 lc rgb '#9467bd' title 'block-cyclic, simulated, replicas, 10 GbE', 'perf/results/scale.dat' index 2 using 1:2 with linespoints lw 2 lc rgb '#d62728' title 'contiguous, 10 GbE', 'perf/results/scale.dat' index 2 using 1:3 with lines dt 2 lw 1.5 lc rgb '#d62728' title 'contiguous, compute only', 'perf/results/scale.dat' index 3 using 1:2 with linespoints lw 2 lc rgb '#2ca02c' title 'random, 10 GbE', 'perf/results/scale.dat' index 3 using 1:3 with lines dt 2 lw 1.5 lc rgb '#2ca02c' title 'random, compute only', 1 with lines lc rgb '#888888' dt 3 notitle
set title 'armadillo\_L1 (208,000 faces), pose 3: 1,475 contacts'
plot 'perf/results/scale.dat' index 4 using 1:2 with linespoints lw 2 lc rgb '#1f77b4' title 'block-cyclic, 10 GbE', 'perf/results/scale.dat' index 4 using 1:3 with lines dt 2 lw 1.5 lc rgb '#1f77b4' title 'block-cyclic, compute only', 'perf/results/scale.dat' index 5 using 1:2 with linespoints dt 3 lw 2 lc rgb '#9467bd' title 'block-cyclic, simulated, replicas, 10 GbE', 'perf/results/scale.dat' index 6 using 1:2 with linespoints lw 2 lc rgb '#d62728' title 'contiguous, 10 GbE', 'perf/results/scale.dat' index 6 using 1:3 with lines dt 2 lw 1.5 lc rgb '#d62728' title 'contiguous, compute only', 'perf/results/scale.dat' index 7 using 1:2 with linespoints lw 2 lc rgb '#2ca02c' title 'random, 10 GbE', 'perf/results/scale.dat' index 7 using 1:3 with lines dt 2 lw 1.5 lc rgb '#2ca02c' title 'random, compute only', 1 with lines lc rgb '#888888' dt 3 notitle
set title 'armadillo\_L2 (832,000 faces), pose 3: 1,477 contacts'
plot 'perf/results/scale.dat' index 8 using 1:2 with linespoints lw 2 lc rgb '#1f77b4' title 'block-cyclic, 10 GbE', 'perf/results/scale.dat' index 8 using 1:3 with lines dt 2 lw 1.5 lc rgb '#1f77b4' title 'block-cyclic, compute only', 'perf/results/scale.dat' index 9 using 1:2 with linespoints dt 3 lw 2 lc rgb '#9467bd' title 'block-cyclic, simulated, replicas, 10 GbE', 'perf/results/scale.dat' index 10 using 1:2 with linespoints lw 2 lc rgb '#d62728' title 'contiguous, 10 GbE', 'perf/results/scale.dat' index 10 using 1:3 with lines dt 2 lw 1.5 lc rgb '#d62728' title 'contiguous, compute only', 'perf/results/scale.dat' index 11 using 1:2 with linespoints lw 2 lc rgb '#2ca02c' title 'random, 10 GbE', 'perf/results/scale.dat' index 11 using 1:3 with lines dt 2 lw 1.5 lc rgb '#2ca02c' title 'random, compute only', 1 with lines lc rgb '#888888' dt 3 notitle
unset multiplot
