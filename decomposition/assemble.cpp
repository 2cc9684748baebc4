// Owned + ghosts → the engine's input in id order (see assemble.hpp).
#include "assemble.hpp"

#include <algorithm>
#include <functional>
#include <queue>
#include <string>
#include <utility>

namespace cg {

EngineInput select_owned_and_ghosts(HostVector<Vec3<double>>&& position, HostVector<double>&& radius,
                                    const SlabDecomposition& s, const GhostRule& rule, int me, int threads,
                                    ShapeRows&& shapes) {
  const std::size_t n = position.size();
  const int axis = s.axis();
  EngineInput in;
  if (s.ranks() == 1) {
    // One slab owns every row: the rows as read are the input (ids implied), without the count pass
    // below (a visible share of a one-rank run).
    in.owned = n;
    in.position = std::move(position);
    in.radius = std::move(radius);
    in.shapes = std::move(shapes);
    return in;
  }
  // 0: not held here, 1: ghost, 2: owned
  auto held = [&](std::size_t i) {
    const double x = component(position[i], axis);
    if (s.owner(x) == me) return 2;
    int h = 0;
    s.for_each_ghost_rank(x, rule.width(radius[i]), [&](int r) { h |= r == me; });
    return h;
  };
  const Chunks c(n, threads);
  std::vector<std::uint64_t> at(static_cast<std::size_t>(c.parts) + 1, 0), owned(at.size(), 0);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::uint64_t k = 0, o = 0;
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i) {
      const int h = held(i);
      k += h != 0;
      o += h == 2;
    }
    at[static_cast<std::size_t>(t) + 1] = k;
    owned[static_cast<std::size_t>(t) + 1] = o;
  }
  for (std::size_t t = 1; t < at.size(); ++t) at[t] += at[t - 1], owned[t] += owned[t - 1];
  const std::uint64_t total = at.back();
  in.owned = owned.back();
  in.ghosts = total - in.owned;
  if (in.owned == n) {  // every row is owned here (so none is a ghost): the rows as read, ids implied
    // (all pairs reported: no mask, so no wide bits either — they only move pairs between owners)
    in.position = std::move(position);
    in.radius = std::move(radius);
    in.shapes = std::move(shapes);
    return in;
  }
  const bool with_shapes = !shapes.empty();
  if (with_shapes) {
    in.shapes.shape.resize(total);
    in.shapes.semi_axes.resize(total);
    in.shapes.orientation.resize(total);
  }
  in.position.resize(total);
  in.radius.resize(total);
  in.id.resize(total);
  in.report.resize(total);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::uint64_t w = at[static_cast<std::size_t>(t)];
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i) {
      const int h = held(i);
      if (h == 0) continue;
      in.position[w] = position[i];
      in.radius[w] = radius[i];
      in.id[w] = static_cast<std::int64_t>(i);
      in.report[w] = static_cast<std::uint8_t>((h == 2 ? kReportedBit : 0) | rule.wide_bit(radius[i]));
      if (with_shapes) {
        in.shapes.shape[w] = shapes.shape[i];
        in.shapes.semi_axes[w] = shapes.semi_axes[i];
        in.shapes.orientation[w] = shapes.orientation[i];
      }
      ++w;
    }
  }
  position = {};
  radius = {};
  shapes = {};
  return in;
}

EngineInput merge_by_id(std::span<const BodyRecord> owned, std::span<const BodyRecord> ghosts,
                        const std::vector<std::uint64_t>& ghost_counts, int threads,
                        std::span<const ShapeRecord> owned_shapes, std::span<const ShapeRecord> ghost_shapes,
                        const GhostRule& rule) {
  const bool with_shapes = !owned_shapes.empty() || !ghost_shapes.empty();
  if (with_shapes && (owned_shapes.size() != owned.size() || ghost_shapes.size() != ghosts.size()))
    throw Error("merge_by_id: shape rows and body records differ in count: internal error");
  // ghost groups → one ascending run
  HostVector<BodyRecord> g(ghosts.size());
  HostVector<ShapeRecord> gs(with_shapes ? ghosts.size() : 0);
  {
    using Head = std::pair<std::int64_t, std::size_t>;  // (id, group)
    std::priority_queue<Head, std::vector<Head>, std::greater<Head>> heap;
    std::vector<std::uint64_t> next, end;
    std::uint64_t at = 0;
    for (std::uint64_t k : ghost_counts) {
      if (k > 0) {
        heap.emplace(ghosts[at].id, next.size());
        next.push_back(at);
        end.push_back(at + k);
      }
      at += k;
    }
    std::size_t w = 0;
    while (!heap.empty()) {
      const std::size_t r = heap.top().second;
      heap.pop();
      if (with_shapes) gs[w] = ghost_shapes[next[r]];
      g[w++] = ghosts[next[r]++];
      if (next[r] < end[r]) heap.emplace(ghosts[next[r]].id, r);
    }
  }
  const std::size_t no = owned.size(), ng = g.size(), n = no + ng;
  EngineInput in;
  in.owned = no;
  in.ghosts = ng;
  in.position.resize(n);
  in.radius.resize(n);
  in.id.resize(n);
  in.report.resize(n);
  if (with_shapes) {
    in.shapes.shape.resize(n);
    in.shapes.semi_axes.resize(n);
    in.shapes.orientation.resize(n);
  }
  auto ghost_split = [&](std::size_t a) -> std::size_t {  // ghosts before owned[a]
    if (a == 0) return 0;
    if (a == no) return ng;
    const std::int64_t id = owned[a].id;
    return static_cast<std::size_t>(
        std::lower_bound(g.data(), g.data() + ng, id,
                         [](const BodyRecord& b, std::int64_t v) { return b.id < v; }) -
        g.data());
  };
  const Chunks c(std::max(no, ng), threads);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::size_t a = static_cast<std::size_t>((std::uint64_t)no * t / c.parts);
    const std::size_t a_end = static_cast<std::size_t>((std::uint64_t)no * (t + 1) / c.parts);
    std::size_t b = ghost_split(a);
    const std::size_t b_end = t + 1 == c.parts ? ng : ghost_split(a_end);
    std::size_t k = a + b;
    auto put = [&](const BodyRecord& x, const ShapeRecord* shape, std::uint8_t mine) {
      in.position[k] = x.position;
      in.radius[k] = x.radius;
      in.id[k] = x.id;
      in.report[k] = static_cast<std::uint8_t>(mine | rule.wide_bit(x.radius));
      if (shape) {
        in.shapes.shape[k] = shape->shape;
        in.shapes.semi_axes[k] = shape->semi_axes;
        in.shapes.orientation[k] = shape->orientation;
      }
      ++k;
    };
    auto put_owned = [&] {
      put(owned[a], with_shapes ? &owned_shapes[a] : nullptr, 1);
      ++a;
    };
    auto put_ghost = [&] {
      put(g[b], with_shapes ? &gs[b] : nullptr, 0);
      ++b;
    };
    while (a < a_end && b < b_end) {
      if (g[b].id < owned[a].id) {
        put_ghost();
      } else {
        put_owned();
      }
    }
    while (a < a_end) put_owned();
    while (b < b_end) put_ghost();
  }
  const std::int64_t* id = in.id.data();
  const std::size_t k =
      first_bad(n > 0 ? n - 1 : 0, threads, [&](std::size_t i) { return !(id[i + 1] > id[i]); });
  if (k + 1 < n) {
    if (id[k + 1] == id[k]) {
      throw Error("body " + std::to_string(id[k]) + " is held twice (owned and ghost): internal error");
    }
    throw Error("bodies are not in id order at " + std::to_string(k + 1) + ": internal error");
  }
  return in;
}

}  // namespace cg
