# Draws report.png from report_plot.dat; written by fovea-error-report. Run: gnuplot report.gp
set terminal pngcairo size 1500,620 font 'sans,11'
set output 'report.png'
set multiplot layout 1,2 title "fovea: bytes and time against error, mock:living-room 640x480, 30 frames (scalar reference)"
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
     '' index 1 using 3:6:1 with labels offset char 1.2,0.8 tc lt 1 notitle, \
     'report_plot.dat' index 2 using 3:6 with linespoints lw 1.5 pt 7 ps 1.6 lc 2 title 'm = 0.028', \
     '' index 2 using 3:6:1 with labels offset char 1.2,-0.8 tc lt 2 notitle, \
     'report_plot.dat' index 3 using 3:6 with linespoints lw 1.5 pt 8 dt 4 ps 1.6 lc 2 title 'ACUITY, m = 0.028', \
     'report_plot.dat' index 4 using 3:6 with linespoints lw 1.5 pt 9 ps 1.6 lc 3 title 'm = 0.034', \
     '' index 4 using 3:6:1 with labels offset char -2.5,0.8 tc lt 3 notitle, \
     'report_plot.dat' index 5 using 3:6 with linespoints lw 1.5 pt 10 dt 4 ps 1.6 lc 3 title 'ACUITY, m = 0.034', \
     'report_plot.dat' index 2 using 3:8 with linespoints dt 2 lw 1 pt 6 ps 1.3 lc 2 title 'm = 0.028, judged by an m = 0.022 eye', \
     'report_plot.dat' index 4 using 3:8 with linespoints dt 2 lw 1 pt 8 ps 1.3 lc 3 title 'm = 0.034, judged by an m = 0.022 eye'
unset logscale x
set key top left box opaque
set xlabel 'CPU time per frame [ms], median: back-projection through sampled output'
set ylabel 'RMS distance from each input point to its representative [mm]'
set title 'geometric error against time'
plot 'report_plot.dat' index 0 using 4:5 with points pt 5 ps 1.6 lc 1 title 'm = 0.022', \
     '' index 0 using 4:5:1 with labels offset char 1.2,0.8 tc lt 1 notitle, \
     'report_plot.dat' index 1 using 4:5 with points pt 6 ps 1.6 lc 1 title 'ACUITY, m = 0.022', \
     '' index 1 using 4:5:1 with labels offset char 1.2,0.8 tc lt 1 notitle, \
     'report_plot.dat' index 2 using 4:5 with points pt 7 ps 1.6 lc 2 title 'm = 0.028', \
     '' index 2 using 4:5:1 with labels offset char 1.2,-0.8 tc lt 2 notitle, \
     'report_plot.dat' index 3 using 4:5 with points pt 8 ps 1.6 lc 2 title 'ACUITY, m = 0.028', \
     'report_plot.dat' index 4 using 4:5 with points pt 9 ps 1.6 lc 3 title 'm = 0.034', \
     '' index 4 using 4:5:1 with labels offset char -2.5,0.8 tc lt 3 notitle, \
     'report_plot.dat' index 5 using 4:5 with points pt 10 ps 1.6 lc 3 title 'ACUITY, m = 0.034'
unset multiplot
