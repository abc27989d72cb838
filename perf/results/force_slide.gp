# SPDX-License-Identifier: BSD-3-Clause
set terminal pngcairo size 900,560 font 'DejaVu Sans,10'
set datafile separator ','
set key outside right top
set grid
set output 'perf/results/force_slide.png'
set title 'hand\_L2 sliding on the elephant (open loop): force along the slide'
set xlabel 'slide, mm'
set ylabel '|F|, N'
set y2label 'direction turn per 1 ms tick, degrees'
set y2tics
set ytics nomirror
set key inside top right
plot 'perf/results/force_slide.dat' index 0 using 1:2 with lines lw 2 lc rgb '#cc3333' title 'paper: |F|', '' index 1 using 1:2 with lines lw 2 lc rgb '#3366cc' title 'patch: |F|', '' index 0 using 1:3 axes x1y2 with lines lw 1 lc rgb '#ee9999' title 'paper: turn', '' index 1 using 1:3 axes x1y2 with lines lw 1 lc rgb '#99bbee' title 'patch: turn'
