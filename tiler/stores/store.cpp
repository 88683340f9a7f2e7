// TileStore: choosing a store by path, and the name checks both stores share.
#include "tiler/stores/store.hpp"

#include "core/error.hpp"
#include "tiler/stores/store_mbtiles.hpp"

#include <memory>
#include <string>
#include <vector>

namespace tb::tiler {

std::unique_ptr<TileStore> open_directory_store(const std::string& path); // store_dir.cpp
std::unique_ptr<TileStore> open_sqlite_store(const std::string& path);    // store_sqlite.cpp
std::unique_ptr<TileStore> open_pmtiles_store(const std::string& path);   // store_pmtiles.cpp

namespace {

bool ends_with(const std::string& s, std::string_view suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Shows a name in an error message without letting control bytes into the log.
std::string printable(const std::string& s) {
    std::string out;
    for (unsigned char c : s.substr(0, 80)) {
        if (c < 0x20 || c >= 0x7f) {
            static const char* hex = "0123456789abcdef";
            out += "\\x";
            out += hex[c >> 4];
            out += hex[c & 15];
        } else {
            out += static_cast<char>(c);
        }
    }
    return s.size() > 80 ? out + "..." : out;
}

} // namespace

std::unique_ptr<TileStore> TileStore::open(const std::string& path) {
    if (path.empty()) {
        throw InputError("tile store: empty path; name a directory or an .sqlite file");
    }
    if (ends_with(path, ".sqlite") || ends_with(path, ".db")) {
        return open_sqlite_store(path);
    }
    if (ends_with(path, ".mbtiles")) {
        return std::make_unique<MbtilesStore>(path);
    }
    if (ends_with(path, ".pmtiles")) {
        return open_pmtiles_store(path);
    }
    return open_directory_store(path);
}

void TileStore::remove(const TileKey& key) {
    (void)key;
    throw InputError(describe() + ": tiles cannot be removed from it (it is written once); "
                                  "rebuild it with --force, or update a directory or an .sqlite "
                                  "file and convert that");
}

void TileStore::remove_document(const std::string& layer, const std::string& name) {
    (void)layer;
    throw InputError(describe() + ": document " + name +
                     " cannot be removed from it (it is written once); rebuild it with --force");
}

bool is_single_file_store(const std::string& path) {
    for (const char* suffix : {".sqlite", ".db", ".mbtiles", ".pmtiles"}) {
        if (ends_with(path, suffix)) {
            return true;
        }
    }
    return false;
}

void check_store_formats(const std::string& path, std::span<const Format> formats) {
    const bool mbtiles = ends_with(path, ".mbtiles");
    if (!mbtiles && !ends_with(path, ".pmtiles")) {
        return;
    }
    const std::string kind = mbtiles ? "an MBTiles file" : "a PMTiles archive";
    const std::string ext = mbtiles ? ".mbtiles" : ".pmtiles";
    std::vector<std::string> dem;
    for (Format f : formats) {
        if (!is_dem_format(f)) {
            throw InputError(path + ": " + kind +
                             " holds raster DEM tiles (terrarium or mapbox, EPSG:3857 XYZ PNG) "
                             "only, not " +
                             format_name(f) +
                             "; build --formats terrarium (or mapbox) into it, and mesh formats "
                             "into a directory or an .sqlite file");
        }
        dem.push_back(format_name(f));
    }
    if (dem.size() != 1) {
        throw InputError(path + ": " + kind +
                         " holds exactly one DEM encoding, and --formats names " +
                         (dem.empty() ? std::string("none") : dem[0] + " and " + dem[1]) +
                         "; build each encoding into its own file (--formats terrarium -o A" + ext +
                         ", then --formats mapbox -o B" + ext + ")");
    }
}

void TileStore::put_batch(std::span<const StoredTile> tiles) {
    for (const auto& t : tiles) {
        put(t.key, t.bytes);
    }
}

void validate_layer_name(const std::string& layer) {
    bool ok = !layer.empty() && layer.size() <= 64;
    for (char c : layer) {
        const bool allowed = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') ||
                             (c >= '0' && c <= '9') || c == '_' || c == '-';
        ok = ok && allowed;
    }
    if (!ok) {
        throw InputError("layer name '" + printable(layer) +
                         "': use 1 to 64 of the characters A-Z a-z 0-9 _ -");
    }
}

void validate_document_name(const std::string& name) {
    auto fail = [&](const std::string& why) {
        throw InputError("document name '" + printable(name) + "': " + why +
                         "; name a relative path inside the layer, such as 'tileset.json'");
    };
    if (name.empty()) {
        fail("empty");
    }
    if (name.size() > 512) {
        fail("longer than 512 bytes");
    }
    if (name.front() == '/') {
        fail("absolute path");
    }
    for (unsigned char c : name) {
        if (c == 0) {
            fail("contains a NUL byte");
        }
        if (c == '\\') {
            fail("contains a backslash");
        }
        if (c < 0x20 || c >= 0x7f) {
            fail("contains a control or non-ASCII byte");
        }
    }
    std::size_t start = 0;
    while (start <= name.size()) {
        std::size_t end = name.find('/', start);
        if (end == std::string::npos) {
            end = name.size();
        }
        const std::string_view part(name.data() + start, end - start);
        if (part.empty()) {
            fail("has an empty path part ('//' or a trailing '/')");
        }
        if (part.front() == '.') {
            fail("has a part starting with '.' ('..', '.', or a hidden name)");
        }
        start = end + 1;
    }
}

void validate_key(const TileKey& key) {
    validate_layer_name(key.layer);
    const auto& id = key.id;
    const bool ok = id.z >= 0 && id.z <= kMaxZoom && id.x >= 0 && id.y >= 0 &&
                    id.x < (std::int64_t{2} << id.z) && id.y < (std::int64_t{2} << id.z);
    if (!ok) {
        throw InputError("tile " + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
                         std::to_string(id.y) + ": outside every tiling scheme (z 0.." +
                         std::to_string(kMaxZoom) + ", x and y from 0 below 2^(z+1))");
    }
    if (is_dem_format(key.format) && key.eps_level != -1) {
        throw InputError(std::string(format_name(key.format)) +
                         " DEM tiles have no eps levels; expected eps level -1, got " +
                         std::to_string(key.eps_level));
    }
    if (key.eps_level < -1) {
        throw InputError("eps level " + std::to_string(key.eps_level) +
                         ": expected -1 (the zoom's ladder eps) or a level index >= 0");
    }
}

} // namespace tb::tiler
