// --walls specs of contactgrid simulate (simulate.hpp: parse_wall).
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "errors.hpp"
#include "simulate/simulate.hpp"

namespace cg {

namespace {
std::vector<double> numbers(const std::string& spec, const std::string& list, std::size_t count) {
  std::vector<double> v;
  std::stringstream ss(list);
  std::string word;
  while (std::getline(ss, word, ',')) {
    std::size_t used = 0;
    double x = 0;
    try {
      x = std::stod(word, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (word.empty() || used != word.size() || !std::isfinite(x))
      throw UsageError("--walls " + spec + ": '" + word + "' is not a finite number");
    v.push_back(x);
  }
  if (v.size() != count)
    throw UsageError("--walls " + spec + ": wants " + std::to_string(count) + " numbers, got " +
                     std::to_string(v.size()));
  return v;
}

dem::Wall plane(Vec3<double> p, Vec3<double> n) {
  dem::Wall w;
  w.kind = dem::WallKind::plane;
  w.point = p;
  w.normal = n;
  return w;
}
}  // namespace

std::vector<dem::Wall> parse_wall(const std::string& spec) {
  const std::size_t colon = spec.find(':');
  if (colon == std::string::npos)
    throw UsageError("--walls " + spec +
                     ": wants KIND:NUMBERS (plane, box, open-box, cylinder, orifice, hopper)");
  const std::string kind = spec.substr(0, colon), list = spec.substr(colon + 1);
  std::vector<dem::Wall> out;
  if (kind == "plane") {
    const auto v = numbers(spec, list, 6);
    const Vec3<double> n{v[3], v[4], v[5]};
    const double len = std::sqrt(dot(n, n));
    if (!(len > 0)) throw UsageError("--walls " + spec + ": the normal is zero");
    out.push_back(plane({v[0], v[1], v[2]}, (1 / len) * n));
  } else if (kind == "box" || kind == "open-box") {
    const auto v = numbers(spec, list, 6);
    if (!(v[0] < v[3] && v[1] < v[4] && v[2] < v[5]))
      throw UsageError("--walls " + spec + ": wants X0 < X1, Y0 < Y1, Z0 < Z1");
    out.push_back(plane({v[0], 0, 0}, {1, 0, 0}));
    out.push_back(plane({v[3], 0, 0}, {-1, 0, 0}));
    out.push_back(plane({0, v[1], 0}, {0, 1, 0}));
    out.push_back(plane({0, v[4], 0}, {0, -1, 0}));
    if (kind == "box") {
      out.push_back(plane({0, 0, v[2]}, {0, 0, 1}));
      out.push_back(plane({0, 0, v[5]}, {0, 0, -1}));
    }
  } else if (kind == "cylinder" || kind == "hopper") {
    const auto v = numbers(spec, list, kind == "cylinder" ? 3 : 5);
    if (!(v[2] > 0)) throw UsageError("--walls " + spec + ": the radius must be > 0");
    dem::Wall c;
    c.kind = dem::WallKind::cylinder;
    c.point = {v[0], v[1], 0};
    c.radius = v[2];
    out.push_back(c);
    if (kind == "hopper") {
      if (!(v[4] >= 0 && v[4] < v[2])) throw UsageError("--walls " + spec + ": wants 0 <= H < R");
      dem::Wall o;
      o.kind = dem::WallKind::orifice;
      o.point = {v[0], v[1], v[3]};
      o.hole = v[4];
      out.push_back(o);
    }
  } else if (kind == "orifice") {
    const auto v = numbers(spec, list, 4);
    if (!(v[3] >= 0)) throw UsageError("--walls " + spec + ": the hole radius must be >= 0");
    dem::Wall o;
    o.kind = dem::WallKind::orifice;
    o.point = {v[0], v[1], v[2]};
    o.hole = v[3];
    out.push_back(o);
  } else {
    throw UsageError("--walls " + spec + ": unknown kind '" + kind +
                     "' (plane, box, open-box, cylinder, orifice, hopper)");
  }
  return out;
}

}  // namespace cg
