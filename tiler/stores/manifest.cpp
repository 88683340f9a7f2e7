// Store manifests: what decided a layer's stored tiles, and the check `serve` makes before it
// hands any of them out (see manifest.hpp).
#include "tiler/stores/manifest.hpp"

#include "core/error.hpp"
#include "tiler/json_number.hpp"
#include "tiler/log.hpp"

#include <algorithm>
#include <sstream>

namespace tb::tiler {
std::string manifest_text(const Manifest& m) {
    std::string out = "{\n";
    for (std::size_t i = 0; i < m.size(); ++i) {
        out +=
            "  " + json_string(m[i].first) + ": " + m[i].second + (i + 1 < m.size() ? ",\n" : "\n");
    }
    return out + "}\n";
}

Manifest parse_manifest(const std::string& text) {
    Manifest m;
    std::istringstream in(text);
    std::string line;
    while (std::getline(in, line)) {
        const auto q0 = line.find('"');
        const auto q1 = q0 == std::string::npos ? q0 : line.find('"', q0 + 1);
        const auto colon = q1 == std::string::npos ? q1 : line.find(": ", q1);
        if (colon == std::string::npos) {
            continue;
        }
        std::string value = line.substr(colon + 2);
        if (!value.empty() && value.back() == ',') {
            value.pop_back();
        }
        m.emplace_back(line.substr(q0 + 1, q1 - q0 - 1), value);
    }
    return m;
}

std::string manifest_value(const Manifest& m, const std::string& key) {
    for (const auto& [k, v] : m) {
        if (k == key) {
            return v;
        }
    }
    return "(absent)";
}

std::optional<ManifestChange>
first_change(const Manifest& was, const Manifest& now, const std::vector<std::string>& ignore) {
    for (const auto& [key, value] : now) {
        if (std::find(ignore.begin(), ignore.end(), key) != ignore.end()) {
            continue;
        }
        const std::string old = manifest_value(was, key);
        if (old != value) {
            return ManifestChange{key, old, value};
        }
    }
    return std::nullopt;
}

namespace {

// "eps was [2, 1], now [80, 40]", or for an entry the manifest lacks, what that means.
std::string describe(const ManifestChange& c) {
    if (c.was == "(absent)") {
        return c.key + " is not recorded (made by an older terrabound), now " + c.now;
    }
    return c.key + " was " + c.was + ", now " + c.now;
}

// The one entry `key` of `m`.
Manifest only(const Manifest& m, const std::string& key) {
    return {{key, manifest_value(m, key)}};
}

} // namespace

StoreUse prepare_store_for_serving(TileStore& store, const std::string& name, const Manifest& now) {
    const std::string where = store.describe() + " (layer " + name + ")";

    if (const auto text = store.get_document(name, kBuildManifest)) {
        if (store.get_document(name, kUpdateRecord)) {
            throw InputError(where +
                             ": an update of its build (terrabound build --update) has not "
                             "finished, so its tiles are part old, part new; finish it by running "
                             "that build again with --update, then serve it");
        }
        const Manifest built = parse_manifest(*text);
        const auto change =
            first_change(built, now, {"bbox", "formats", "shard_count", "eps_levels", "version"});
        if (change) {
            throw InputError(where +
                             ": its tiles were made by terrabound build with other settings (" +
                             describe(*change) +
                             "); serve it with the settings it was built with, rebuild it with "
                             "build --force, or give serve another store");
        }
        // Another Terrabound revision made the tiles to the same settings and bounds: they are
        // served, and the warning says how to have this one's.
        if (const auto version = first_change(built, only(now, "version"))) {
            const auto bare = [](const std::string& v) { // the JSON string's text
                return v.size() >= 2 && v.front() == '"' ? v.substr(1, v.size() - 2) : v;
            };
            log::warn("store: " + where + " was built by terrabound " + bare(version->was) +
                      ", this is " + bare(version->now) +
                      "; serving its tiles as built (same settings); rebuild with build --force "
                      "for this revision's tiles");
        }
        StoreUse use;
        use.eps_levels = !first_change(built, only(now, "eps_levels")).has_value();
        for (const auto& [key, value] : built) {
            if (key == "terrain_extensions") {
                use.terrain_extensions = value;
            }
        }
        if (!use.eps_levels) {
            log::info("store: " + where +
                      " was built without this layer's eps_levels; tiles at those levels are "
                      "cached in memory only");
        }
        return use;
    }
    if (const auto served = store.get_document(name, kServeManifest)) {
        const auto change = first_change(parse_manifest(*served), now);
        if (!change) {
            return {};
        }
        log::warn("store: " + where + " holds tiles made with other settings (" +
                  describe(*change) + "); removing them");
        store.remove_layer(name);
    } else if (store.has_layer(name)) {
        // `build` writes its manifest before any tile, so tiles of ours with no manifest at all
        // are an older server's cache; in a directory they may also be someone else's files.
        if (!store.written_by_terrabound_only()) {
            throw InputError(where + " holds tiles but no " + std::string(kServeManifest) + " or " +
                             kBuildManifest +
                             " saying what made them (an older terrabound's cache, or other "
                             "files); move the layer's directory aside or delete it, or give "
                             "serve another store");
        }
        log::warn("store: " + where +
                  " holds tiles an older terrabound kept without recording its settings; "
                  "removing them");
        store.remove_layer(name);
    }
    store.put_document(name, kServeManifest, manifest_text(now));
    return {};
}

} // namespace tb::tiler
