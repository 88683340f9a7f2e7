#pragma once
// What made a store's tiles (keys and JSON values; the store knows no layer). Beside each layer's
// tiles a store keeps a manifest document: the settings that decide the tiles' bytes (and so the
// error bound each tile was made to), one "key": JSON value per line in a fixed order, with no
// timestamps, so that processes starting together write identical bytes.
//   build-manifest.json  written by `terrabound build` before its first tile (build.hpp);
//   serve-manifest.json  written by `terrabound serve` when it starts with a store.
// Before a store's tiles are handed out or added to, the manifest is compared with the layer's
// settings now: a tile made for another eps, DEM or Terrabound version would publish a bound
// that is not this layer's.
#include "tiler/stores/store.hpp"

#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tb::tiler {

inline constexpr const char* kBuildManifest = "build-manifest.json";
inline constexpr const char* kServeManifest = "serve-manifest.json";
// The record of a `build --update` in progress (tiler/pyramid/update.hpp): the manifest of the
// build it updates, written before the first tile changes and removed once the tileset
// documents are in. While it is there the layer's tiles are part old, part new: an update that
// was interrupted is finished by running it again, which reads its changes from this record,
// and nothing serves or converts the layer meanwhile.
inline constexpr const char* kUpdateRecord = "build-update.json";

using Manifest = std::vector<std::pair<std::string, std::string>>; // key, JSON value

std::string manifest_text(const Manifest& m);
// Reads what manifest_text wrote; lines that are not "key": value are skipped.
Manifest parse_manifest(const std::string& text);
// The value of `key`, or "(absent)".
std::string manifest_value(const Manifest& m, const std::string& key);

struct ManifestChange {
    std::string key, was, now;
};
// The first entry of `now` (in its order) whose value in `was` differs, skipping `ignore`d keys.
// An entry `was` lacks (older manifests record fewer) differs: what it was is unknown.
std::optional<ManifestChange>
first_change(const Manifest& was, const Manifest& now, const std::vector<std::string>& ignore = {});

// How a server may use a store it serves a layer from.
struct StoreUse {
    // Whether tiles at the layer's extra eps levels (EpsChoice::level >= 0) may be kept there.
    // A build has none, and the index k of another eps_levels list names another eps, so a
    // built store keeps only the layer's ladder tiles unless its eps_levels are the layer's.
    bool eps_levels = true;
    // The build manifest's "terrain_extensions" (which quantized-mesh extensions its .terrain
    // tiles hold, as a JSON array); empty when it records none (a serve cache, an older
    // build, no terrain), whose tiles hold them all.
    std::string terrain_extensions;
};

// Makes `store` ready to serve the tiles of layer `name`, whose tile settings are `now` (see
// tiler/pyramid/tile_settings.hpp), before any is read or written:
//   - a build manifest must match those settings (its bbox, formats, shards and
//     eps_levels aside), else InputError naming the setting, both values and the ways out;
//     when only the Terrabound version differs, the tiles are served with a warning line;
//   - a serve manifest that does not match means the tiles are an earlier server's cache made
//     with other settings: they are removed (one warning line), and the new manifest written;
//   - tiles with no manifest at all: in an SQLite store an older server's cache, removed (one
//     warning line); in a directory InputError (they may not be Terrabound's, so they are not
//     deleted on a guess);
//   - an empty layer gets a serve manifest.
// IoError when the store cannot be read or written.
StoreUse prepare_store_for_serving(TileStore& store, const std::string& name, const Manifest& now);

} // namespace tb::tiler
