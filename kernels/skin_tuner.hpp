#pragma once
// The automatic Verlet skin (EngineOptions::skin_auto, detect --skin auto): the skin whose mean cost
// per step is lowest for the observed motion. Pure host code, g++-safe public header.
//
// A list built with skin s lasts while every body moved less than s/2 since the build; with v the
// largest displacement per step, the skin s(n) = 2·v·n·(1 + 1/16) lasts a build and n reuses. A build
// with a larger skin costs more (inflated spheres: more cell entries, tests and candidates) and so does
// each reuse (more candidates to decide), so the mean cost per step (B(s) + n·R(s)) / (n + 1) first
// falls with n (fewer builds), then rises.
//
// The tuner models both costs from what it measures: each build starts a cycle, and when the cycle
// ends (the next build) its build's seconds and its reuses' mean are kept as samples at the cycle's
// skin (the newest per skin, the last 8 skins). A least-squares line through each (slope >= 0) gives
// B(s) and R(s); the next choice is the n of the lowest modelled mean, n at most 4 times the largest n
// measured so far (the lines are not trusted far beyond what was seen; the next cycle measures there
// and refits). Until both lines have two skins the search multiplies n by 4 (2, 8, …). The cycle in
// progress counts as ended when skin() is asked (a build asks it), so a trial's result sets the skin
// of the build that ends it. A build and a reuse are measured separately, so a change of either cost
// (a cheaper reuse path, a slower build) moves the choice at once; a cycle cut short by faster motion
// still gives its samples. v is the largest displacement per step ever observed (displacement since
// the build / steps since the build), so faster motion shortens the lists at once. Before any motion is seen
// the skin is 0 (detection from scratch); bodies that never move get a small skin (kept lists are then reused
// for ever).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace cg {

class SkinTuner {
 public:
  // `length`: a length of the scene (the largest bounding radius): the skin of bodies that do not
  // move is length/64, and no skin exceeds 2·length (a larger one only adds candidates).
  explicit SkinTuner(double length = 1) : m_length(length) {}
  void set_length(double length) { m_length = length; }

  // The skin of the next build (the engine keeps the skin of the list it built until its next build).
  double skin() {
    m_n_asked = m_v > 0 ? m_n : 0;  // 0: not a trial of n (no motion seen yet)
    if (!(m_v > 0)) return m_skin_asked = m_seen ? m_length / 64 : 0;
    // the cycle in progress counts as if it ended now: when this call builds, it does (so a trial's
    // result is used by the build that ends it, not one cycle later)
    if (valid_cycle()) {
      std::vector<Sample> samples = m_samples;
      add_sample(samples, current_sample());
      choose(samples, std::max(m_n_seen, m_cycle_reuses));
    }
    m_n_asked = m_n;
    return m_skin_asked = skin_of(m_n);
  }

  // After each step: whether it built a list (else it reused one), its cost in seconds, and the
  // largest displacement of a body since the last build over the steps since that build.
  void observe(bool built, double seconds, double displacement, int steps_since_build) {
    if (steps_since_build > 0 && displacement > 0) m_v = std::max(m_v, displacement / steps_since_build);
    m_seen = true;
    if (built) {
      end_cycle();
      m_cycle_n = m_n_asked;
      m_cycle_skin = m_skin_asked;
      m_cycle_build = seconds;
      m_cycle_reuse_seconds = 0;
      m_cycle_reuses = 0;
    } else {
      m_cycle_reuse_seconds += seconds;
      ++m_cycle_reuses;
    }
  }

  int reuses_per_build() const { return m_n; }  // the n of the current choice
  double speed() const { return m_v; }          // the largest displacement per step observed
  // The modelled mean cost per step of a build and n reuses (0 while the model lacks two skins).
  double modelled_mean(int n) const {
    Line b, r;
    if (!fit(m_samples, b, r)) return 0;
    const double s = skin_of(n);
    return (b.at(s) + n * r.at(s)) / (n + 1);
  }

 private:
  struct Sample {
    double skin, build, reuse_seconds;
    int reuses;
  };
  struct Line {
    double intercept = 0, slope = 0;
    double at(double s) const { return intercept + slope * s; }
  };

  double skin_of(int n) const { return std::min(2 * m_length, 2 * m_v * n * (1 + 1.0 / 16)); }

  // The weighted least-squares line of y over s (slope >= 0); false with fewer than two skins.
  template <class Y, class W>
  static bool fit_line(const std::vector<Sample>& samples, Line& line, const Y& y, const W& weight) {
    double sw = 0, ss = 0, sy = 0;
    for (const Sample& p : samples) {
      const double w = weight(p);
      sw += w, ss += w * p.skin, sy += w * y(p);
    }
    if (!(sw > 0)) return false;
    const double ms = ss / sw, my = sy / sw;
    double var = 0, cov = 0;
    for (const Sample& p : samples) {
      const double w = weight(p);
      var += w * (p.skin - ms) * (p.skin - ms);
      cov += w * (p.skin - ms) * (y(p) - my);
    }
    if (!(var > 0)) return false;
    line.slope = std::max(0.0, cov / var);
    line.intercept = my - line.slope * ms;
    return true;
  }
  static bool fit(const std::vector<Sample>& samples, Line& build, Line& reuse) {
    return fit_line(
               samples, build, [](const Sample& p) { return p.build; }, [](const Sample&) { return 1.0; }) &&
           fit_line(
               samples, reuse, [](const Sample& p) { return p.reuses ? p.reuse_seconds / p.reuses : 0.0; },
               [](const Sample& p) { return double(p.reuses); });
  }

  // a cycle built with a trial skin (motion seen)
  bool valid_cycle() const { return m_cycle_n > 0 && m_cycle_skin > 0; }
  Sample current_sample() const {
    return {m_cycle_skin, m_cycle_build, m_cycle_reuse_seconds, m_cycle_reuses};
  }
  // the newest sample per skin, the last k_samples skins
  static void add_sample(std::vector<Sample>& samples, const Sample& x) {
    auto same =
        std::find_if(samples.begin(), samples.end(), [&](const Sample& p) { return p.skin == x.skin; });
    if (same != samples.end()) samples.erase(same);
    if (samples.size() == k_samples) samples.erase(samples.begin());
    samples.push_back(x);
  }

  void end_cycle() {
    if (!valid_cycle()) return;
    add_sample(m_samples, current_sample());
    m_n_seen = std::max(m_n_seen, m_cycle_reuses);
    choose(m_samples, m_n_seen);
  }

  // The n of the lowest modelled mean, or the search's next trial while the model lacks two skins.
  void choose(const std::vector<Sample>& samples, int n_seen) {
    // the largest n whose skin stays within 2·length (a larger n would not last longer)
    const int n_max = std::clamp(int(std::floor(2 * m_length / skin_of(1))), 1, k_max_n);
    const int n_cap = std::min(n_max, 4 * std::max(1, n_seen));
    Line b, r;
    if (!fit(samples, b, r)) {
      m_n = n_cap;
      return;
    }
    double best = 0;
    for (int n = 1; n <= n_cap; ++n) {
      const double s = skin_of(n);
      const double mean = (b.at(s) + n * r.at(s)) / (n + 1);
      if (n == 1 || mean < best) best = mean, m_n = n;
    }
  }

  static constexpr int k_max_n = 256;
  static constexpr std::size_t k_samples = 8;
  double m_length;
  double m_v = 0;              // the largest displacement per step observed
  bool m_seen = false;         // a call was observed
  int m_n = 2, m_n_asked = 0;  // reuses per build: the current choice, and the one the last skin() gave
  double m_skin_asked = 0;     // the skin the last skin() gave
  int m_n_seen = 0;            // the most reuses a measured cycle made
  std::vector<Sample> m_samples;
  int m_cycle_n = 0, m_cycle_reuses = 0;  // the cycle in progress (since the last build)
  double m_cycle_skin = 0, m_cycle_build = 0, m_cycle_reuse_seconds = 0;
};

}  // namespace cg
