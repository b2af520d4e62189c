# Draws bandwidth.png from bandwidth.dat; written by fovea-eval. Run: gnuplot bandwidth.gp
set terminal pngcairo size 900,500 noenhanced
set output 'bandwidth.png'
set title 'Bandwidth at the socket per condition (mean over HMD positions, error bar: SD)'
set ylabel 'MB/s (UDP payloads + IP/UDP headers)'
set style data histogram
set style histogram errorbars gap 2 lw 1
set style fill solid 0.7 border -1
set key top left
set yrange [0:*]
set grid ytics
plot 'bandwidth.dat' using 2:3:xtic(1) title 'living-room', 'bandwidth.dat' using 4:5:xtic(1) title 'balloon', 'bandwidth.dat' using 6:7:xtic(1) title 'tum'
