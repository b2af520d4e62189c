# Draws report.png from report_plot.dat; written by fovea-error-report. Run: gnuplot report.gp
set terminal pngcairo size 1500,620 font 'sans,11'
set output 'report.png'
set multiplot layout 1,2 title "fovea: bytes and time against error, mock:living-room 640x480, 30 frames (scalar reference)"
set grid
set autoscale xfix
set offsets graph 0.05, graph 0.1, graph 0.05, graph 0.05
set key top right box opaque
set yrange [-2:*]
unset logscale x
set xlabel 'bytes per frame on the wire [MB] (fovea chunk codec, 1200-byte datagrams)'
set ylabel 'input points displaced by more than the MAR at their eccentricity [%]'
set title 'perceptual error against size (a colour per slope m)'
plot 'report_plot.dat' index 0 using 3:6 with linespoints lw 1.5 pt 5 ps 1.6 lc 1 title 'F1, m = 0.022', \
     '' index 0 every 2 using 3:6:1 with labels left offset char 1,0.7 tc lt 1 notitle, \
     'report_plot.dat' index 1 using 3:6:9 with points pt 12 ps 1.8 lw 1.5 lc variable notitle, \
     keyentry with points pt 12 ps 1.8 lw 1.5 lc 'black' title 'ACUITY k=0.50'
unset key
unset logscale x
set xtics autofreq
set xlabel 'CPU time per frame [ms], median: back-projection through sampled output'
set ylabel 'RMS distance from each input point to its representative [mm]'
set title 'geometric error against time (symbols as on the left)'
plot 'report_plot.dat' index 0 using 4:5 with points pt 5 ps 1.6 lc 1 title 'F1, m = 0.022', \
     '' index 0 using 4:5:1 with labels offset char 1.5,0.9 tc lt 1 notitle, \
     'report_plot.dat' index 1 using 4:5:9 with points pt 12 ps 1.8 lw 1.5 lc variable notitle
unset multiplot
