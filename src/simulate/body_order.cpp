// The order simulate keeps its bodies in (body_order.hpp).
#include "simulate/body_order.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <numeric>
#include <regex>

namespace cg {

namespace {

// The 21 low bits of v spread to every third bit (a Morton key's axis).
std::uint64_t spread(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}

// The rows of `v` in the order `from` (out[k] = v[from[k]]) or back (out[from[k]] = v[k]); empty
// arrays stay empty.
template <class T>
std::vector<T> reordered(const std::vector<T>& v, const std::vector<std::int64_t>& from, bool back) {
  if (v.empty()) return {};
  std::vector<T> out(v.size());
  for (std::size_t k = 0; k < from.size(); ++k) {
    const std::size_t i = static_cast<std::size_t>(from[k]);
    if (back)
      out[i] = v[k];
    else
      out[k] = v[i];
  }
  return out;
}

DemBodies reordered(const DemBodies& b, const std::vector<std::int64_t>& from, bool back) {
  DemBodies out;
  out.position = reordered(b.position, from, back);
  out.velocity = reordered(b.velocity, from, back);
  out.angular_velocity = reordered(b.angular_velocity, from, back);
  out.radius = reordered(b.radius, from, back);
  out.shape = reordered(b.shape, from, back);
  out.semi_axes = reordered(b.semi_axes, from, back);
  out.orientation = reordered(b.orientation, from, back);
  out.fixed = reordered(b.fixed, from, back);
  return out;
}

}  // namespace

BodyOrder BodyOrder::cells(const DemBodies& b, std::size_t spheres) {
  const std::size_t n = b.size();
  BodyOrder order;
  if (n < 2) return order;
  Vec3<double> lo = b.position[0];
  double r_max = 0;
  for (std::size_t i = 0; i < n; ++i) {
    lo = {std::min(lo.x, b.position[i].x), std::min(lo.y, b.position[i].y), std::min(lo.z, b.position[i].z)};
    r_max = std::max(r_max, b.radius[i]);
  }
  const double cell = 2 * r_max;
  if (!(cell > 0) || !std::isfinite(cell)) return order;
  // a cell index per axis, clamped: a scene far wider than its bodies keeps an exact order
  auto index = [&](double x, double from) {
    return static_cast<std::uint64_t>(std::clamp(std::floor((x - from) / cell), 0.0, 2097151.0));
  };
  // CONTACTGRID_SIMULATE_ORDER_KEY=morton: the cells along a Z-order curve instead of rows
  const char* knob = std::getenv("CONTACTGRID_SIMULATE_ORDER_KEY");
  const bool morton = knob && std::string(knob) == "morton";
  std::vector<std::uint64_t> key(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<double>& p = b.position[i];
    const std::uint64_t x = index(p.x, lo.x), y = index(p.y, lo.y), z = index(p.z, lo.z);
    key[i] = morton ? spread(x) | spread(y) << 1 | spread(z) << 2 : z << 42 | y << 21 | x;
  }
  order.m_name = morton ? "cells-morton" : "cells";
  order.m_scene_of.resize(n);
  std::iota(order.m_scene_of.begin(), order.m_scene_of.end(), std::int64_t(0));
  const auto by_key = [&](std::int64_t i, std::int64_t j) {
    return key[std::size_t(i)] < key[std::size_t(j)];
  };
  const auto mid = order.m_scene_of.begin() + static_cast<std::ptrdiff_t>(std::min(spheres, n));
  std::stable_sort(order.m_scene_of.begin(), mid, by_key);
  std::stable_sort(mid, order.m_scene_of.end(), by_key);
  return order;
}

DemBodies BodyOrder::to_run(const DemBodies& scene) const {
  return identity() ? scene : reordered(scene, m_scene_of, false);
}

DemBodies BodyOrder::to_scene(const DemBodies& run) const {
  return identity() ? run : reordered(run, m_scene_of, true);
}

std::string BodyOrder::scene_message(const std::string& message) const {
  if (identity()) return message;
  static const std::regex body(R"(\bbody (\d+))");
  std::string out;
  auto at = message.cbegin();
  for (std::sregex_iterator it(message.begin(), message.end(), body), end; it != end; ++it) {
    out.append(at, (*it)[0].first);
    out += "body " + std::to_string(scene_of(std::stoll((*it)[1].str())));
    at = (*it)[0].second;
  }
  out.append(at, message.cend());
  return out;
}

}  // namespace cg
