# Draws report.png from report_plot.dat; written by fovea-error-report. Run: gnuplot report.gp
set terminal pngcairo size 1500,620 font 'sans,11'
set output 'report.png'
set multiplot layout 1,2 title "fovea: bytes and time against error, mock:living-room 640x480, 10 frames (scalar reference)"
set grid
set key top right box opaque
set offsets graph 0.05, graph 0.05, graph 0.05, graph 0.05
set logscale x
set yrange [-2:*]
set xlabel 'bytes per frame on the wire [MB] (fovea chunk codec, 1200-byte datagrams; log scale)'
set ylabel 'input points displaced by more than the MAR at their eccentricity [%]'
set title 'perceptual error against size'
plot 'report_plot.dat' index 0 using 3:6 with linespoints lw 1.5 pt 5 ps 1.6 lc 1 title 'm = 0.022', \
     '' index 0 using 3:6:1 with labels offset char 1.2,0.8 tc lt 1 notitle, \
     'report_plot.dat' index 1 using 3:6 with linespoints lw 1.5 pt 6 dt 4 ps 1.6 lc 1 title 'ACUITY, m = 0.022', \
     '' index 1 using 3:6:1 with labels offset char 1.2,0.8 tc lt 1 notitle
unset logscale x
set key top left box opaque
set xlabel 'CPU time per frame [ms], median: back-projection through sampled output'
set ylabel 'RMS distance from each input point to its representative [mm]'
set title 'geometric error against time'
plot 'report_plot.dat' index 0 using 4:5 with points pt 5 ps 1.6 lc 1 title 'm = 0.022', \
     '' index 0 using 4:5:1 with labels offset char 1.2,0.8 tc lt 1 notitle, \
     'report_plot.dat' index 1 using 4:5 with points pt 6 ps 1.6 lc 1 title 'ACUITY, m = 0.022', \
     '' index 1 using 4:5:1 with labels offset char 1.2,0.8 tc lt 1 notitle
unset multiplot
