# Draws report_acuity.png from report_acuity_plot.dat; written by fovea-error-report. Run: gnuplot report_acuity.gp
set terminal pngcairo size 1800,700 font 'sans,11'
set output 'report_acuity.png'
set multiplot layout 1,2 title "fovea: every ACUITY setting, bytes and time against error, mock:living-room 640x480, 30 frames (scalar reference)"
set grid
set autoscale xfix
set offsets graph 0.05, graph 0.1, graph 0.05, graph 0.05
unset key
set yrange [-2:*]
unset logscale x
set xlabel 'bytes per frame on the wire [MB] (fovea chunk codec, 1200-byte datagrams)'
set ylabel 'input points displaced by more than the MAR at their eccentricity [%]'
set title 'm = 0.022: perceptual error against size (a line per setting through its margins k)'
plot 'report_acuity_plot.dat' index 0 using 3:6 with linespoints lw 1.5 pt 5 ps 1.4 lc 'black' notitle, \
     '' index 0 every 2 using 3:6:1 with labels left offset char 1,0.7 tc 'black' notitle, \
     'report_acuity_plot.dat' index 1 using 3:6 with linespoints lw 1.5 pt 6 ps 1.6 lc 1 notitle
set key outside right top vertical box
set autoscale y
unset logscale x
set xtics autofreq
set xlabel 'CPU time per frame [ms], median: back-projection through sampled output'
set ylabel 'RMS distance from each input point to its representative [mm]'
set title 'm = 0.022: geometric error against time'
plot 'report_acuity_plot.dat' index 0 using 4:5 with points lw 1.5 pt 5 ps 1.4 lc 'black' title 'F1', \
     '' index 0 using 4:5:1 with labels right offset char -0.8,0.9 tc 'black' notitle, \
     'report_acuity_plot.dat' index 1 using 4:5 with points lw 1.5 pt 6 ps 1.6 lc 1 title 'ACUITY k=0.50'
unset multiplot
