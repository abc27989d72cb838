# SPDX-License-Identifier: BSD-3-Clause
set terminal pngcairo size 900,560 font 'DejaVu Sans,10'
set datafile separator ','
set key outside right top
set grid
set output 'perf/results/table3.png'
set title 'Table 3: collision rounds per second vs workers (solid ~100, dashed ~1,500 contacts)'
set xlabel 'workers (0 = collision thread)'
set ylabel 'rounds / s'
set logscale y
set xtics (0,1,2,4,8)
plot 'perf/results/table3_plot.dat' index 0 using 1:2 with linespoints lw 2 dt 1 title 'icosphere 100', 'perf/results/table3_plot.dat' index 1 using 1:2 with linespoints lw 2 dt 2 title 'icosphere 300', 'perf/results/table3_plot.dat' index 2 using 1:2 with linespoints lw 2 dt 1 title 'elephant 100', 'perf/results/table3_plot.dat' index 3 using 1:2 with linespoints lw 2 dt 2 title 'elephant 1500', 'perf/results/table3_plot.dat' index 4 using 1:2 with linespoints lw 2 dt 1 title 'armadillo\_L1 100', 'perf/results/table3_plot.dat' index 5 using 1:2 with linespoints lw 2 dt 2 title 'armadillo\_L1 1500', 'perf/results/table3_plot.dat' index 6 using 1:2 with linespoints lw 2 dt 1 title 'armadillo\_L2 100', 'perf/results/table3_plot.dat' index 7 using 1:2 with linespoints lw 2 dt 2 title 'armadillo\_L2 1500'
