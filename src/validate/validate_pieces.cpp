// The pieces of a validation (validate.hpp, "Pieces and memory"): regions halved at the median centre
// of their longest axis until Bullet's world of each fits the memory budget.
//
// Invariants: the boxes of the pieces of one region partition it (half-open boxes), so every owned body
// belongs to exactly one piece; a piece's world holds every body whose centre lies within 2·r_max of
// its box, a superset of the bodies that can touch an owned one; ids stay ascending (every list is a
// filtered copy of an ascending one).
#include <algorithm>
#include <limits>

#include "validate/validate_detail.hpp"

namespace cg::validate_detail {
namespace {

double component(Vec3<double> v, int axis) { return axis == 0 ? v.x : axis == 1 ? v.y : v.z; }
void set_component(Vec3<double>& v, int axis, double x) { (axis == 0 ? v.x : axis == 1 ? v.y : v.z) = x; }

// Bullet pairs per contact before any piece has run: Bullet grows every box by its contact breaking
// threshold and pairs every two overlapping boxes, so it holds more pairs than there are contacts
// (about 1.9 for spheres scattered at random: a cube's volume over a ball's; more for packed grains,
// whose neighbours nearly touch). Measured 2.1–2.7 in our scenes; observe() replaces it.
constexpr double kInitialPairsPerContact = 3.0;
// Margin on the ratios Bullet is seen to reach, for the pieces still to run.
constexpr double kObservedSafety = 1.25;
// A piece tells the ratio when it holds this many contacts.
constexpr double kObservedContacts = 256;

}  // namespace

PiecePlanner::PiecePlanner(const Scene& scene, const ContactIndex& index,
                           const std::vector<std::uint32_t>& degree, double margin, BulletCost cost,
                           double budget)
    : m_scene(scene),
      m_index(index),
      m_degree(degree),
      m_owned(scene.size(), 0),
      m_margin(margin),
      m_cost(cost),
      m_budget(budget),
      m_pairs_per_contact(kInitialPairsPerContact) {}

Piece PiecePlanner::make_piece(const Box& box, const std::vector<std::int64_t>& inside_of,
                               const std::vector<std::int64_t>& world_of) const {
  Piece p;
  p.box = box;
  const Box outer = box.grown(m_margin);
  for (const std::int64_t id : inside_of)
    if (box.contains(centre(m_scene, std::size_t(id)))) p.inside.push_back(id);
  for (const std::int64_t id : world_of)
    if (outer.contains(centre(m_scene, std::size_t(id)))) p.world.push_back(id);
  return p;
}

void PiecePlanner::add_region(const Box& box, const std::vector<std::int64_t>& candidates) {
  m_pending.push_back(make_piece(box, candidates, candidates));
}

double PiecePlanner::contacts_of(const Piece& piece) {
  // Σ degree over the owned bodies counts a pair between two owned bodies twice: once less.
  double contacts = 0;
  for (const std::int64_t id : piece.inside) {
    contacts += m_degree[std::size_t(id)];
    m_owned[std::size_t(id)] = 1;
  }
  for (const std::int64_t a : piece.inside)
    for (std::size_t k = m_index.lower_bound_a(a); k < m_index.size() && m_index.key(k).first == a; ++k)
      if (m_owned[std::size_t(m_index.key(k).second)]) contacts -= 1;
  for (const std::int64_t id : piece.inside) m_owned[std::size_t(id)] = 0;
  return contacts;
}

double PiecePlanner::estimate(const Piece& piece) {
  const double pairs =
      std::max(m_pairs_per_contact * contacts_of(piece), m_pairs_per_body * double(piece.inside.size()));
  return m_cost.per_body * double(piece.world.size()) + m_cost.per_pair * pairs;
}

void PiecePlanner::observe(const Piece& piece, std::uint64_t pairs) {
  const double contacts = contacts_of(piece);
  if (contacts >= kObservedContacts) {
    const double ratio = kObservedSafety * double(pairs) / contacts;
    m_pairs_per_contact = m_observed ? std::max(m_pairs_per_contact, ratio) : ratio;
    m_observed = true;
  }
  if (piece.inside.size() >= 64)
    m_pairs_per_body =
        std::max(m_pairs_per_body, kObservedSafety * double(pairs) / double(piece.inside.size()));
}

std::optional<Piece> PiecePlanner::next() {
  while (!m_pending.empty()) {
    Piece p = std::move(m_pending.back());
    m_pending.pop_back();
    if (p.inside.empty()) continue;
    const bool fits = p.world.size() <= kMaxPieceBodies && estimate(p) <= m_budget;
    if (p.inside.size() <= kMinPieceBodies || fits) return p;
    // Halve at the median centre of the owned bodies' longest axis (the first axis, by extent, along
    // which the median leaves bodies on both sides).
    const double inf = std::numeric_limits<double>::infinity();
    Box span{{inf, inf, inf}, {-inf, -inf, -inf}};
    for (const std::int64_t id : p.inside) {
      const Vec3<double> c = centre(m_scene, std::size_t(id));
      span.lo = {std::min(span.lo.x, c.x), std::min(span.lo.y, c.y), std::min(span.lo.z, c.z)};
      span.hi = {std::max(span.hi.x, c.x), std::max(span.hi.y, c.y), std::max(span.hi.z, c.z)};
    }
    const Vec3<double> e = span.hi - span.lo;
    int axes[3] = {0, 1, 2};
    std::sort(axes, axes + 3, [&](int a, int b) { return component(e, a) > component(e, b); });
    bool split = false;
    for (const int axis : axes) {
      std::vector<double> x;
      x.reserve(p.inside.size());
      for (const std::int64_t id : p.inside) x.push_back(component(centre(m_scene, std::size_t(id)), axis));
      auto mid = x.begin() + std::ptrdiff_t(x.size() / 2);
      std::nth_element(x.begin(), mid, x.end());
      const double cut = *mid;                          // lower half: < cut; the median itself goes up
      if (!(cut > component(span.lo, axis))) continue;  // nothing below the cut on this axis
      Box lower = p.box, upper = p.box;
      set_component(lower.hi, axis, cut);
      set_component(upper.lo, axis, cut);
      m_pending.push_back(make_piece(upper, p.inside, p.world));
      m_pending.push_back(make_piece(lower, p.inside, p.world));
      split = true;
      break;
    }
    if (!split) return p;  // every owned centre is the same point: nothing to halve
  }
  return std::nullopt;
}

}  // namespace cg::validate_detail
