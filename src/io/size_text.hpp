#pragma once
// Sizes in bytes as a user writes them on the command line: a number with an optional unit K, M, G, T
// (powers of 1024; "GB" and "GiB" too), e.g. 4G, 512M, 1.5GiB, 800000000.
#include <cctype>
#include <cmath>
#include <cstdint>
#include <exception>
#include <string>

#include "errors.hpp"

namespace cg {

// Bytes of `text`; UsageError naming `option` when it is not a size or is out of range.
inline std::uint64_t parse_size(const std::string& text, const char* option) {
  std::size_t used = 0;
  double x = 0;
  try {
    x = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  std::string unit = text.substr(used);
  for (char& ch : unit) ch = char(std::toupper(static_cast<unsigned char>(ch)));
  if (unit.size() > 1 && unit.back() == 'B') unit.pop_back();  // "GB", "GiB" → "G", "GI"
  if (unit.size() > 1 && unit.back() == 'I') unit.pop_back();
  const std::size_t k = unit.empty() ? std::string::npos : std::string("KMGT").find(unit);
  if (used == 0 || !(x > 0) || !std::isfinite(x) ||
      (!unit.empty() && (unit.size() != 1 || k == std::string::npos)))
    throw UsageError(std::string(option) + ": '" + text +
                     "' is not a size (e.g. 4G, 512M, 1.5GiB, or bytes)");
  const double bytes = x * std::pow(1024.0, unit.empty() ? 0.0 : double(k + 1));
  if (bytes < 1 || bytes > 9e18) throw UsageError(std::string(option) + ": '" + text + "' is out of range");
  return std::uint64_t(bytes);
}

}  // namespace cg
