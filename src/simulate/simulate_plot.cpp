// Plots of a simulate run (simulate_plot.hpp).
#include "simulate/simulate_plot.hpp"

#include <fmt/format.h>

#include "io/text_file.hpp"
#include "run/subprocess.hpp"

namespace cg {

namespace {
// gnuplot `body` into <prefix>.png (pngcairo, else png) and <prefix>.svg.
bool gnuplot_both(const std::string& gnuplot, const std::string& prefix, const std::string& size,
                  const std::string& body) {
  bool ok = true;
  for (const char* term : {"png", "svg"}) {
    auto script = [&](const char* t) {
      return fmt::format("set terminal {} size {}; set output '{}.{}'; {}", t, size, prefix, term, body);
    };
    if (run_program({gnuplot, "-e", script(term == std::string("png") ? "pngcairo" : "svg")}) != 0)
      ok = ok && run_program({gnuplot, "-e", script(term)}) == 0;
  }
  return ok;
}
}  // namespace

bool plot_run_log(const std::string& log_csv, const std::string& prefix, bool quiet) {
  const std::string gnuplot = find_on_path("gnuplot");
  if (gnuplot.empty()) {
    if (!quiet) fmt::print("  plots: gnuplot is not on PATH (log.csv has the numbers)\n");
    return false;
  }
  // energy on the left axis, contacts on the right; the status lines (#) are comments to gnuplot
  const std::string body = fmt::format(
      "set datafile separator ','; set key autotitle columnhead; set xlabel 'step'; set ylabel 'energy'; "
      "set y2label 'contacts'; set y2tics; set ytics nomirror; set grid; "
      "plot '{0}' using 1:3 with lines title 'kinetic', '' using 1:4 with lines title 'potential', "
      "'' using 1:($3+$4) with lines title 'total', '' using 1:5 axes x1y2 with lines title 'contacts'",
      log_csv);
  const bool ok = gnuplot_both(gnuplot, prefix, "900,500", body);
  if (!quiet) fmt::print("  plots: {} {}.png, {}.svg\n", ok ? "wrote" : "gnuplot failed on", prefix, prefix);
  return ok;
}

bool plot_final_state(const DemBodies& b, const std::string& prefix, bool quiet) {
  const std::string gnuplot = find_on_path("gnuplot");
  if (gnuplot.empty()) return false;
  std::string table;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const bool ell = !b.shape.empty() && b.shape[i] == Shape::ellipsoid;
    const double r = ell ? (b.semi_axes[i].x + b.semi_axes[i].y + b.semi_axes[i].z) / 3 : b.radius[i];
    table += fmt::format("{} {} {}\n", b.position[i].x, b.position[i].z, r);
  }
  write_text_file(prefix + ".dat", table);
  const std::string body = fmt::format(
      "set size ratio -1; set xlabel 'x'; set ylabel 'z'; unset key; "
      "plot '{}.dat' using 1:2:3 with circles fill solid 0.5 noborder lc rgb '#3060a0'",
      prefix);
  const bool ok = gnuplot_both(gnuplot, prefix, "800,800", body);
  if (!quiet)
    fmt::print("  final state: {} {}.png, {}.svg\n", ok ? "wrote" : "gnuplot failed on", prefix, prefix);
  return ok;
}

}  // namespace cg
