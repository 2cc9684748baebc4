# Plots the CSV of `contactgrid bench` like the course report's Figures 1–2:
#   <out>_time.{png,svg}    time per detection against N (linear axes)
#   <out>_loglog.{png,svg}  the same on log-log axes, with least-squares lines of log t on log N over
#                           N >= 2^14, slopes in the legend (slope 1 = linear scaling)
# Usage (bench runs this itself when gnuplot is on PATH):
#   gnuplot -e "csv='bench.csv'; out='bench'" jobs/plot_bench.gp
# Invariants: columns are looked up by the fixed CSV layout of src/bench.hpp; an empty field is a
# series not run at that N, and a series with no points is left out of the fit (never an error).

if (!exists("csv")) csv = 'bench.csv'
if (!exists("out")) out = 'bench'
nmin = 2**14

set datafile separator ','
# CSV columns (src/bench.hpp): 1 n, 6 bullet_scratch_s, 7 bullet_warm_s, 8 engine_cpu_s, 9 engine_cuda_s
cols = "6 7 8 9"
names = "'Bullet (double), from scratch' 'Bullet (double), warm step' 'contactgrid CPU' 'contactgrid CUDA'"
array slope[4]
array icept[4]
array npts[4]
have = ""   # the series with at least one point, e.g. "1 3"

# Least squares of log10(t) on log10(N), accumulated while "plotting" into a throw-away table, so
# that a series without points gives npts = 0 instead of a fit error.
do for [i=1:4] {
  c = int(word(cols, i))
  sx = 0; sy = 0; sxx = 0; sxy = 0; nn = 0; nall = 0
  set table $discard
  plot csv every ::1 using ((valid(c) && column(c) > 0) ? (nall = nall + 1) : 0, \
      ($1 >= nmin && valid(c) && column(c) > 0) ? \
      (lx = log10($1), ly = log10(column(c)), sx = sx + lx, sy = sy + ly, sxx = sxx + lx*lx, \
       sxy = sxy + lx*ly, nn = nn + 1) : 0):(0) with table
  unset table
  if (nall > 0) { have = have . sprintf(" %d", i) }
  npts[i] = nn
  den = nn*sxx - sx*sx
  slope[i] = (nn >= 2 && den != 0) ? (nn*sxy - sx*sy)/den : NaN
  icept[i] = (nn >= 2 && den != 0) ? (sy - slope[i]*sx)/nn : NaN
  if (nn >= 2) { print sprintf("%s: slope %.3f over %d points (N >= 2^14)", word(names, i), slope[i], nn) }
}
fitline(i, x) = (x >= nmin && npts[i] >= 2) ? 10**(icept[i] + slope[i]*log10(x)) : NaN
label(i) = npts[i] >= 2 ? sprintf("%s (slope %.2f)", word(names, i), slope[i]) : word(names, i)

set grid
set key top left
set xlabel 'N (spheres)'
set ylabel 'time per detection (s)'
set style data linespoints

if (words(have) == 0) { print "plot_bench.gp: ".csv." has no timings"; exit }

do for [t in "png svg"] {
  if (t eq "png") {
    set terminal pngcairo size 1000,700 enhanced font ",11"
  } else {
    set terminal svg size 1000,700 dynamic enhanced
  }
  set output sprintf("%s_time.%s", out, t)
  set title 'Contact detection time against N (uniform spheres)'
  unset logscale
  plot for [k=1:words(have)] csv every ::1 using 1:(column(int(word(cols, int(word(have, k)))))) \
       title word(names, int(word(have, k)))

  set output sprintf("%s_loglog.%s", out, t)
  set title 'Contact detection time against N, log-log, least-squares slopes for N >= 2^{14}'
  set logscale x 2
  set logscale y 10
  set format x '2^{%L}'
  set sample 200
  plot for [k=1:words(have)] csv every ::1 using 1:(column(int(word(cols, int(word(have, k)))))) \
         title label(int(word(have, k))) lc int(word(have, k)) pt 7, \
       for [k=1:words(have)] fitline(int(word(have, k)), x) notitle with lines dt 2 lc int(word(have, k))
  set format x '%g'
}
set output
