#pragma once
// The one way Terrabound writes a number (and, below, a string) into a JSON document (tilesets,
// glTF, build manifests and summaries, the layer list, mesh statistics): the shortest decimal that
// reads back as the same double. JSON has no infinity and no NaN, so those are refused rather than
// written.
#include <string>
#include <string_view>

namespace tb::tiler {

// Throws InputError naming `what` when `v` is not finite.
std::string json_number(double v, std::string_view what = "a number");

// `s` as a JSON string literal, quotes included: '"' and '\\' escaped, control bytes as \u00XX.
std::string json_string(std::string_view s);

} // namespace tb::tiler
