# SPDX-License-Identifier: BSD-3-Clause
set terminal pngcairo size 900,560 font 'DejaVu Sans,10'
set datafile separator ','
set key outside right top
set grid
set output 'perf/results/trade_trace.png'
set title 'Force along the press/slide script (armadillo): reference vs configurations'
set xlabel 't, s'
set ylabel '|F|, N'
set key inside top left
plot 'perf/results/trade_trace.csv' using 1:2 with lines lw 2 title 'reference', 'perf/results/trade_trace.csv' using 1:3 with lines lw 1 title 'armadillo leaf24 1000Hz hold', 'perf/results/trade_trace.csv' using 1:15 with lines lw 1 title 'armadillo\_L2 leaf24 25Hz hold', 'perf/results/trade_trace.csv' using 1:16 with lines lw 1 title 'armadillo\_L2 leaf24 25Hz paper', 'perf/results/trade_trace.csv' using 1:17 with lines lw 1 title 'armadillo\_L2 leaf24 25Hz plane'
