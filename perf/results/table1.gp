# SPDX-License-Identifier: BSD-3-Clause
set terminal pngcairo size 900,560 font 'DejaVu Sans,10'
set datafile separator ','
set key outside right top
set grid
set output 'perf/results/table1.png'
set title 'Table 1: collision round vs contacts, hand\_L2 x elephant (median)'
set xlabel 'contacts'
set ylabel 'round time, ms'
set logscale y
plot 'perf/results/table1_plot.dat' index 0 using 1:2 with linespoints lw 2 title '0 workers', 'perf/results/table1_plot.dat' index 1 using 1:2 with linespoints lw 2 title '1 workers', 'perf/results/table1_plot.dat' index 2 using 1:2 with linespoints lw 2 title '2 workers', 'perf/results/table1_plot.dat' index 3 using 1:2 with linespoints lw 2 title '4 workers', 'perf/results/table1_plot.dat' index 4 using 1:2 with linespoints lw 2 title '8 workers'
