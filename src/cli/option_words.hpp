#pragma once
// The words of the command line's enum options, shared by the subcommands' files (subcommands.hpp),
// and the validator that turns a word into its enum (enum_names).
#include <CLI/CLI.hpp>
#include <map>
#include <string>

#include "bench/broad_bench.hpp"
#include "engine.hpp"
#include "run/pipeline.hpp"
#if defined(CONTACTGRID_HAVE_BULLET)
#include "bench/bench.hpp"
#endif

namespace cg::cli {

inline const std::map<std::string, Backend> k_backends{
    {"cpu", Backend::cpu}, {"cuda", Backend::cuda}, {"auto", Backend::automatic}};
#if defined(CONTACTGRID_HAVE_BULLET)
inline const std::map<std::string, BenchKind> k_bench_kinds{
    {"spheres", BenchKind::spheres}, {"ellipsoids", BenchKind::ellipsoids}, {"mixed", BenchKind::mixed}};
#endif
inline const std::map<std::string, Precision> k_precisions{
    {"fp32", Precision::fp32}, {"fp64", Precision::fp64}, {"mixed", Precision::mixed}};
inline const std::map<std::string, Fields> k_fields{{"basic", Fields::basic}, {"full", Fields::full}};
inline const std::map<std::string, BroadPhase> k_broad_phases{{"auto", BroadPhase::automatic},
                                                              {"grid", BroadPhase::grid},
                                                              {"levels", BroadPhase::levels},
                                                              {"sweep", BroadPhase::sweep},
                                                              {"brute", BroadPhase::brute}};
inline const std::map<std::string, SlabAxis> k_axes{
    {"auto", SlabAxis::automatic}, {"x", SlabAxis::x}, {"y", SlabAxis::y}, {"z", SlabAxis::z}};
inline const std::map<std::string, Balance> k_balances{{"count", Balance::count}, {"width", Balance::width}};
inline const std::map<std::string, SceneRead> k_reads{
    {"auto", SceneRead::automatic}, {"own", SceneRead::own_rows}, {"all", SceneRead::all_rows}};
inline const std::map<std::string, ContactOutput> k_writes{{"gather", ContactOutput::gather},
                                                           {"ranks", ContactOutput::ranks}};

// An enum option by name: the names are what --help and the error of a wrong word show (CLI11's
// CheckedTransformer shows the enum's internal numbers too). The word becomes the enum's number for
// CLI11 to store.
template <class E>
CLI::Validator enum_names(const std::map<std::string, E>& names) {
  std::string list;
  for (const auto& entry : names) list += (list.empty() ? "" : "|") + entry.first;
  return CLI::Validator(
      [names, list](std::string& word) -> std::string {
        const auto it = names.find(word);
        if (it == names.end()) return "'" + word + "' is not one of " + list;
        word = std::to_string(static_cast<long long>(it->second));
        return {};
      },
      list);
}

}  // namespace cg::cli
