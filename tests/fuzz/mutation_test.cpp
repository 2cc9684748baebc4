// Seeded mutation test of every reader of an input file, run as a user runs them: the contactgrid
// binary in a child process (posix_spawn) with a deadline, so a crash or a hang fails this test
// instead of killing it (issue #21).
//
//   contactgrid_mutation_test <contactgrid> <work dir> [--mutations N] [--seed S] [--jobs J]
//                             [--replay DIR]
//
// Corpus: a 200-sphere scene from `contactgrid generate` (with generate's root attributes), contact
// files from `contactgrid detect` (basic fp64, full fp32), and structure-aware variants written with
// the HDF5 API (wrong dimensions, element types, attribute types and shapes, chunked datasets that
// claim more rows than the file holds, variable-length datasets). Mutations: byte flips, runs of
// 0x00/0xff, truncation, and bytes patched inside the structures HDF5 trusts (the global heap
// collection "GCOL", object headers near attribute names, B-tree and local heap signatures).
// Each mutant goes through `detect --backend cpu` (scenes) or `compare` (contact files), and every
// third one also through `validate` when it is built. Allowed outcomes: exit 0, 3 (input error), and
// 1 for compare/validate (different / FAIL); after a failed detect no output file (nor temporary)
// may exist. --replay runs every file of DIR (the regression files, tests/data/damaged) through all
// readers instead. A failing mutant is kept under <work dir>/failures.
#include <fcntl.h>
#include <fmt/format.h>
#include <hdf5.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "io/inspect.hpp"

extern char** environ;

namespace fs = std::filesystem;

namespace {

constexpr double kDeadlineSeconds = 20;

struct Run {
  std::string kind;  // "detect", "compare", "validate"
  std::vector<std::string> argv;
  std::string input;   // the mutant
  std::string output;  // detect's -o (checked for absence after an error)
  std::string log;
  pid_t pid = -1;
  std::chrono::steady_clock::time_point start{};
};

struct Tally {
  std::map<std::string, std::map<std::string, int>> outcomes;  // kind → outcome → count
  int failures = 0;
};

std::vector<unsigned char> slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void spill(const std::string& path, const std::vector<unsigned char>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

std::string tail_of(const std::string& path) {
  std::vector<unsigned char> b = slurp(path);
  std::string s(b.begin(), b.end());
  return s.size() > 400 ? s.substr(s.size() - 400) : s;
}

pid_t spawn(const std::vector<std::string>& args, const std::string& log) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) {
    std::fprintf(stderr, "cannot start %s: %s\n", argv[0], std::strerror(rc));
    std::exit(2);
  }
  return pid;
}

// Runs a command to completion (corpus making): its exit code.
int run_now(const std::vector<std::string>& args, const std::string& log) {
  const pid_t pid = spawn(args, log);
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

void judge(const Run& r, int status, bool timed_out, Tally& tally, const std::string& failures) {
  std::string outcome, problem;
  if (timed_out) {
    outcome = "hang";
    problem = fmt::format("no exit within {} s (killed)", kDeadlineSeconds);
  } else if (WIFSIGNALED(status)) {
    outcome = fmt::format("signal {}", WTERMSIG(status));
    problem = fmt::format("killed by signal {} ({})", WTERMSIG(status), strsignal(WTERMSIG(status)));
  } else {
    const int code = WEXITSTATUS(status);
    outcome = fmt::format("exit {}", code);
    const bool allowed = code == 0 || code == 3 || (code == 1 && r.kind != "detect");
    if (!allowed)
      problem = fmt::format("exit code {} (allowed: 0, 3{})", code, r.kind != "detect" ? ", 1" : "");
    if (r.kind == "detect" && code != 0) {
      std::error_code ec;
      for (const auto& e : fs::directory_iterator(fs::path(r.output).parent_path(), ec)) {
        const std::string name = e.path().filename().string();
        if (name.rfind(fs::path(r.output).filename().string(), 0) == 0)
          problem += fmt::format("{}output {} exists after the error", problem.empty() ? "" : "; ", name);
      }
    }
  }
  ++tally.outcomes[r.kind][outcome];
  if (r.kind == "detect") {
    std::error_code ec;
    fs::remove(r.output, ec);
  }
  if (problem.empty()) return;
  ++tally.failures;
  const std::string kept = (fs::path(failures) / fs::path(r.input).filename()).string();
  std::error_code ec;
  fs::copy_file(r.input, kept, fs::copy_options::overwrite_existing, ec);
  std::string command;
  for (const std::string& a : r.argv) command += a + " ";
  std::fprintf(stderr, "FAIL: %s\n  %s\n  kept as %s\n  output: %s\n", problem.c_str(), command.c_str(),
               kept.c_str(), tail_of(r.log).c_str());
}

// Runs every command, `jobs` at a time, each under the deadline.
void run_all(std::vector<Run>& runs, int jobs, Tally& tally, const std::string& failures) {
  std::vector<Run*> active;
  std::size_t next = 0;
  while (next < runs.size() || !active.empty()) {
    while (next < runs.size() && static_cast<int>(active.size()) < jobs) {
      Run& r = runs[next++];
      r.start = std::chrono::steady_clock::now();
      r.pid = spawn(r.argv, r.log);
      active.push_back(&r);
    }
    bool progressed = false;
    for (std::size_t k = 0; k < active.size();) {
      Run& r = *active[k];
      int status = 0;
      const pid_t done = waitpid(r.pid, &status, WNOHANG);
      const double age = std::chrono::duration<double>(std::chrono::steady_clock::now() - r.start).count();
      bool timed_out = false;
      if (done == 0 && age > kDeadlineSeconds) {
        kill(r.pid, SIGKILL);
        waitpid(r.pid, &status, 0);
        timed_out = true;
      } else if (done == 0) {
        ++k;
        continue;
      }
      judge(r, status, timed_out, tally, failures);
      active.erase(active.begin() + static_cast<std::ptrdiff_t>(k));
      progressed = true;
    }
    if (!progressed) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

// ---- structure-aware variants, written with the HDF5 API ------------------------------------------

void write_vlen_string_dataset(const std::string& path, const char* name) {
  hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, H5T_VARIABLE);
  hsize_t dims[1] = {2};
  hid_t space = H5Screate_simple(1, dims, nullptr);
  hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
  H5Pset_create_intermediate_group(lcpl, 1);
  hid_t d = H5Dcreate2(file, name, type, space, lcpl, H5P_DEFAULT, H5P_DEFAULT);
  const char* text[2] = {"one", "two"};
  H5Dwrite(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, text);
  H5Dclose(d);
  H5Pclose(lcpl);
  H5Sclose(space);
  H5Tclose(type);
  H5Fclose(file);
}

// A chunked float64 dataset of `rows` × cols with nothing written (no chunk allocated).
void write_empty_chunked(const std::string& path, const char* name, hsize_t rows, hsize_t cols) {
  hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  hsize_t dims[2] = {rows, cols}, chunk[2] = {1024, cols};
  const int rank = cols ? 2 : 1;
  if (!cols) dims[0] = rows, chunk[0] = 1024;
  hid_t space = H5Screate_simple(rank, dims, nullptr);
  hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  H5Pset_chunk(dcpl, rank, chunk);
  hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
  H5Pset_create_intermediate_group(lcpl, 1);
  hid_t d = H5Dcreate2(file, name, H5T_IEEE_F64LE, space, lcpl, dcpl, H5P_DEFAULT);
  H5Dclose(d);
  H5Pclose(lcpl);
  H5Pclose(dcpl);
  H5Sclose(space);
  H5Fclose(file);
}

void write_array_attribute(const std::string& path, const char* name) {
  hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  hid_t root = H5Gopen2(file, "/", H5P_DEFAULT);
  H5Adelete(root, name);
  hsize_t dims[1] = {2};
  hid_t space = H5Screate_simple(1, dims, nullptr);
  hid_t a = H5Acreate2(root, name, H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT);
  const double v[2] = {0.1, 0.2};
  H5Awrite(a, H5T_NATIVE_DOUBLE, v);
  H5Aclose(a);
  H5Sclose(space);
  H5Gclose(root);
  H5Fclose(file);
}

struct Seed {
  std::string path;
  bool scene;  // else a contact file
};

std::vector<Seed> make_variants(const std::string& dir, const std::string& scene,
                                const std::string& contacts) {
  std::vector<Seed> out;
  auto copy = [&](const std::string& from, const std::string& name) {
    const std::string to = dir + "/" + name;
    fs::copy_file(from, to, fs::copy_options::overwrite_existing);
    return to;
  };
  using cg::AttrValue;
  using cg::RawType;
  const std::vector<double> p6{0, 0, 0, 1, 1, 1}, r2{0.5, 0.5};
  {  // attribute types: radius bounds as strings, arrays, integers; generator as an integer
    std::string f = copy(scene, "v_radius_high_string.h5");
    cg::write_raw_attribute(f, "radius_high", AttrValue{std::string("big")});
    out.push_back({f, true});
    f = copy(scene, "v_radius_low_array.h5");
    write_array_attribute(f, "radius_low");
    out.push_back({f, true});
    f = copy(scene, "v_radius_int.h5");
    cg::write_raw_attribute(f, "radius_low", AttrValue{std::int64_t{0}});
    cg::write_raw_attribute(f, "generator", AttrValue{std::int64_t{7}});
    out.push_back({f, true});
    f = copy(contacts, "v_precision_array.h5");
    write_array_attribute(f, "precision");
    out.push_back({f, false});
  }
  {  // dimensions and element types
    std::string f = dir + "/v_position_2cols.h5";
    cg::write_raw_dataset(f, "/spheres/position", RawType::float64, {3, 2}, p6);
    cg::write_raw_dataset(f, "/spheres/radius", RawType::float64, {3}, std::vector<double>{1, 1, 1});
    out.push_back({f, true});
    f = dir + "/v_int32_position.h5";
    cg::write_raw_dataset(f, "/spheres/position", RawType::int32, {2, 3}, p6);
    cg::write_raw_dataset(f, "/spheres/radius", RawType::float32, {2}, r2);
    out.push_back({f, true});
    f = dir + "/v_rank3.h5";
    cg::write_raw_dataset(f, "/spheres/position", RawType::float64, {2, 3, 1}, p6);
    cg::write_raw_dataset(f, "/spheres/radius", RawType::float64, {2}, r2);
    out.push_back({f, true});
    f = dir + "/v_vlen_radius.h5";
    cg::write_raw_dataset(f, "/spheres/position", RawType::float64, {2, 3}, p6);
    write_vlen_string_dataset(f, "/spheres/radius");
    out.push_back({f, true});
    f = dir + "/v_huge_chunked.h5";  // 2^40 rows claimed, nothing stored
    cg::write_raw_dataset(f, "/spheres/radius", RawType::float64, {2}, r2);
    write_empty_chunked(f, "/spheres/position", hsize_t(1) << 40, 3);
    out.push_back({f, true});
    f = dir + "/v_ellipsoids_short.h5";
    cg::write_raw_dataset(f, "/ellipsoids/position", RawType::float64, {2, 3}, p6);
    cg::write_raw_dataset(f, "/ellipsoids/semi_axes", RawType::float64, {2, 3}, p6);
    cg::write_raw_dataset(f, "/ellipsoids/orientation", RawType::float64, {1, 4},
                          std::vector<double>{1, 0, 0, 0});
    out.push_back({f, true});
  }
  {  // contact files: vlen ids, a chunked distance claiming 2^40 rows, float16-sized ints
    std::string f = dir + "/v_contacts_vlen_ids.h5";
    cg::write_raw_attribute(f, "precision", AttrValue{std::string("fp64")});
    write_vlen_string_dataset(f, "/contacts/id_a");
    cg::write_raw_dataset(f, "/contacts/id_b", RawType::int64, {2}, std::vector<double>{1, 2});
    out.push_back({f, false});
    f = dir + "/v_contacts_huge.h5";
    cg::write_raw_attribute(f, "precision", AttrValue{std::string("fp64")});
    cg::write_raw_dataset(f, "/contacts/id_a", RawType::int64, {2}, std::vector<double>{0, 1});
    cg::write_raw_dataset(f, "/contacts/id_b", RawType::int64, {2}, std::vector<double>{1, 2});
    write_empty_chunked(f, "/contacts/distance", hsize_t(1) << 40, 0);
    out.push_back({f, false});
  }
  return out;
}

// ---- mutations --------------------------------------------------------------------------------

// Offsets of every occurrence of `what` in b.
std::vector<std::size_t> find_all(const std::vector<unsigned char>& b, const std::string& what) {
  std::vector<std::size_t> at;
  auto it = b.begin();
  while ((it = std::search(it, b.end(), what.begin(), what.end())) != b.end()) {
    at.push_back(static_cast<std::size_t>(it - b.begin()));
    ++it;
  }
  return at;
}

std::string mutate(std::vector<unsigned char>& b, std::mt19937_64& rng) {
  auto below = [&](std::size_t n) { return n == 0 ? 0 : static_cast<std::size_t>(rng() % n); };
  if (b.empty()) return "empty";
  switch (below(6)) {
    case 0: {  // byte flips
      const std::size_t n = 1 + below(8);
      for (std::size_t k = 0; k < n; ++k) b[below(b.size())] ^= static_cast<unsigned char>(1 + below(255));
      return fmt::format("flip {} bytes", n);
    }
    case 1: {  // a run of 0x00 or 0xff
      const std::size_t at = below(b.size()), len = std::min(b.size() - at, 1 + below(64));
      const unsigned char v = below(2) ? 0xff : 0x00;
      std::fill_n(b.begin() + static_cast<std::ptrdiff_t>(at), len, v);
      return fmt::format("run of {} x{:02x} at {}", len, v, at);
    }
    case 2: {  // truncation
      const std::size_t size = below(b.size());
      b.resize(size);
      return fmt::format("truncate to {}", size);
    }
    default: {  // bytes patched inside a structure HDF5 trusts
      static const char* anchors[] = {
          "GCOL",      "OHDR",       "TREE",        "HEAP",      "SNOD",
          "generator", "radius_low", "radius_high", "precision", "software_version",
          "position",  "distance"};
      const std::string anchor = anchors[below(std::size(anchors))];
      const std::vector<std::size_t> at = find_all(b, anchor);
      if (at.empty()) {
        b[below(b.size())] ^= 0x80;
        return "flip (no anchor)";
      }
      const std::size_t base = at[below(at.size())];
      const std::size_t n = 1 + below(4);
      for (std::size_t k = 0; k < n; ++k) {
        const std::ptrdiff_t off = static_cast<std::ptrdiff_t>(below(160)) - 64;
        const std::ptrdiff_t p = static_cast<std::ptrdiff_t>(base) + off;
        if (p >= 0 && static_cast<std::size_t>(p) < b.size()) {
          const std::size_t q = static_cast<std::size_t>(p);
          switch (below(3)) {
            case 0:
              b[q] ^= static_cast<unsigned char>(1 + below(255));
              break;
            case 1:
              b[q] = 0xff;
              break;
            default:
              b[q] = static_cast<unsigned char>(b[q] + 1);
          }
        }
      }
      return fmt::format("patch {} bytes near {}", n, anchor);
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr,
                 "usage: %s <contactgrid> <work dir> [--mutations N] [--seed S] [--jobs J] [--replay DIR]\n",
                 argv[0]);
    return 2;
  }
  const std::string cg = fs::absolute(argv[1]).string();
  const std::string work = fs::absolute(argv[2]).string();
  long mutations = 1000, jobs = 2;
  std::uint64_t seed = 21;
  std::string replay;
  for (int k = 3; k + 1 < argc; k += 2) {
    const std::string key = argv[k], value = argv[k + 1];
    if (key == "--mutations") mutations = std::stol(value);
    if (key == "--seed") seed = std::stoull(value);
    if (key == "--jobs") jobs = std::stol(value);
    if (key == "--replay") replay = value;
  }
  std::error_code ec;
  fs::remove_all(work, ec);
  const std::string corpus = work + "/corpus", mutants = work + "/mutants", out = work + "/out",
                    logs = work + "/logs", failures = work + "/failures";
  for (const std::string& d : {corpus, mutants, out, logs, failures}) fs::create_directories(d);

  const std::string scene = corpus + "/scene.h5", contacts = corpus + "/contacts.h5",
                    contacts_full = corpus + "/contacts_full.h5";
  if (run_now({cg, "generate", scene, "-n", "200", "--seed", "7", "-q"}, logs + "/corpus.log") != 0 ||
      run_now({cg, "detect", scene, "-o", contacts, "--backend", "cpu", "-q"}, logs + "/corpus.log") != 0 ||
      run_now({cg, "detect", scene, "-o", contacts_full, "--backend", "cpu", "--fields", "full",
               "--precision", "fp32", "-q"},
              logs + "/corpus.log") != 0) {
    std::fprintf(stderr, "cannot make the corpus: %s\n", tail_of(logs + "/corpus.log").c_str());
    return 2;
  }
  const bool have_validate = run_now({cg, "validate", "--help"}, logs + "/validate_help.log") == 0;

  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  std::vector<Seed> seeds{{scene, true}, {contacts, false}, {contacts_full, false}};
  for (const Seed& s : make_variants(corpus, scene, contacts)) seeds.push_back(s);

  std::vector<Run> runs;
  auto add_runs = [&](const std::string& file, bool is_scene, bool with_validate, const std::string& tag) {
    if (is_scene) {
      const std::string o = out + "/" + tag + ".out.h5";
      runs.push_back({"detect",
                      {cg, "detect", file, "-o", o, "--backend", "cpu", "-q"},
                      file,
                      o,
                      logs + "/" + tag + ".detect.log"});
      if (with_validate)
        runs.push_back(
            {"validate", {cg, "validate", file, contacts}, file, "", logs + "/" + tag + ".validate.log"});
    } else {
      runs.push_back(
          {"compare", {cg, "compare", file, contacts}, file, "", logs + "/" + tag + ".compare.log"});
      if (with_validate)
        runs.push_back(
            {"validate", {cg, "validate", scene, file}, file, "", logs + "/" + tag + ".validate.log"});
    }
  };

  std::map<std::string, int> kinds;
  if (!replay.empty()) {  // the regression files: every reader
    for (const auto& e : fs::directory_iterator(replay)) {
      if (e.path().extension() != ".h5") continue;
      const std::string tag = e.path().stem().string();
      const std::string file = mutants + "/" + e.path().filename().string();
      fs::copy_file(e.path(), file, fs::copy_options::overwrite_existing);
      add_runs(file, true, have_validate, tag + ".s");
      add_runs(file, false, have_validate, tag + ".c");
    }
  } else {
    std::mt19937_64 rng(seed);
    std::map<std::string, std::vector<unsigned char>> bytes;
    for (const Seed& s : seeds) bytes[s.path] = slurp(s.path);
    for (long i = 0; i < mutations; ++i) {
      const Seed& s = seeds[i < static_cast<long>(seeds.size()) ? i : rng() % seeds.size()];
      std::vector<unsigned char> b = bytes[s.path];
      std::string how = i < static_cast<long>(seeds.size()) ? "unmutated variant" : mutate(b, rng);
      ++kinds[how.substr(0, how.find(' '))];
      const std::string tag = fmt::format("m{:05d}", i);
      const std::string file = mutants + "/" + tag + "_" + fs::path(s.path).stem().string() + ".h5";
      spill(file, b);
      add_runs(file, s.scene, have_validate && i % 3 == 0, tag);
    }
  }

  const auto t0 = std::chrono::steady_clock::now();
  Tally tally;
  run_all(runs, static_cast<int>(std::max(1L, jobs)), tally, failures);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  std::printf("%s: %zu runs in %.1f s (%ld jobs, seed %llu%s)\n", replay.empty() ? "mutations" : "replay",
              runs.size(), seconds, jobs, static_cast<unsigned long long>(seed),
              have_validate ? ", validate included" : ", validate not built");
  for (const auto& [how, n] : kinds) std::printf("  mutation %-10s %d\n", how.c_str(), n);
  for (const auto& [kind, outcomes] : tally.outcomes) {
    std::printf("  %-8s", kind.c_str());
    for (const auto& [outcome, n] : outcomes) std::printf("  %s: %d", outcome.c_str(), n);
    std::printf("\n");
  }
  if (tally.failures) {
    std::printf("%d FAILED (kept in %s)\n", tally.failures, failures.c_str());
    return 1;
  }
  fs::remove_all(mutants, ec);
  fs::remove_all(out, ec);
  fs::remove_all(logs, ec);
  return 0;
}
