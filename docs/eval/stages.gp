# Draws stages.png from stages.dat; written by fovea-eval. Run: gnuplot stages.gp
set terminal pngcairo size 1260,520 noenhanced
set output 'stages.png'
set style data histogram
set style histogram rowstacked
set style fill solid 0.8 border -1
set key outside bottom horizontal
set ylabel 'ms (mean per frame), capture to decoded'
set grid ytics
set yrange [0:*]
set multiplot layout 1,3
set title 'living-room'
unset key
plot for [c=3:10] 'stages.dat' index 0 using c:xtic(1) title columnheader(c)
set title 'balloon'
unset key
plot for [c=3:10] 'stages.dat' index 1 using c:xtic(1) title columnheader(c)
set title 'tum'
set key
plot for [c=3:10] 'stages.dat' index 2 using c:xtic(1) title columnheader(c)
unset multiplot
