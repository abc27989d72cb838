# SPDX-License-Identifier: BSD-3-Clause
set terminal pngcairo size 900,560 font 'DejaVu Sans,10'
set datafile separator ','
set key outside right top
set grid
set output 'perf/results/trade_pareto.png'
set title 'Speed/accuracy trade: collision cost per haptic tick vs RMS force error'
set xlabel 'collision work per 1 ms tick, us (log)'
set ylabel 'RMS force error vs exact every-tick reference, N'
set logscale x
set key inside top right
plot 'perf/results/trade_plot.dat' index 2 using 1:2 with lines lw 2 lc rgb '#999999' title 'Pareto front', '' index 0 using 1:2 with points pt 7 ps 1.5 title 'mesh level (1 kHz, hold)', '' index 1 using 1:2 with points pt 5 ps 1.2 title 'rate cap x interpolation (L2)', '' index 0 using 1:2:3 with labels offset 1,0.6 left font ',8' notitle, '' index 1 using 1:2:3 with labels offset 1,-0.6 left font ',8' notitle
