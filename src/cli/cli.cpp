// Command-line parsing. Every option is validated here, before any file is read or any rank talks:
// the subcommands' options are defined by their families' files (subcommands.hpp).
#include "cli/cli.hpp"

#include <CLI/CLI.hpp>
#include <cmath>
#include <vector>

#include "cli/subcommands.hpp"
#include "errors.hpp"
#include "session.hpp"

namespace cg {

std::optional<double> positive_number(const std::string& word) {
  std::size_t used = 0;
  double x = 0;
  try {
    x = std::stod(word, &used);
  } catch (const std::exception&) {
    return std::nullopt;
  }
  if (used != word.size() || !(x > 0) || !std::isfinite(x)) return std::nullopt;
  return x;
}

Accuracy parse_accuracy(const std::string& text) {
  const std::size_t comma = text.find(',');
  auto number = [&](const std::string& word, const char* what) {
    const std::optional<double> v = positive_number(word);
    if (!v) throw UsageError("--accuracy " + text + ": " + what + " '" + word + "' is not a number > 0");
    return *v;
  };
  Accuracy a;
  a.position = number(text.substr(0, comma), "the position error (relative to the smallest radius)");
  if (comma != std::string::npos) a.angle_deg = number(text.substr(comma + 1), "the normal angle (degrees)");
  return a;
}

int run_cli(int argc, char** argv, Session& session) {
  CLI::App app{
      "contactgrid: every touching or overlapping pair of spheres and ellipsoids, with Bullet's contact\n"
      "data. Le Grand's uniform grid on a CPU or CUDA backend; MPI slabs under mpirun.\n"
      "Files and conventions: docs/FORMAT.md; commands and exit codes: docs/USAGE.md."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "contactgrid " CONTACTGRID_VERSION);
  using namespace cli;
  std::vector<Subcommand> commands{add_generate(app), add_detect(app), add_simulate(app),
                                   add_compare(app),  add_study(app),  add_bench_broad(app)};
#if defined(CONTACTGRID_HAVE_BULLET)
  commands.push_back(add_validate(app));
  commands.push_back(add_bench(app));
#endif

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  }
  for (const Subcommand& command : commands)
    if (command.app->parsed()) return command.run(session);
  return 2;
}

}  // namespace cg
