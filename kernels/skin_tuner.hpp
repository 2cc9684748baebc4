#pragma once
// The automatic Verlet skin (EngineOptions::skin_auto, detect --skin auto): the skin whose mean cost
// per step is lowest for the observed motion. Pure host code, g++-safe public header.
//
// A list built with skin s lasts while every body moved less than s/2 since the build; with v the
// largest displacement per step, the skin 2·v·n lasts a build and n reuses. Building with a larger skin
// costs more (inflated spheres: more cell entries and candidates) and so does each reuse (more
// candidates to decide), so the mean cost per step (build + n reuses) / (n + 1) first falls with n
// (fewer builds), then rises. The tuner measures it: each build starts a cycle at the current n, and
// the cycle's mean cost, when it ends (the next build), is compared with the best so far; n doubles
// (1, 2, 4, …) while the mean falls, and the first cycle that costs more ends the search at the best
// n, kept from then on (as HOOMD tunes its neighbour list's buffer by timing). v is the largest
// displacement per step ever observed (displacement since the build / steps since the build), so
// faster motion shortens the lists at once. Before any motion is seen the skin is 0 (detection from
// scratch); bodies that never move get a small skin (kept lists are then reused for ever).
#include <algorithm>
#include <cmath>

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
    if (!(m_v > 0)) return m_seen ? m_length / 64 : 0;
    return std::min(2 * m_length, 2 * m_v * m_n * (1 + 1.0 / 16));
  }

  // After each step: whether it built a list (else it reused one), its cost in seconds, and the
  // largest displacement of a body since the last build over the steps since that build.
  void observe(bool built, double seconds, double displacement, int steps_since_build) {
    if (steps_since_build > 0 && displacement > 0) m_v = std::max(m_v, displacement / steps_since_build);
    m_seen = true;
    if (built) {
      end_cycle();
      m_cycle_n = m_n_asked;
      m_cycle_seconds = seconds;
      m_cycle_steps = 1;
    } else {
      m_cycle_seconds += seconds;
      ++m_cycle_steps;
    }
  }

  int reuses_per_build() const { return m_n; }  // the n of the current choice
  bool searching() const { return m_searching; }
  double speed() const { return m_v; }  // the largest displacement per step observed

 private:
  void end_cycle() {
    // a cycle built with a trial skin (motion seen): while searching, only the current trial's counts
    // (a cycle the previous n started before the change is not one)
    if (m_cycle_steps == 0 || m_cycle_n == 0) return;
    const double mean = m_cycle_seconds / m_cycle_steps;
    if (!m_searching) {
      if (m_cycle_n == m_best_n) m_best_mean = mean;  // the cost of the choice, as it is now
      return;
    }
    if (m_cycle_n != m_n) return;
    if (m_best_n == 0 || mean < m_best_mean) {
      m_best_mean = mean;
      m_best_n = m_n;
      if (2 * m_v * 2 * m_n <= 2 * m_length && m_n < k_max_n)
        m_n = 2 * m_n;
      else
        m_searching = false;
    } else {
      m_searching = false;
      m_n = m_best_n;
    }
  }

  static constexpr int k_max_n = 256;
  double m_length;
  double m_v = 0;              // the largest displacement per step observed
  bool m_seen = false;         // a call was observed
  int m_n = 1, m_n_asked = 0;  // reuses per build: the current choice, and the one the last skin() gave
  bool m_searching = true;
  int m_best_n = 0;
  double m_best_mean = 0;
  int m_cycle_n = 0, m_cycle_steps = 0;  // the cycle in progress (since the last build)
  double m_cycle_seconds = 0;
};

}  // namespace cg
