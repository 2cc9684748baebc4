// The step loop (see resident_steps.hpp): the rows of the steps, then each step's stages (the layout:
// step_layout.cpp; the halo: step_halo.cpp; rebalance and migrate: step_migrate.cpp; the state they
// share: step_state.hpp).
#include "resident_steps.hpp"

#include "step_state.hpp"

namespace cg {

using step_detail::k_body_gather_tag;

const char* to_string(StepStage stage) {
  switch (stage) {
    case StepStage::frame:
      return "frame";
    case StepStage::migrate:
      return "migrate";
    case StepStage::rebuild:
      return "rebuild";
    case StepStage::halo:
      return "halo";
    case StepStage::interior:
      return "interior";
    case StepStage::boundary:
      return "boundary";
    case StepStage::step:
      return "step";
    case StepStage::halo_pack:
      return "halo pack";
    case StepStage::halo_mpi:
      return "halo mpi";
    case StepStage::halo_unpack:
      return "halo unpack";
    case StepStage::merge_wait:
      return "merge wait";
  }
  return "?";
}

template <class Real>
StepLoop<Real>::StepLoop(Session& session, Engine<Real>& engine, const SlabDecomposition& slabs,
                         const StepMotion& motion, int threads, const StepBalance& balance)
    : m(std::make_unique<State>(session, engine, slabs, motion, threads, balance)) {}

template <class Real>
StepLoop<Real>::~StepLoop() = default;

template <class Real>
StepBodies& StepLoop<Real>::bodies() {
  m->finish_merge();
  return m->bodies;
}
template <class Real>
const SlabDecomposition& StepLoop<Real>::slabs() const {
  return m->slabs;
}
template <class Real>
const Frame& StepLoop<Real>::frame() const {
  return m->frame;
}

template <class Real>
const ExportPlan& StepLoop<Real>::halo() const {
  return m->plan.halo;
}

template <class Real>
void StepLoop<Real>::update_frame(int step) {
  State& s = *m;
  // After the first layout engine A holds the bodies' rows: the moved positions go there first (the
  // commit's write, made early and not timed, as commit is not), then the engine validates them and
  // returns their bounds and the largest displacement since the layout where they are (CUDA: on the
  // device; no centre is read on the host). Before it: the bodies' own bounds.
  s.finish_merge();
  const bool resident = s.layouts > 0 && !s.rows_changed;
  StepBodies& b = s.bodies;
  if (resident) {
    agreed_stage(s.session, "steps", [&] {
      s.a.write_resident(0, b.size(), b.position.data(), b.radius.data());
      s.written = true;
    });
  }
  const auto f0 = WallClock::now();
  Bounds mine;
  agreed_stage(s.session, "steps", [&] {
    s.moved = 0;
    if (b.size() == 0) return;
    try {
      if (resident) {
        const ResidentExtent e = s.a.resident_extent(b.id);
        mine = e.bounds;
        s.moved = e.displacement;
      } else {
        mine = compute_bounds(b.view());
      }
    } catch (const InputError& e) {
      throw InputError("step " + std::to_string(step) + ": " + e.what());
    }
  });
  s.global = allgather_bounds(s.session, mine);
  agreed_stage(s.session, "steps", [&] {
    const EngineOptions& o = s.a.options();
    try {
      s.frame = make_frame(s.global, o.cell_size, s.a.precision(), o.cell_choice);
    } catch (const InputError& e) {
      throw InputError("step " + std::to_string(step) + ": " + e.what());
    }
    s.width = frame_ghost_width(s.global, s.frame.origin, std::numeric_limits<Real>::epsilon());
  });
  s.t[static_cast<std::size_t>(StepStage::frame)] = seconds_since(f0);
}

template <class Real>
bool StepLoop<Real>::rebuild_due() {
  State& s = *m;
  const auto t0 = WallClock::now();
  s.displacement = s.session.max(s.moved);  // (update_frame's, from engine A's mark at the layout)
  ++s.steps_since_layout;
  s.tuner_displacement = s.displacement;
  s.tuner_steps = s.steps_since_layout;
  s.t[static_cast<std::size_t>(StepStage::rebuild)] += seconds_since(t0);
  return 2 * s.displacement > s.layout_skin();
}

template <class Real>
void StepLoop<Real>::commit(Moved moved) {
  State& s = *m;
  StepBodies& b = s.bodies;
  const bool written = s.written;
  s.written = false;
  if (s.uploaded) {  // this step's layout set engine A's rows from the moved bodies
    s.uploaded = false;
    return;
  }
  try {
    if ((moved.positions && !written) || moved.orientations) s.finish_merge();  // the rows read whole
    if (moved.positions && !written) s.a.write_resident(0, b.size(), b.position.data(), b.radius.data());
    if (moved.orientations && !b.shapes.empty())
      s.a.write_resident_shapes(0, b.size(), nullptr, b.shapes.orientation.data());
  } catch (...) {
    s.fail();
  }
}

template <class Real>
void StepLoop<Real>::detect_interior() {
  State& s = *m;
  s.found_a = s.found_b = 0;
  s.interior_error = nullptr;
  s.builds_before = s.a.stats().candidate_builds;
  s.s0 = WallClock::now();
  auto run = [&s] {
    const auto i0 = WallClock::now();
    try {
      s.found_a = s.a.detect_resident(s.frame);
    } catch (...) {
      s.interior_error = std::current_exception();
    }
    s.t[static_cast<std::size_t>(StepStage::interior)] = seconds_since(i0);
  };
  if (s.session.size() > 1) s.gather_halo();  // engine A's rows, before A detects on the other thread
  if (s.error) return;
  s.start_merge();  // a migration's host rows, while the host waits for the device
  if (s.session.size() > 1) {
    try {
      s.interior = std::thread(run);  // overlaps the halo
    } catch (...) {
      s.fail();
    }
  } else {
    run();
  }
}

template <class Real>
void StepLoop<Real>::detect_boundary() {
  State& s = *m;
  if (s.b_active && !s.error) {
    const auto b0 = WallClock::now();
    try {
      s.found_b = s.b->detect_resident(s.frame);
    } catch (...) {
      s.fail();
    }
    s.t[static_cast<std::size_t>(StepStage::boundary)] = seconds_since(b0);
  }
  const auto j0 = WallClock::now();
  if (s.interior.joinable()) s.interior.join();
  const double join = seconds_since(j0);
  if (!s.error) s.error = s.interior_error;
  std::exception_ptr error = s.error;
  s.error = nullptr;
  const auto g0 = WallClock::now();
  s.session.agree(error, "steps");
  s.t[static_cast<std::size_t>(StepStage::step)] = seconds_since(s.s0);
  if (s.trace.on && s.a.stats().candidate_builds > s.builds_before) {
    // a building step: engine A's call against the sum of its stages (the rest is outside them)
    double staged = 0;
    for (const StageTime& st : s.a.times()) staged += st.seconds;
    s.trace.line.clear();
    s.trace.value("interior", s.t[static_cast<std::size_t>(StepStage::interior)]);
    s.trace.value("a_stages", staged);
    s.trace.value("halo", s.t[static_cast<std::size_t>(StepStage::halo)]);
    s.trace.value("boundary", s.t[static_cast<std::size_t>(StepStage::boundary)]);
    s.trace.value("join", join);
    s.trace.value("agree", seconds_since(g0));
    s.trace.value("step", s.t[static_cast<std::size_t>(StepStage::step)]);
    // engine A's stages of this build and what it walked (the skin, entries, tests, candidates)
    for (const StageTime& st : s.a.times())
      if (st.name == "pairs" || st.name == "order" || st.name == "narrow")
        s.trace.value(st.name.c_str(), st.seconds);
    const EngineStats& a = s.a.stats();
    char counts[192];
    std::snprintf(counts, sizeof counts,
                  " skin %.4f entries %llu tests %llu candidates %llu contacts %llu walks %d", a.skin,
                  static_cast<unsigned long long>(a.entries), static_cast<unsigned long long>(a.pair_tests),
                  static_cast<unsigned long long>(a.candidates), static_cast<unsigned long long>(a.contacts),
                  a.pair_walks);
    s.trace.line += counts;
    s.trace.print(s.session.rank(), s.layouts, "build");
  }
}

template <class Real>
void StepLoop<Real>::collect() {
  State& s = *m;
  s.found.push_back(s.found_a + s.found_b);
  s.times.push_back(s.t);
  const std::vector<std::string>& names = engine_stage_names();
  std::vector<double> e(names.size(), 0);
  for (const StageTime& t : s.a.times())
    for (std::size_t j = 0; j < names.size(); ++j)
      if (t.name == names[j]) e[j] = t.seconds;
  s.engine_times.push_back(std::move(e));
  s.built.push_back(s.a.stats().candidate_builds > s.builds_before || !(s.skin > 0) ? 1.0 : 0.0);
  s.relaid.push_back(s.relaid_now ? 1.0 : 0.0);
  s.relaid_now = false;
  s.uploaded = false;
  s.written = false;
  if (s.motion.hash_every_step) {
    std::uint64_t h = 0;
    agreed_stage(s.session, "steps", [&] { h = contacts_hash(contacts()); });
    s.hashes.push_back(h);
  }
  if (s.skin_auto) {  // the same observation on every rank
    using I = std::size_t;
    const double seconds =
        s.session.max(s.t[I(StepStage::migrate)] + s.t[I(StepStage::rebuild)] + s.t[I(StepStage::step)]);
    const bool built = s.session.max(s.built.back()) > 0;
    s.tuner.observe(built, seconds, s.tuner_displacement, s.tuner_steps);
  }
  s.t = {};
}

template <class Real>
Contacts<Real> StepLoop<Real>::contacts() {
  State& s = *m;
  const bool full = s.a.options().fields == Fields::full;
  auto with_ids = [full](const Contacts<Real>& c, const std::int64_t* ids) {
    Contacts<Real> out = c;
    out.full = full;
    for (std::size_t k = 0; k < out.size(); ++k) {
      out.id_a[k] = ids[out.id_a[k]];
      out.id_b[k] = ids[out.id_b[k]];
    }
    return out;
  };
  if (s.found.empty()) {
    Contacts<Real> none;
    none.full = full;
    return none;
  }
  s.finish_merge();
  Contacts<Real> a = with_ids(s.a.resident_contacts(), s.bodies.id.data());
  if (!s.b_active) return a;
  std::vector<Contacts<Real>> runs;
  runs.push_back(std::move(a));
  runs.push_back(with_ids(s.b->resident_contacts(), s.b_id.data()));
  return merge_contact_runs<Real>(runs, full).contacts;
}

template <class Real>
std::uint64_t StepLoop<Real>::pair_hash_sum() {
  State& s = *m;
  std::uint64_t hash = 0;
  agreed_stage(s.session, "steps", [&] {
    s.finish_merge();
    if (s.found.empty()) return;
    auto add = [&](const Contacts<Real>& c, const std::int64_t* ids) {
      for (std::size_t k = 0; k < c.size(); ++k) hash += pair_hash(ids[c.id_a[k]], ids[c.id_b[k]]);
    };
    add(s.a.resident_contacts(), s.bodies.id.data());
    if (s.b_active) add(s.b->resident_contacts(), s.b_id.data());
  });
  return s.session.sum(hash);
}

template <class Real>
StepBodies StepLoop<Real>::gather_bodies() {
  State& s = *m;
  s.finish_merge();
  const StepBodies& b = s.bodies;
  const std::vector<std::uint64_t> counts = allgather_counts(s.session, b.size());
  const bool root = s.session.rank() == 0;
  const std::uint64_t total = std::accumulate(counts.begin(), counts.end(), std::uint64_t(0));
  StepBodies all;
  agreed_stage(s.session, "steps", [&] {
    if (root) all = sized_step_bodies(total, s.shapes);
  });
  auto gather = [&](const auto* local, auto* into, int field) {
    using T = std::remove_cv_t<std::remove_pointer_t<decltype(local)>>;
    std::vector<T*> at(counts.size(), nullptr);
    std::uint64_t offset = 0;
    for (std::size_t r = 0; r < counts.size(); ++r) {
      if (root) at[r] = into + offset;
      offset += counts[r];
    }
    if (root && counts[0] > 0) std::copy_n(local, counts[0], into);
    s.comm.gather_to_root(local, counts, at, std::uint64_t(1) << 30, k_body_gather_tag + field);
  };
  gather(b.position.data(), all.position.data(), 0);
  gather(b.radius.data(), all.radius.data(), 1);
  gather(b.id.data(), all.id.data(), 2);
  if (s.shapes) {
    // a rank without rows has no shape rows to send: it sends nothing (its count is 0)
    gather(b.shapes.shape.data(), all.shapes.shape.data(), 3);
    gather(b.shapes.semi_axes.data(), all.shapes.semi_axes.data(), 4);
    gather(b.shapes.orientation.data(), all.shapes.orientation.data(), 5);
  }
  if (!root) return {};
  std::vector<std::size_t> order(total);
  std::iota(order.begin(), order.end(), std::size_t(0));
  std::sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) { return all.id[x] < all.id[y]; });
  StepBodies sorted = sized_step_bodies(total, s.shapes);
  for (std::size_t k = 0; k < total; ++k) {
    const std::size_t i = order[k];
    sorted.position[k] = all.position[i];
    sorted.radius[k] = all.radius[i];
    sorted.id[k] = all.id[i];
    if (s.shapes) {
      sorted.shapes.shape[k] = all.shapes.shape[i];
      sorted.shapes.semi_axes[k] = all.shapes.semi_axes[i];
      sorted.shapes.orientation[k] = all.shapes.orientation[i];
    }
  }
  return sorted;
}

template <class Real>
StepStats StepLoop<Real>::stats() {
  State& s = *m;
  s.finish_merge();
  const std::size_t n = s.times.size(), n_engine = engine_stage_names().size();
  // per step: the step stages, then engine A's, whether A built, whether the rows were rebuilt
  std::vector<double> all;
  for (std::size_t k = 0; k < n; ++k) {
    all.insert(all.end(), s.times[k].begin(), s.times[k].end());
    all.insert(all.end(), s.engine_times[k].begin(), s.engine_times[k].end());
    all.push_back(s.built[k]);
    all.push_back(s.relaid[k]);
  }
  s.comm.allreduce_max(all);
  const std::size_t row = kStepStageCount + n_engine + 2;
  auto at = [&](std::size_t k, StepStage stage) { return all[k * row + static_cast<std::size_t>(stage)]; };
  auto median_at = [&](std::size_t j) {
    std::vector<double> v(n);
    for (std::size_t k = 0; k < n; ++k) v[k] = all[k * row + j];
    return cg::median(std::move(v));
  };
  StepStats st;
  st.steps = static_cast<int>(n);
  st.spin = s.motion.spin;
  st.drift = s.motion.drift;
  st.turned = s.shapes && s.motion.spin != 0;
  st.oriented = s.refresh && s.session.size() > 1;
  st.halo_rows = s.session.sum(s.halo_rows);
  st.setup = s.session.max(s.setup);
  st.frame = median_at(static_cast<std::size_t>(StepStage::frame));
  st.halo = median_at(static_cast<std::size_t>(StepStage::halo));
  st.halo_pack = median_at(static_cast<std::size_t>(StepStage::halo_pack));
  st.halo_mpi = median_at(static_cast<std::size_t>(StepStage::halo_mpi));
  st.halo_unpack = median_at(static_cast<std::size_t>(StepStage::halo_unpack));
  st.halo_on_device = s.halo_lists;
  st.interior = median_at(static_cast<std::size_t>(StepStage::interior));
  st.boundary = median_at(static_cast<std::size_t>(StepStage::boundary));
  st.step = median_at(static_cast<std::size_t>(StepStage::step));
  std::vector<double> migrate, rebuild, build, reuse, waits;
  double total = 0, frames = 0;
  for (std::size_t k = 0; k < n; ++k) {
    if (all[k * row + row - 1] > 0) {
      migrate.push_back(at(k, StepStage::migrate));
      rebuild.push_back(at(k, StepStage::rebuild));
    }
    if (at(k, StepStage::merge_wait) > 0) waits.push_back(at(k, StepStage::merge_wait));
    frames += at(k, StepStage::frame);
    total += at(k, StepStage::frame) + at(k, StepStage::migrate) + at(k, StepStage::rebuild) +
             at(k, StepStage::merge_wait) + at(k, StepStage::step);
    const double detect = at(k, StepStage::interior) + at(k, StepStage::boundary);
    (all[k * row + row - 2] > 0 ? build : reuse).push_back(detect);
  }
  st.migrate = median(migrate);
  st.merge_wait = median(waits);
  st.rebuild = median(rebuild);
  st.step_mean = n > 0 ? total / double(n) : 0;
  st.detect_mean = n > 0 ? (total - frames) / double(n) : 0;
  st.detect_build = median(build);
  st.detect_reuse = median(reuse);
  for (std::size_t j = 0; j < n_engine && n > 0; ++j) {
    const double t = median_at(kStepStageCount + j);
    if (t > 0) st.stages.push_back({engine_stage_names()[j], t});
    // the same stage over the steps that built their candidate lists (a few among many reuses)
    std::vector<double> v;
    for (std::size_t k = 0; k < n; ++k)
      if (all[k * row + row - 2] > 0) v.push_back(all[k * row + kStepStageCount + j]);
    const double tb = v.empty() ? 0 : cg::median(std::move(v));
    if (tb > 0) st.build_stages.push_back({engine_stage_names()[j], tb});
  }
  st.rebuilds = static_cast<std::uint64_t>(std::max(0, s.layouts - 1));
  st.migrated = s.migrated;
  st.rebalances = s.rebalances;
  const std::vector<std::uint64_t> owned = allgather_counts(s.session, s.bodies.size());
  st.owned_min = *std::min_element(owned.begin(), owned.end());
  st.owned_max = *std::max_element(owned.begin(), owned.end());
  st.builds = s.a.stats().candidate_builds - s.builds0;
  st.reuses = s.a.stats().candidate_reuses - s.reuses0;
  st.skin = s.skin;
  st.skin_auto = s.skin_auto;
  st.step_contacts = s.found;
  s.comm.allreduce_sum(st.step_contacts);
  if (!st.step_contacts.empty()) st.contacts = st.step_contacts.back();
  st.step_hashes = s.hashes;
  s.comm.allreduce_sum(st.step_hashes);
  return st;
}

template class StepLoop<float>;
template class StepLoop<double>;

}  // namespace cg
