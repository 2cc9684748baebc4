// The study's plot (study.hpp: study_svg): time against error on log-log axes, as SVG text.
// One point per row (mode × tolerance × backend × family), a colour per mode, a marker per backend
// (circle CPU, square CUDA); per family, the Pareto-optimal points (no other point of the family both
// at most as slow and at most as wrong, one of them strictly) are filled and joined by a line, the
// others hollow. Refused rows are not drawn.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "study/study.hpp"

namespace cg {
namespace {

constexpr double kWidth = 900, kHeight = 600, kLeft = 80, kRight = 220, kTop = 40, kBottom = 60;
constexpr double kErrorFloor = 1e-17;  // an exact answer is drawn here
const char* const kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"};

struct Dot {
  double x, y;  // log10 time ms, log10 error
  const StudyRow* row;
};

double error_of(const StudyRow& r) { return std::max(r.errors.max_position_rel, kErrorFloor); }

bool dominates(const Dot& a, const Dot& b) { return a.x <= b.x && a.y <= b.y && (a.x < b.x || a.y < b.y); }

std::string escape(const std::string& s) {
  std::string out;
  for (char c : s) out += c == '<' ? "&lt;" : c == '>' ? "&gt;" : c == '&' ? "&amp;" : std::string(1, c);
  return out;
}

}  // namespace

std::string study_svg(const std::vector<StudyRow>& rows) {
  std::vector<Dot> dots;
  for (const StudyRow& r : rows)
    if (!r.refused && r.seconds > 0)
      dots.push_back({std::log10(r.seconds * 1e3), std::log10(error_of(r)), &r});
  double x0 = -2, x1 = 1, y0 = -17, y1 = 0;
  if (!dots.empty()) {
    auto [xmin, xmax] =
        std::minmax_element(dots.begin(), dots.end(), [](auto& a, auto& b) { return a.x < b.x; });
    auto [ymin, ymax] =
        std::minmax_element(dots.begin(), dots.end(), [](auto& a, auto& b) { return a.y < b.y; });
    x0 = std::floor(xmin->x), x1 = std::max(std::ceil(xmax->x), x0 + 1);
    y0 = std::floor(ymin->y), y1 = std::max(std::ceil(ymax->y), y0 + 1);
  }
  auto px = [&](double x) { return kLeft + (x - x0) / (x1 - x0) * (kWidth - kLeft - kRight); };
  auto py = [&](double y) { return kHeight - kBottom - (y - y0) / (y1 - y0) * (kHeight - kTop - kBottom); };

  std::string s = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\" font-family=\"sans-serif\" "
      "font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
      "<text x=\"{}\" y=\"22\" font-size=\"14\">contactgrid study: time vs max position error / r "
      "(filled: Pareto-optimal in its family)</text>\n",
      kWidth, kHeight, kLeft);
  for (double x = x0; x <= x1; ++x)
    s += fmt::format(
        "<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\" stroke=\"#ddd\"/><text x=\"{0}\" y=\"{3}\" "
        "text-anchor=\"middle\">1e{4}</text>\n",
        px(x), py(y0), py(y1), py(y0) + 16, int(x));
  for (double y = y0; y <= y1; ++y)
    s += fmt::format(
        "<line x1=\"{1}\" y1=\"{0}\" x2=\"{2}\" y2=\"{0}\" stroke=\"#ddd\"/><text x=\"{3}\" y=\"{4}\" "
        "text-anchor=\"end\">1e{5}</text>\n",
        py(y), px(x0), px(x1), px(x0) - 6, py(y) + 4, int(y));
  s += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">time per detect (ms, median)</text>\n",
                   px((x0 + x1) / 2), kHeight - 15);
  s += fmt::format(
      "<text transform=\"translate(18,{}) rotate(-90)\" text-anchor=\"middle\">max |p − p_exact| / r "
      "(exact drawn at 1e-17)</text>\n",
      py((y0 + y1) / 2));

  std::map<std::string, std::string> colour;
  for (const Dot& d : dots)
    if (!colour.count(d.row->mode)) colour[d.row->mode] = kColours[colour.size() % std::size(kColours)];
  std::map<std::string, std::vector<const Dot*>> front;  // family → its Pareto-optimal dots
  for (const Dot& d : dots) {
    const bool optimal = std::none_of(dots.begin(), dots.end(), [&](const Dot& o) {
      return o.row->family == d.row->family && dominates(o, d);
    });
    if (optimal) front[d.row->family].push_back(&d);
    const std::string fill = optimal ? colour[d.row->mode] : "none";
    if (d.row->backend == std::string("cuda"))
      s += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"8\" height=\"8\" fill=\"{}\" stroke=\"{}\"/>\n",
                       px(d.x) - 4, py(d.y) - 4, fill, colour[d.row->mode]);
    else
      s += fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"4\" fill=\"{}\" stroke=\"{}\"/>\n", px(d.x), py(d.y),
                       fill, colour[d.row->mode]);
  }
  for (auto& [family, f] : front) {
    std::sort(f.begin(), f.end(), [](const Dot* a, const Dot* b) { return a->x < b->x; });
    std::string path;
    for (const Dot* d : f) path += fmt::format("{}{},{}", path.empty() ? "M" : " L", px(d->x), py(d->y));
    s += fmt::format("<path d=\"{}\" fill=\"none\" stroke=\"#888\" stroke-dasharray=\"3,3\"/>\n", path);
    s += fmt::format("<text x=\"{}\" y=\"{}\" fill=\"#444\">{}</text>\n", px(f.front()->x) + 6,
                     py(f.front()->y) - 6, escape(family));
  }
  double ly = kTop + 10;
  for (const auto& [mode, c] : colour) {
    s += fmt::format("<circle cx=\"{}\" cy=\"{}\" r=\"5\" fill=\"{}\"/><text x=\"{}\" y=\"{}\">{}</text>\n",
                     kWidth - kRight + 20, ly, c, kWidth - kRight + 32, ly + 4, escape(mode));
    ly += 18;
  }
  s +=
      fmt::format("<text x=\"{}\" y=\"{}\">circle: cpu, square: cuda</text>\n", kWidth - kRight + 14, ly + 4);
  return s + "</svg>\n";
}

}  // namespace cg
