#pragma once
// A text output (CSV, SVG) written as every output of contactgrid: to "<path>.tmp.<pid>", then
// renamed, so a failed run leaves no file. Throws IoError naming the path.
#include <string>

namespace cg {
void write_text_file(const std::string& path, const std::string& text);
}  // namespace cg
