# Draws report_acuity.png from report_acuity_plot.dat; written by fovea-error-report. Run: gnuplot report_acuity.gp
set terminal pngcairo size 1800,700 font 'sans,11'
set output 'report_acuity.png'
set multiplot layout 1,2 title "fovea: every ACUITY setting, bytes and time against error, tum:../shared/data/tum-fr3-teddy 640x480, 10 frames (scalar reference)"
set grid
set autoscale xfix
set offsets graph 0.05, graph 0.1, graph 0.05, graph 0.05
unset key
set yrange [-2:*]
set logscale x
set xtics add (0.02, 0.05, 0.2, 0.5, 2, 5)
set xlabel 'bytes per frame on the wire [MB] (fovea chunk codec, 1200-byte datagrams; log scale)'
set ylabel 'input points displaced by more than the MAR at their eccentricity [%]'
set title 'm = 0.022: perceptual error against size (a line per setting through its margins k)'
plot 'report_acuity_plot.dat' index 0 using 3:6 with linespoints lw 1.5 pt 5 ps 1.4 lc 'black' notitle, \
     '' index 0 every 2 using 3:6:1 with labels left offset char 1,0.7 tc 'black' notitle, \
     '' index 0 every 2::1 using 3:6:1 with labels left offset char 1,-0.7 tc 'black' notitle, \
     'report_acuity_plot.dat' index 1 using 3:6 with linespoints lw 1.5 pt 6 ps 1.6 lc 1 notitle, \
     '' index 1 using 3:6:1 with labels right offset char -0.6,-0.9 tc lt 1 notitle, \
     'report_acuity_plot.dat' index 2 using 3:6 with linespoints lw 1.5 pt 8 ps 1.6 lc 2 notitle, \
     'report_acuity_plot.dat' index 3 using 3:6 with linespoints lw 1.5 pt 4 ps 1.6 lc 3 notitle, \
     'report_acuity_plot.dat' index 4 using 3:6 with linespoints lw 1.5 pt 10 ps 1.6 lc 4 notitle, \
     'report_acuity_plot.dat' index 5 using 3:6 with linespoints lw 1.5 pt 12 ps 1.6 lc 5 notitle, \
     'report_acuity_plot.dat' index 6 using 3:6 with linespoints lw 1.5 pt 14 ps 1.6 lc 6 notitle, \
     'report_acuity_plot.dat' index 7 using 3:6 with linespoints lw 1.5 pt 1 ps 1.6 lc 7 notitle
set key outside right top vertical box
set autoscale y
unset logscale x
set xtics autofreq
set xlabel 'CPU time per frame [ms], median: back-projection through sampled output'
set ylabel 'RMS distance from each input point to its representative [mm]'
set title 'm = 0.022: geometric error against time'
plot 'report_acuity_plot.dat' index 0 using 4:5 with points lw 1.5 pt 5 ps 1.4 lc 'black' title 'F1, F2, F3, FREF', \
     '' index 0 using 4:5:1 with labels right offset char -0.8,0.9 tc 'black' notitle, \
     'report_acuity_plot.dat' index 1 using 4:5 with points lw 1.5 pt 6 ps 1.6 lc 1 title 'ACUITY', \
     'report_acuity_plot.dat' index 2 using 4:5 with points lw 1.5 pt 8 ps 1.6 lc 2 title 'ACUITY floor 16mm', \
     'report_acuity_plot.dat' index 3 using 4:5 with points lw 1.5 pt 4 ps 1.6 lc 3 title 'ACUITY floor 1mm*r^2', \
     'report_acuity_plot.dat' index 4 using 4:5 with points lw 1.5 pt 10 ps 1.6 lc 4 title 'ACUITY floor 2mm*r^2', \
     'report_acuity_plot.dat' index 5 using 4:5 with points lw 1.5 pt 12 ps 1.6 lc 5 title 'ACUITY k=0.30 refined 1', \
     'report_acuity_plot.dat' index 6 using 4:5 with points lw 1.5 pt 14 ps 1.6 lc 6 title 'ACUITY k=0.12 refined 2', \
     'report_acuity_plot.dat' index 7 using 4:5 with points lw 1.5 pt 1 ps 1.6 lc 7 title 'ACUITY k=0.15 refined 7'
unset multiplot
