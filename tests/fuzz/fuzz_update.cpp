// libFuzzer harness: any bytes as two build manifests (the last build's and this run's, split at
// the first line "----") through what `build --update` reads of them: parse_manifest,
// update_scope, parse_ranges and UpdateTiles. A damaged or foreign manifest must come back as
// InputError; any other exception, a crash or a sanitizer report is a finding.
#include "core/error.hpp"
#include "tiler/pyramid/update.hpp"

#include <cstdint>
#include <cstdlib>
#include <string>

namespace {

using namespace tb::tiler;

// The tiles an update of one pyramid touches, as build --update asks for them.
void touch(const UpdateScope& scope,
           const Manifest& was,
           const Manifest& now,
           const std::string& key) {
    const auto before = parse_ranges(manifest_value(was, key), key);
    const auto after = parse_ranges(manifest_value(now, key), key);
    const UpdateTiles tiles(scope, Scheme::Geodetic, before, after, scope.zooms, 0.25);
    const std::int64_t remade = tiles.remade();
    std::int64_t total = 0;
    for (const TileRange& r : after) {
        total += r.empty() ? 0 : r.count();
    }
    if (remade < 0 || remade > total || tiles.left_out_count() < 0) {
        std::abort(); // counts tiles of the new ranges, each once
    }
    for (const TileRange& r : after) {
        if (!r.empty()) {
            tiles.contains(TileId{r.z, r.x0, r.y0});
        }
    }
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    const std::size_t cut = text.find("\n----\n");
    if (cut == std::string::npos) {
        return 0;
    }
    const Manifest was = parse_manifest(text.substr(0, cut));
    const Manifest now = parse_manifest(text.substr(cut + 6));
    try {
        const UpdateScope scope = update_scope(was, now);
        if (scope.everything.empty()) {
            touch(scope, was, now, "mesh_ranges");
            touch(scope, was, now, "dem_ranges");
        }
    } catch (const tb::InputError& e) {
        if (std::string(e.what()).empty()) {
            std::abort();
        }
    }
    return 0;
}
