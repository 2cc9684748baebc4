// One contact file from every rank's rows (see contact_file_shared.hpp): create (rank 0) → broadcast
// the layout → pwrite own rows (every rank) → attributes and rename (rank 0), agreeing after each.
#include "run/contact_file_shared.hpp"

#include <exception>
#include <optional>

#include "io/temp_output.hpp"
#include "run/stop.hpp"
#include "run/test_fault.hpp"
#include "timing.hpp"

namespace cg {

namespace {

// A temporary another rank writes, registered for removal should this rank end at once (remove_on_stop),
// unregistered on leaving.
struct ForgetOnReturn {
  explicit ForgetOnReturn(std::string path) : m_path(std::move(path)) { remove_on_stop(m_path); }
  ~ForgetOnReturn() { forget_on_stop(m_path); }
  ForgetOnReturn(const ForgetOnReturn&) = delete;
  ForgetOnReturn& operator=(const ForgetOnReturn&) = delete;
  std::string m_path;
};

// Runs `work` where `here` holds, then every rank agrees on the outcome (stage "write").
template <class F>
void write_stage(const Session& session, bool here, F&& work) {
  std::exception_ptr error;
  if (here) {
    try {
      work();
    } catch (...) {
      error = std::current_exception();
    }
  }
  session.agree(error, "write");
}

template <class Real>
double write_all(Session& session, const std::string& path, const Contacts<Real>& slice,
                 std::uint64_t first_row, std::uint64_t total_rows, RunInfo& info, int threads) {
  const auto t0 = WallClock::now();
  const bool root = session.rank() == 0;
  constexpr Precision precision = precision_of<Real>();
  const bool full = slice.full;

  // The temporary's name first: every other rank registers it for removal should the job end at once
  // (a rank killed: the launcher's SIGTERM reaches the others), and the collectives below make sure
  // that every rank has, before rank 0 creates it (rank 0 registers it in create_contact_file).
  const std::string temp = session.broadcast(root ? temp_name(path) : std::string());
  std::optional<ForgetOnReturn> registered;
  if (!root) registered.emplace(temp);

  // The slices tile [0, K): checked before anything is created.
  write_stage(session, true, [&] {
    if (first_row > total_rows || slice.size() > total_rows - first_row)
      throw Error(path + ": rows " + std::to_string(first_row) + " + " + std::to_string(slice.size()) +
                  " are outside the " + std::to_string(total_rows) + " rows of the file: internal error");
  });
  const unsigned long long rows = session.sum(slice.size()), with_full = session.sum(full ? 1 : 0);
  if (rows != total_rows ||
      (with_full != 0 && with_full != static_cast<unsigned long long>(session.size()))) {
    write_stage(session, root, [&] {
      throw Error(path + ": the ranks hold " + std::to_string(rows) + " rows for a file of " +
                  std::to_string(total_rows) + " (or differ in fields): internal error");
    });
  }

  // (a) rank 0 creates the file; the layout goes to every rank
  std::optional<ContactFileLayout> layout;
  write_stage(session, root, [&] { layout = create_contact_file(path, total_rows, precision, full); });
  const std::string text = session.broadcast(root ? layout->to_text() : std::string());
  // from here on rank 0 removes the temporary on any failure
  try {
    write_stage(session, true, [&] {
      if (!root) layout = ContactFileLayout::from_text(text);
      fault_point("write", session.rank());
      // (b) every rank its rows
      write_contact_rows(*layout, first_row, slice, threads);
    });
    // (c) rank 0: attributes (with the write time) and rename
    const double seconds = session.max(seconds_since(t0));
    info.times.push_back({"write", seconds});
    write_stage(session, root, [&] { commit_contact_file(*layout, info); });
    return seconds;
  } catch (const CommFailure&) {
    throw;
  } catch (...) {
    if (root && layout) discard_contact_file(*layout);
    throw;
  }
}

}  // namespace

template <class Real>
double write_contacts_distributed(Session& session, const std::string& path, const Contacts<Real>& slice,
                                  std::uint64_t first_row, std::uint64_t total_rows, RunInfo& info,
                                  int threads) {
  try {
    return write_all(session, path, slice, first_row, total_rows, info, threads);
  } catch (const CommFailure& e) {
    // Other ranks may be waiting in a collective this rank will never join.
    run_cleanup_actions();
    session.abort(e.exit_code(), e.what());
  }
}

template double write_contacts_distributed<float>(Session&, const std::string&, const Contacts<float>&,
                                                  std::uint64_t, std::uint64_t, RunInfo&, int);
template double write_contacts_distributed<double>(Session&, const std::string&, const Contacts<double>&,
                                                   std::uint64_t, std::uint64_t, RunInfo&, int);

}  // namespace cg
