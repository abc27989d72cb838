# SPDX-License-Identifier: BSD-3-Clause
set terminal pngcairo size 900,560 font 'DejaVu Sans,10'
set datafile separator ','
set key outside right top
set grid
set output 'perf/results/table2.png'
set title 'Table 2: haptic rate, single thread vs spheretouch'
set style data histograms
set style histogram clustered gap 1
set style fill solid 0.8 border -1
set logscale y
set ylabel 'Hz'
set yrange [100:1500]
set xtics rotate by -30
plot 'perf/results/table2_plot.dat' using 2:xtic(1) title 'single thread: haptic = collision', '' using 3 title 'spheretouch haptic', '' using 4 title 'spheretouch collision'
