// The offline pyramid builder (see build.hpp for the order of events that makes it safe to
// kill). Threads: N workers take tile indices from one atomic counter over the fixed order,
// make the tile's formats and push the bytes into a bounded queue; the calling thread is the
// only writer: it drains the queue into the store in batches and draws the progress.
#include "tiler/pyramid/build.hpp"

#include "tiler/formats/quantized_mesh.hpp"
#include "tiler/formats/terrain_tiles.hpp"

#include "core/error.hpp"
#include "tiler/cpus.hpp"
#include "tiler/dem_tiles.hpp"
#include "tiler/json_number.hpp"
#include "tiler/log.hpp"
#include "tiler/pyramid/hosting.hpp"
#include "tiler/pyramid/tile_settings.hpp"
#include "tiler/pyramid/update.hpp"
#include "tiler/sources/lattice_raster.hpp"
#include "tiler/stores/checksum.hpp"
#include "tiler/stores/output_lock.hpp"
#include "tiler/stores/store.hpp"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <exception>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>
#include <unistd.h>

namespace tb::tiler {
namespace {

using Clock = std::chrono::steady_clock;

constexpr std::size_t kBatchTiles = 64;  // tiles per SQLite transaction
constexpr double kBatchSeconds = 1.0;    // ... or this long since the last commit
constexpr double kLogEverySeconds = 5.0; // progress lines when stderr is no terminal
constexpr double kBarEverySeconds = 0.1; // progress bar redraws on a terminal

std::string shard_document(const ShardSpec& s) {
    return "build-shards/" + std::to_string(s.index) + "-of-" + std::to_string(s.count) + ".json";
}

// Throws InputError naming the first parameter that differs. shard_count is checked only
// when `check_shards` (shards and --finalize must agree on N; an unsharded resume need not).
void compare_manifests(const Manifest& was,
                       const Manifest& now,
                       bool check_shards,
                       const std::string& where) {
    std::vector<std::string> ignore;
    if (!check_shards) {
        ignore.emplace_back("shard_count");
    }
    if (const auto change = first_change(was, now, ignore)) {
        const std::string fix =
            change->key == "version"
                ? "a build cannot be continued by another terrabound revision (its version, or "
                  "the code that makes tiles, changed); use --force to start over"
                : "rerun with the same parameters, or use --force to start over";
        throw InputError(where + ": the existing build was made with different parameters: " +
                         change->key + " was " + change->was + ", now " + change->now + "; " + fix);
    }
}

// ---- the queue between workers and the writer: bounded, so memory is too ----

struct Made {
    TileId id;
    std::vector<std::pair<Format, std::string>> tiles;
    bool dem = false;            // a tile of the DEM pyramid
    std::vector<Format> removed; // an update: formats the tile no longer has
};

// Removes a tile's `formats` and the documents that hang on it (the external tileset and the
// 3D Tiles terrain subtree rooted at it, when there are).
void remove_tile(TileStore& store,
                 const std::string& name,
                 const TileId& id,
                 const std::vector<Format>& formats) {
    for (Format f : formats) {
        store.remove(TileKey{name, id, f, -1});
        const std::string zxy =
            std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
        if (f == Format::Glb || f == Format::Drc) {
            store.remove_document(name, "tilesets/" + zxy + ".json");
        } else if (f == Format::Terrain3d && id.z % kTerrainSubtreeLevels == 0) {
            const std::int64_t side = std::int64_t{1} << id.z;
            store.remove_document(name,
                                  "terrain/" + std::to_string(id.x / side) + "/" +
                                      std::to_string(id.z) + "/" + std::to_string(id.x % side) +
                                      "/" + std::to_string(id.y) + ".subtree");
        }
    }
}

// Leaves in made's .terrain tile only the quantized-mesh extensions in `mask`.
void keep_terrain_extensions(Made& made, unsigned mask) {
    if (mask == kAllQuantizedMeshExtensions) {
        return;
    }
    for (auto& [format, bytes] : made.tiles) {
        if (format == Format::Terrain) {
            bytes = select_extensions(bytes, mask);
        }
    }
}

class Queue {
public:
    explicit Queue(std::size_t capacity) : capacity_(capacity) {}

    bool push(Made&& m) { // false once closed
        std::unique_lock lock(mutex_);
        not_full_.wait(lock, [&] { return closed_ || items_.size() < capacity_; });
        if (closed_) {
            return false;
        }
        items_.push_back(std::move(m));
        not_empty_.notify_one();
        return true;
    }

    // Waits up to `timeout`; nullopt when nothing came.
    std::optional<Made> pop(std::chrono::milliseconds timeout) {
        std::unique_lock lock(mutex_);
        if (!not_empty_.wait_for(lock, timeout, [&] { return !items_.empty(); })) {
            return std::nullopt;
        }
        Made m = std::move(items_.front());
        items_.pop_front();
        not_full_.notify_one();
        return m;
    }

    void close() {
        std::lock_guard lock(mutex_);
        closed_ = true;
        not_full_.notify_all();
    }

private:
    std::size_t capacity_;
    std::mutex mutex_;
    std::condition_variable not_full_, not_empty_;
    std::deque<Made> items_;
    bool closed_ = false;
};

// ---- the fixed tile order: zoom ascending, then rows (y), then columns (x) ----

struct Plan {
    std::vector<TileRange> ranges;     // one per zoom and pyramid, none empty
    std::vector<Scheme> schemes;       // each range's scheme
    std::vector<std::int64_t> offsets; // index of each range's first tile
    std::int64_t total = 0;
    std::int64_t mesh_total = 0; // tiles before this index are mesh tiles, the rest DEM tiles

    bool dem(std::int64_t i) const { return i >= mesh_total; }

    // The ranges of the mesh pyramid, or of the DEM pyramid.
    std::vector<TileRange> ranges_of(bool dem_pyramid) const {
        std::vector<TileRange> out;
        for (std::size_t k = 0; k < ranges.size(); ++k) {
            if ((offsets[k] >= mesh_total) == dem_pyramid) {
                out.push_back(ranges[k]);
            }
        }
        return out;
    }

    ValidTile at(std::int64_t i) const {
        const auto k = static_cast<std::size_t>(
            std::upper_bound(offsets.begin(), offsets.end(), i) - offsets.begin() - 1);
        return ValidTile::in_range(schemes[k], ranges[k], i - offsets[k]);
    }
};

// Appends the non-empty ranges of zooms min_z..max_z of one pyramid, cut to --bbox.
template <typename RangeAt>
void add_ranges(Plan& plan,
                const BuildOptions& o,
                Scheme scheme,
                int min_z,
                int max_z,
                const RangeAt& range_at) {
    for (int z = min_z; z <= max_z; ++z) {
        TileRange r = range_at(z);
        if (o.bbox) {
            const TileRange b = tiles_covering(scheme, *o.bbox, z);
            r.x0 = std::max(r.x0, b.x0);
            r.y0 = std::max(r.y0, b.y0);
            r.x1 = std::min(r.x1, b.x1);
            r.y1 = std::min(r.y1, b.y1);
        }
        r.z = z;
        if (r.empty()) {
            continue;
        }
        plan.offsets.push_back(plan.total);
        plan.ranges.push_back(r);
        plan.schemes.push_back(scheme);
        plan.total += r.count();
    }
}

bool wants_terrain(const Layer& layer, const BuildOptions& o) {
    return layer.options().scheme == Scheme::Geodetic &&
           std::any_of(o.formats.begin(), o.formats.end(), is_terrain_format);
}

bool wants(const BuildOptions& o, Format f) {
    return std::find(o.formats.begin(), o.formats.end(), f) != o.formats.end();
}

TerrainSpec terrain_spec_of(const Layer& layer) {
    return TerrainSpec{layer.options().name,
                       layer.min_zoom(),
                       layer.max_zoom(),
                       layer.data_bounds(),
                       [&layer](int z) { return layer.eps_for_zoom(z); },
                       [&layer](int z) -> const TileCover& { return layer.data_cover_at(z); }};
}

// Whether tile id is made in format f: DEM tiles wherever planned, terrain tiles where
// layer.json lists them, mesh tiles where the layer may have data.
bool makes(const Layer& layer, Format f, const ValidTile& tile) {
    if (is_terrain_format(f)) {
        // Globe terrain is geodetic: a layer of another scheme makes none (nor its tileset).
        return layer.options().scheme == Scheme::Geodetic &&
               terrain_lists(terrain_spec_of(layer), tile.id());
    }
    return is_dem_format(f) || layer.may_have_tile(tile);
}

// Whether every terrain tile of `format` that layer.json and the terrain tileset list as
// available is in the store (a --bbox build leaves some out: a warning names one, and what
// lists them is then not written).
bool terrain_complete(const Layer& layer,
                      TileStore& store,
                      const std::string& name,
                      Format format) {
    const TerrainSpec spec = terrain_spec_of(layer);
    // The first tile of r missing from the store, if any.
    const auto missing = [&](const TileRange& r) -> std::optional<TileId> {
        for (std::int64_t y = r.y0; y <= r.y1; ++y) {
            for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                if (!store.contains(TileKey{name, TileId{r.z, x, y}, format, -1})) {
                    return TileId{r.z, x, y};
                }
            }
        }
        return std::nullopt;
    };
    for (int z = 0; z <= spec.max_zoom; ++z) {
        for (const TileRange& r : terrain_available(spec, z)) {
            if (const std::optional<TileId> id = missing(r)) {
                log::warn(std::string("build: ") +
                          (format == Format::Terrain ? "layer.json" : "terrain/tileset.json") +
                          " not written: it lists " + format_name(format) + " tile " +
                          tile_name(*id) +
                          ", which is not in the store (build it, e.g. with --resume and no "
                          "--bbox)");
                return false;
            }
        }
    }
    return true;
}

// Writes layer.json when every tile it lists is in the store. Returns whether it was.
bool write_layer_json(const Layer& layer,
                      TileStore& store,
                      const std::string& name,
                      unsigned extensions) {
    if (!terrain_complete(layer, store, name, Format::Terrain)) {
        return false;
    }
    const TerrainSpec spec = terrain_spec_of(layer);
    std::string text;
    layer.document("layer.json", text);
    text = layer_json_with_extensions(text, extensions);
    store.put_document(name, "layer.json", text);
    log::info("build: wrote layer.json (quantized-mesh terrain, zooms 0.." +
              std::to_string(spec.max_zoom) + ")");
    return true;
}

// Writes what clients and static hosts need beside the tiles: the raster DEM tiles' TileJSON
// (not for a --bbox build, whose TileJSON would claim tiles it lacks) and, in a directory, the
// host files (tiler/pyramid/hosting.hpp).
void write_static_hosting(const BuildOptions& o,
                          const Layer& layer,
                          TileStore& store,
                          const std::string& name) {
    for (Format f : o.formats) {
        if (is_dem_format(f) && !o.bbox) {
            store.put_document(
                name, dem_tilejson_name(f), static_dem_tilejson(layer, f, o.base_url));
            log::info("build: wrote " + dem_tilejson_name(f) + " (" + format_name(f) +
                      " DEM tiles" +
                      (o.base_url.empty() ? ", tile URLs relative to it; MapLibre needs absolute "
                                            "ones: build with --base-url URL"
                                          : " at " + o.base_url) +
                      ")");
        }
    }
    std::error_code ec;
    if (std::filesystem::is_directory(o.output, ec)) {
        write_host_files(o.output);
        log::info("build: wrote " + o.output + "/terrabound-nginx.conf and " + o.output +
                  "/_headers (static hosting: media types, gzip .terrain, CORS, caching)");
    }
}

// Writes the 3D Tiles terrain documents when every tile they list is in the store: each
// subtree reachable from the two roots, then terrain/tileset.json last. Returns whether it did.
bool write_terrain_tileset(const Layer& layer, TileStore& store, const std::string& name) {
    if (!terrain_complete(layer, store, name, Format::Terrain3d)) {
        return false;
    }
    std::size_t written = 0;
    for (int root = 0; root < 2; ++root) {
        std::vector<std::array<std::int64_t, 3>> todo{{0, 0, 0}};
        while (!todo.empty()) {
            const auto [level, x, y] = todo.back();
            todo.pop_back();
            const std::string path = "terrain/" + std::to_string(root) + "/" +
                                     std::to_string(level) + "/" + std::to_string(x) + "/" +
                                     std::to_string(y) + ".subtree";
            std::string bytes;
            if (!layer.document(path, bytes)) {
                continue;
            }
            store.put_document(name, path, bytes);
            ++written;
            // The child subtrees are those whose root tile is available.
            const int child = static_cast<int>(level) + kTerrainSubtreeLevels;
            const TerrainSpec spec = terrain_spec_of(layer);
            const std::int64_t side = std::int64_t{1} << kTerrainSubtreeLevels;
            const std::int64_t offset = std::int64_t{root} << child;
            for (std::int64_t j = y * side; child <= spec.max_zoom && j < (y + 1) * side; ++j) {
                for (std::int64_t i = x * side; i < (x + 1) * side; ++i) {
                    if (terrain_lists(spec, TileId{child, offset + i, j})) {
                        todo.push_back({child, i, j});
                    }
                }
            }
        }
    }
    std::string text;
    layer.document("terrain/tileset.json", text);
    store.put_document(name, "terrain/tileset.json", text);
    log::info("build: wrote terrain/tileset.json (3D Tiles terrain, zooms 0.." +
              std::to_string(layer.max_zoom()) + ", " + std::to_string(written) + " subtrees)");
    return true;
}

// Mesh tiles first (when a mesh format is asked for), then the DEM pyramid's tiles (when a DEM
// format is).
Plan make_plan(const Layer& layer, const BuildOptions& o) {
    Plan plan;
    const bool mesh =
        std::any_of(o.formats.begin(), o.formats.end(), [](Format f) { return !is_dem_format(f); });
    const bool dem = std::any_of(o.formats.begin(), o.formats.end(), is_dem_format);
    if (mesh) {
        // Terrain tiles start at zoom 0 (filler below min_zoom) and at zoom 0 cover both roots;
        // elsewhere they are the tiles covering the data, as the mesh tiles.
        const bool terrain = wants_terrain(layer, o);
        const TerrainSpec spec = terrain_spec_of(layer);
        add_ranges(
            plan, o, o.layer.scheme, terrain ? 0 : layer.min_zoom(), layer.max_zoom(), [&](int z) {
                return terrain ? bounding(z, terrain_available(spec, z)) : layer.tiles_at(z);
            });
    }
    plan.mesh_total = plan.total;
    if (dem) {
        const DemTilePlan d = dem_tile_plan(layer);
        add_ranges(plan, o, Scheme::Mercator, d.min_zoom, d.max_zoom, [&](int z) {
            return dem_tiles_at(layer, z);
        });
    }
    return plan;
}

// The build manifest: what decides the tiles' bytes (tiler/stores/manifest.hpp), then what
// decides which tiles there are.
Manifest
make_manifest(const BuildOptions& o, const Layer& layer, const Plan& plan, int shard_count) {
    Manifest m;
    m.emplace_back("terrabound_build", "1");
    for (auto& entry : tile_settings(layer)) {
        m.push_back(std::move(entry));
    }
    if (o.bbox) {
        m.emplace_back("bbox",
                       "[" + json_number(o.bbox->west) + ", " + json_number(o.bbox->south) + ", " +
                           json_number(o.bbox->east) + ", " + json_number(o.bbox->north) + "]");
    } else {
        m.emplace_back("bbox", "null");
    }
    std::string formats = "[";
    for (std::size_t i = 0; i < o.formats.size(); ++i) {
        formats += std::string(i ? ", " : "") + json_string(format_name(o.formats[i]));
    }
    m.emplace_back("formats", formats + "]");
    if (std::find(o.formats.begin(), o.formats.end(), Format::Terrain) != o.formats.end()) {
        m.emplace_back("terrain_extensions", terrain_extensions_json(o.terrain_extensions));
    }
    m.emplace_back("shard_count", std::to_string(shard_count));
    // What an update compares (update.hpp).
    m.emplace_back("source_bounds", source_bounds_entry(layer.options().sources));
    m.emplace_back("source_grids", source_grids_entry(layer));
    m.emplace_back("data_bounds", box_entry(layer.data_bounds()));
    m.emplace_back("zooms", zooms_entry(layer, 0, layer.max_zoom()));
    m.emplace_back("grid_origins", grid_origins_entry(layer));
    m.emplace_back("summary_levels", summary_levels_entry(layer));
    m.emplace_back("mesh_ranges", ranges_entry(plan.ranges_of(false)));
    m.emplace_back("dem_ranges", ranges_entry(plan.ranges_of(true)));
    return m;
}

// ---- progress ----

std::string format_seconds(double s) {
    if (!(s >= 0) || s > 1e7) {
        return "?";
    }
    const long long t = static_cast<long long>(s + 0.5);
    if (t < 100) {
        return std::to_string(t) + " s";
    }
    if (t < 6000) {
        return std::to_string(t / 60) + " min " + std::to_string(t % 60) + " s";
    }
    return std::to_string(t / 3600) + " h " + std::to_string(t / 60 % 60) + " min";
}

struct Counters {
    std::atomic<std::int64_t> skipped{0}, empty{0}, failed{0}, made{0};
};

class Progress {
public:
    Progress(ProgressMode mode, std::int64_t planned) : planned_(planned), start_(Clock::now()) {
        mode_ = mode == ProgressMode::Auto
                    ? (::isatty(STDERR_FILENO) ? ProgressMode::Bar : ProgressMode::Lines)
                    : mode;
        last_ = start_;
    }

    void update(std::int64_t done, std::int64_t skipped, bool final) {
        const auto now = Clock::now();
        const double since = std::chrono::duration<double>(now - last_).count();
        if (mode_ == ProgressMode::Off) {
            return;
        }
        const double every = mode_ == ProgressMode::Bar ? kBarEverySeconds : kLogEverySeconds;
        if (!final && since < every) {
            return;
        }
        if (final && mode_ == ProgressMode::Lines) {
            return; // the summary line follows
        }
        last_ = now;
        const double elapsed = std::chrono::duration<double>(now - start_).count();
        // Rate over tiles actually worked on: skipped tiles cost next to nothing.
        const double worked = static_cast<double>(done - skipped);
        const double rate = elapsed > 0 ? worked / elapsed : 0;
        const double left = static_cast<double>(planned_ - done);
        const std::string eta = rate > 0 ? format_seconds(left / rate) : "?";
        const double pct = planned_ > 0
                               ? 100.0 * static_cast<double>(done) / static_cast<double>(planned_)
                               : 100.0;
        char line[200];
        if (mode_ == ProgressMode::Bar) {
            constexpr int kWidth = 30;
            const int filled = static_cast<int>(pct / 100 * kWidth);
            std::string bar(static_cast<std::size_t>(filled), '#');
            bar.resize(kWidth, '.');
            std::snprintf(line,
                          sizeof line,
                          "\r%5.1f%% [%s] %lld/%lld tiles, %.0f tiles/s, eta %s\033[K",
                          pct,
                          bar.c_str(),
                          static_cast<long long>(done),
                          static_cast<long long>(planned_),
                          rate,
                          eta.c_str());
            std::fputs(line, stderr);
            if (final) {
                std::fputc('\n', stderr);
            }
            std::fflush(stderr);
        } else {
            std::snprintf(line,
                          sizeof line,
                          "build %lld/%lld tiles (%.1f%%), %.0f tiles/s, eta %s",
                          static_cast<long long>(done),
                          static_cast<long long>(planned_),
                          pct,
                          rate,
                          eta.c_str());
            log::info(line);
        }
    }

private:
    ProgressMode mode_;
    std::int64_t planned_;
    Clock::time_point start_, last_;
};

// ---- the tileset, written last ----

// "a/b/../c.json" -> "a/c.json"; empty when the path leaves the layer.
std::string normalize(const std::string& dir, const std::string& uri) {
    std::vector<std::string> parts;
    std::istringstream in(dir + uri);
    std::string part;
    while (std::getline(in, part, '/')) {
        if (part.empty() || part == ".") {
            continue;
        }
        if (part == "..") {
            if (parts.empty()) {
                return "";
            }
            parts.pop_back();
        } else {
            parts.push_back(part);
        }
    }
    std::string out;
    for (const auto& p : parts) {
        out += (out.empty() ? "" : "/") + p;
    }
    return out;
}

std::vector<std::string> uris_in(const std::string& json) {
    std::vector<std::string> out;
    constexpr std::string_view kKey = "\"uri\":";
    for (auto at = json.find(kKey); at != std::string::npos; at = json.find(kKey, at + 1)) {
        auto q0 = json.find('"', at + kKey.size());
        auto q1 = q0 == std::string::npos ? q0 : json.find('"', q0 + 1);
        if (q1 != std::string::npos) {
            out.push_back(json.substr(q0 + 1, q1 - q0 - 1));
        }
    }
    return out;
}

bool parse_tile_uri(const std::string& path, TileId& id, Format& format) {
    const auto dot = path.rfind('.');
    if (dot == std::string::npos) {
        return false;
    }
    const auto f = parse_format(std::string_view(path).substr(dot + 1));
    if (!f) {
        return false;
    }
    long long v[3];
    const char* p = path.data();
    const char* end = path.data() + dot;
    for (int k = 0; k < 3; ++k) {
        const auto r = std::from_chars(p, end, v[k]);
        if (r.ec != std::errc() || r.ptr == p || (k < 2 && (r.ptr == end || *r.ptr != '/'))) {
            return false;
        }
        p = r.ptr + (k < 2 ? 1 : 0);
    }
    if (p != end || v[0] < 0 || v[0] > kMaxZoom) {
        return false;
    }
    id = TileId{static_cast<int>(v[0]), v[1], v[2]};
    format = *f;
    return true;
}

// The documents the stored tileset.json of layer `name` reaches through "uri"s (tileset.json
// among them), or none: what an earlier build wrote, for write_tileset to remove those the new
// tileset no longer reaches (a pyramid made deeper or shallower by an update).
std::set<std::string> stored_tileset_documents(const TileStore& store, const std::string& name) {
    std::set<std::string> out;
    std::vector<std::string> todo{"tileset.json"};
    while (!todo.empty()) {
        const std::string path = todo.back();
        todo.pop_back();
        const auto bytes = store.get_document(name, path);
        if (!bytes || !out.insert(path).second) {
            continue;
        }
        const auto slash = path.rfind('/');
        const std::string dir = slash == std::string::npos ? "" : path.substr(0, slash + 1);
        for (const auto& uri : uris_in(*bytes)) {
            const std::string target = normalize(dir, uri);
            TileId id;
            Format format;
            if (!target.empty() && !parse_tile_uri(target, id, format) && !out.count(target)) {
                todo.push_back(target);
            }
        }
    }
    return out;
}

// Collects the layer's documents by following "uri"s from tileset.json, checks that every tile
// they name is in the store, then writes them with tileset.json last. Returns false (and says
// why in the log) when a named tile is missing, writing nothing.
bool write_tileset(const Layer& layer, TileStore& store, const std::string& name, bool bbox) {
    std::vector<std::pair<std::string, std::string>> docs; // path, bytes; tileset.json first
    std::vector<std::string> todo{"tileset.json"};
    std::map<std::string, bool> seen{{"tileset.json", true}};
    std::int64_t tiles = 0;
    while (!todo.empty()) {
        const std::string path = todo.back();
        todo.pop_back();
        std::string bytes;
        if (!layer.document(path, bytes)) {
            throw IoError("layer " + name + ": the tileset refers to document '" + path +
                          "' that the layer does not make; this is a bug, please report it");
        }
        const auto slash = path.rfind('/');
        const std::string dir = slash == std::string::npos ? "" : path.substr(0, slash + 1);
        for (const auto& uri : uris_in(bytes)) {
            const std::string target = normalize(dir, uri);
            TileId id;
            Format format;
            if (parse_tile_uri(target, id, format)) {
                ++tiles;
                if (!store.contains(TileKey{name, id, format, -1})) {
                    const std::string why =
                        bbox ? "it lies outside --bbox; a partial build gets no tileset (serve "
                               "the layer, or build without --bbox)"
                             : "build it with --resume (and --formats " +
                                   std::string(extension(format)) + ")";
                    log::warn("build: tileset.json not written: it lists tile " + target +
                              ", which is not in the store; " + why);
                    return false;
                }
            } else if (!target.empty() && !seen[target]) {
                seen[target] = true;
                todo.push_back(target);
            }
        }
        docs.emplace_back(path, std::move(bytes));
    }
    std::set<std::string> stale = stored_tileset_documents(store, name);
    for (std::size_t i = docs.size(); i-- > 1;) {
        store.put_document(name, docs[i].first, docs[i].second);
    }
    store.put_document(name, docs[0].first, docs[0].second);
    for (const auto& [path, bytes] : docs) {
        stale.erase(path);
    }
    for (const std::string& path : stale) { // unreachable now: nothing lists them
        store.remove_document(name, path);
    }
    log::info("build: wrote " + std::to_string(docs.size()) + " tileset document(s) listing " +
              std::to_string(tiles) + " tiles");
    return true;
}

struct ShardRecord {
    std::int64_t present = 0;
    std::int64_t empty = 0;
    std::int64_t manifest = -1; // checksum of the build manifest the shard ran under
};

// `manifest`: the build manifest's text, so that a shard of an earlier build (before an
// update) does not count as one of this build.
std::string shard_record_text(const ShardSpec& s,
                              std::int64_t present,
                              std::int64_t empty,
                              const std::string& manifest) {
    return "{\"shard\": " + std::to_string(s.index) + ", \"count\": " + std::to_string(s.count) +
           ", \"present\": " + std::to_string(present) + ", \"empty\": " + std::to_string(empty) +
           ", \"manifest\": " + std::to_string(store_checksum(manifest)) + "}\n";
}

std::optional<ShardRecord> parse_shard_record(const std::string& text) {
    auto field = [&](const std::string& key) -> std::optional<std::int64_t> {
        const auto at = text.find("\"" + key + "\": ");
        if (at == std::string::npos) {
            return std::nullopt;
        }
        std::int64_t v = 0;
        const char* p = text.data() + at + key.size() + 4;
        const auto r = std::from_chars(p, text.data() + text.size(), v);
        if (r.ec != std::errc()) {
            return std::nullopt;
        }
        return v;
    };
    const auto present = field("present");
    const auto empty = field("empty");
    const auto manifest = field("manifest");
    if (!present || !empty || !manifest) {
        return std::nullopt;
    }
    return ShardRecord{*present, *empty, *manifest};
}

void check_options(const BuildOptions& o) {
    if (o.output.empty()) {
        throw InputError("build: name the output with -o OUT (a directory, or a file ending in "
                         ".sqlite)");
    }
    if (o.layer.sources.empty()) {
        throw InputError("build: name at least one DEM to build from");
    }
    validate_layer_name(o.layer.name);
    if (o.threads < 0 || o.threads > 1024) {
        throw InputError("build: --threads " + std::to_string(o.threads) +
                         ": expected 1..1024 (or 0 for one per usable core)");
    }
    if (o.formats.empty()) {
        throw InputError(
            "build: --formats: name at least one of glb, drc, terrarium, mapbox, terrain, "
            "terrain3d");
    }
    for (std::size_t i = 0; i < o.formats.size(); ++i) {
        for (std::size_t j = 0; j < i; ++j) {
            if (o.formats[i] == o.formats[j]) {
                throw InputError(std::string("build: --formats names ") +
                                 format_name(o.formats[i]) + " twice");
            }
        }
    }
    if (o.bbox) {
        const auto& b = *o.bbox;
        const bool ok = b.west >= -180 && b.east <= 180 && b.south >= -90 && b.north <= 90 &&
                        b.west < b.east && b.south < b.north;
        if (!ok) {
            throw InputError("build: --bbox " + json_number(b.west) + "," + json_number(b.south) +
                             "," + json_number(b.east) + "," + json_number(b.north) +
                             ": expected W,S,E,N in degrees with -180 <= W < E <= 180 and -90 <= "
                             "S < N <= 90");
        }
    }
    if (o.shard && (o.shard->count < 1 || o.shard->index < 0 || o.shard->index >= o.shard->count)) {
        throw InputError("build: --shard " + std::to_string(o.shard->index) + "/" +
                         std::to_string(o.shard->count) + ": expected I/N with 0 <= I < N");
    }
    if (o.force && (o.resume || o.shard || o.finalize || o.update)) {
        throw InputError("build: --force starts over and cannot go with --resume, --update, "
                         "--shard or --finalize (with shards, clear the output once, then start "
                         "the shards)");
    }
    if (o.update && is_single_file_store(o.output) && !o.output.ends_with(".sqlite") &&
        !o.output.ends_with(".db")) {
        throw InputError("build --update: " + o.output +
                         " is written once and cannot be updated in place; update a directory "
                         "or an .sqlite store and convert it, or rebuild with --force");
    }
    if (o.finalize && o.shard) {
        throw InputError("build: --finalize runs once after all shards; drop --shard");
    }
}

struct Prepared {
    int shard_count = 1;
    Manifest manifest;               // this run's
    std::optional<Manifest> updated; // --update: the manifest of the build it updates
};

// --update: records the build being updated (unless an interrupted update already did), then
// writes this run's manifest. `pending` is that record, when there is one.
Manifest start_update(const BuildOptions& o,
                      TileStore& store,
                      const std::optional<std::string>& existing,
                      const std::optional<std::string>& pending,
                      const Manifest& manifest,
                      const std::string& where) {
    const std::string& name = o.layer.name;
    if (!existing) {
        throw InputError(where + ": nothing to update (no " + std::string(kBuildManifest) +
                         "); build it once without --update");
    }
    const std::string text = manifest_text(manifest);
    if (pending && *existing != text) {
        // The interrupted update wrote tiles for its own DEMs and settings, which the record's
        // comparison with this run's would not see: finish it as it was started first.
        const auto change = first_change(parse_manifest(*existing), manifest);
        throw InputError(
            where + ": an update to other DEMs or settings was interrupted" +
            (change ? " (" + change->key + " was " + change->was + ", now " + change->now + ")"
                    : std::string()) +
            "; finish it first by running that build again with --update, or "
            "rebuild with --force");
    }
    if (!pending && *existing != text) {
        store.put_document(name, kUpdateRecord, *existing); // before any tile changes
    }
    store.put_document(name, kBuildManifest, text);
    return parse_manifest(pending ? *pending : *existing);
}

// Checks the output against this run (--force: clears the layer) and writes the build manifest
// when there is none yet (or, updating, this run's). --finalize learns the shard count from the
// manifest. Runs inside the output lock's setup, so that shards starting together agree on one
// manifest.
Prepared prepare_output(const BuildOptions& o,
                        const Layer& layer,
                        const Plan& plan,
                        TileStore& store,
                        const std::string& where) {
    const std::string& name = o.layer.name;
    const auto existing = store.get_document(name, kBuildManifest);
    const auto pending = store.get_document(name, kUpdateRecord);
    Prepared p;
    p.shard_count = o.shard ? o.shard->count : 1;
    if (o.finalize && existing) {
        // --finalize learns N from the shards' manifest.
        const std::string n = manifest_value(parse_manifest(*existing), "shard_count");
        const auto r = std::from_chars(n.data(), n.data() + n.size(), p.shard_count);
        if (r.ec != std::errc() || p.shard_count < 1) {
            throw IoError(where + ": " + std::string(kBuildManifest) +
                          " has no valid shard_count; "
                          "it was not written by this terrabound; use --force to start over");
        }
    }
    if (pending && !o.update && !o.force && !o.finalize) {
        throw InputError(where + ": an update of it (build --update) was interrupted; finish it "
                                 "by running that build again with --update");
    }
    p.manifest = make_manifest(o, layer, plan, p.shard_count);
    const Manifest& manifest = p.manifest;
    if (o.force) {
        if (store.has_layer(name)) {
            log::info("build: --force: removing layer " + name + " from " + store.describe());
            store.remove_layer(name);
        }
    } else if (o.update && !o.finalize) {
        p.updated = start_update(o, store, existing, pending, manifest, where);
        return p;
    } else if (o.resume || o.shard || o.finalize) {
        if (existing) {
            const Manifest was = parse_manifest(*existing);
            compare_manifests(was, manifest, o.shard || o.finalize, where);
        } else if (store.has_layer(name)) {
            throw InputError(where + ": holds files but no " + std::string(kBuildManifest) +
                             ", so it was not made by terrabound build; use --force to overwrite "
                             "or choose another output");
        } else if (o.finalize) {
            throw InputError(where + ": nothing to finalize (no " + std::string(kBuildManifest) +
                             "); run the shards first");
        }
    } else if (store.has_layer(name)) {
        throw InputError(o.output + " exists (layer " + name +
                         "); use --resume to continue, --update to follow changed DEMs, or "
                         "--force to overwrite");
    }
    if (!existing || o.force) {
        store.put_document(name, kBuildManifest, manifest_text(manifest));
    }
    return p;
}

// An update's tiles in both pyramids (tiler/pyramid/update.hpp).
struct Update {
    UpdateScope scope;
    UpdateTiles mesh, dem;
    bool touches(const TileId& id, bool dem_tile) const {
        return (dem_tile ? dem : mesh).contains(id);
    }
};

std::string changes_text(const std::vector<std::string>& changes) {
    if (changes.empty()) {
        return "no DEM changed";
    }
    std::string out;
    for (std::size_t i = 0; i < changes.size() && i < 3; ++i) {
        out += (i ? ", " : "") + changes[i];
    }
    return changes.size() > 3 ? out + " and " + std::to_string(changes.size() - 3) + " more" : out;
}

std::string zooms_text(const std::vector<int>& zooms) {
    std::string out;
    for (int z : zooms) {
        out += (out.empty() ? "" : ",") + std::to_string(z);
    }
    return out;
}

Update plan_update(const Manifest& was, const Manifest& now, const Layer& layer, const Plan& plan) {
    UpdateScope scope = update_scope(was, now);
    // What a tile reads beyond its edges, in tiles: the void filling's margin (in lattice
    // samples, pixels no coarser than those at pixel zooms; in a DEM tile's pixels), and a
    // quarter of a tile at least.
    const double mesh_around =
        std::max(0.25, (kLatticeFillMargin + 2.0) / layer.options().tile_size);
    const double dem_around =
        std::max(0.25, (kDemFillMargin + 2.0) / dem_tile_plan(layer).tile_size);
    Update u{scope,
             UpdateTiles(scope,
                         layer.options().scheme,
                         parse_ranges(manifest_value(was, "mesh_ranges"), "mesh_ranges"),
                         plan.ranges_of(false),
                         scope.zooms,
                         mesh_around),
             UpdateTiles(scope,
                         Scheme::Mercator,
                         parse_ranges(manifest_value(was, "dem_ranges"), "dem_ranges"),
                         plan.ranges_of(true),
                         {}, // raster DEM tiles have no eps or budget: no zoom changes whole
                         dem_around)};
    if (!scope.everything.empty()) {
        log::warn("build --update: " + scope.everything + "; every tile is made again");
    }
    std::string zooms;
    if (!scope.zooms.empty()) {
        zooms = " (whole zooms: " + zooms_text(scope.zooms) + ")";
    }
    for (std::size_t i = 0; i < scope.why.size() && i < 3; ++i) {
        log::info("build --update: " + scope.why[i] +
                  (i == 2 && scope.why.size() > 3
                       ? " (and " + std::to_string(scope.why.size() - 3) + " more)"
                       : ""));
    }
    log::info("build --update: " + changes_text(scope.changes) + "; remaking " +
              std::to_string(u.mesh.remade() + u.dem.remade()) + " tiles" + zooms + ", removing " +
              std::to_string(u.mesh.left_out_count() + u.dem.left_out_count()) +
              " that no longer hold data");
    return u;
}

// Removes the tiles `tiles` leaves out that `mine` owns, in every format of their pyramid.
// Returns how many tiles it removed.
std::int64_t remove_left_out(TileStore& store,
                             const BuildOptions& o,
                             const UpdateTiles& tiles,
                             bool dem,
                             const std::function<bool(const TileId&)>& mine) {
    std::vector<Format> formats;
    for (Format f : o.formats) {
        if (is_dem_format(f) == dem) {
            formats.push_back(f);
        }
    }
    std::int64_t removed = 0;
    tiles.for_each_left_out([&](const TileId& id) {
        if (mine(id) && !formats.empty()) {
            remove_tile(store, o.layer.name, id, formats);
            ++removed;
        }
    });
    return removed;
}

// Ends an update once its documents are in: the record of the build it updated goes.
void finish_update(TileStore& store, const std::string& name) {
    if (store.get_document(name, kUpdateRecord)) {
        store.remove_document(name, kUpdateRecord);
        log::info("build --update: done; " + store.describe() +
                  " now holds what a full build "
                  "of these DEMs makes");
    }
}

// This run as the lock file shows it to a refused one.
std::string lock_command(const BuildOptions& o) {
    std::string command = "terrabound build";
    if (o.shard) {
        command +=
            " --shard " + std::to_string(o.shard->index) + "/" + std::to_string(o.shard->count);
    } else if (o.force) {
        command += " --force";
    } else if (o.finalize) {
        command += " --finalize";
    } else if (o.update) {
        command += " --update";
    } else if (o.resume) {
        command += " --resume";
    }
    return command + " -o " + o.output;
}

} // namespace

ShardSpec parse_shard(std::string_view text) {
    const auto bad = [&](const std::string& why) {
        return InputError("--shard '" + std::string(text) + "': " + why +
                          "; expected I/N with 0 <= I < N (0-based), or auto/N");
    };
    const auto slash = text.find('/');
    if (slash == std::string_view::npos) {
        throw bad("no '/'");
    }
    auto to_int = [&](std::string_view s, const char* what) {
        int v = 0;
        const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
        if (s.empty() || r.ec != std::errc() || r.ptr != s.data() + s.size()) {
            throw bad(std::string(what) + " '" + std::string(s) + "' is not a whole number");
        }
        return v;
    };
    ShardSpec s;
    s.count = to_int(text.substr(slash + 1), "N");
    const std::string_view first = text.substr(0, slash);
    if (first == "auto") {
        const char* names[] = {"JOB_COMPLETION_INDEX", "SLURM_ARRAY_TASK_ID"};
        const char* value = nullptr;
        for (const char* n : names) {
            if ((value = std::getenv(n)) != nullptr) {
                s.index = to_int(value, n);
                break;
            }
        }
        if (!value) {
            throw bad("neither JOB_COMPLETION_INDEX nor SLURM_ARRAY_TASK_ID is set");
        }
    } else {
        s.index = to_int(first, "I");
    }
    if (s.count < 1 || s.index < 0 || s.index >= s.count) {
        throw bad("shard " + std::to_string(s.index) + " of " + std::to_string(s.count) +
                  " does not exist");
    }
    return s;
}

int shard_of(const TileId& id, int count) {
    // splitmix64 of the packed (z, x, y): stable across machines and releases.
    std::uint64_t h = (static_cast<std::uint64_t>(id.z) << 58) ^
                      (static_cast<std::uint64_t>(id.x) << 29) ^ static_cast<std::uint64_t>(id.y);
    h += 0x9e3779b97f4a7c15ull;
    h = (h ^ (h >> 30)) * 0xbf58476d1ce4e5b9ull;
    h = (h ^ (h >> 27)) * 0x94d049bb133111ebull;
    h ^= h >> 31;
    return static_cast<int>(h % static_cast<std::uint64_t>(count));
}

std::string to_json(const BuildSummary& s) {
    return "{\"planned\":" + std::to_string(s.planned) +
           ",\"written\":" + std::to_string(s.written) +
           ",\"dem_written\":" + std::to_string(s.dem_written) +
           ",\"skipped\":" + std::to_string(s.skipped) + ",\"empty\":" + std::to_string(s.empty) +
           ",\"failed\":" + std::to_string(s.failed) + ",\"removed\":" + std::to_string(s.removed) +
           ",\"bytes\":" + std::to_string(s.bytes) + ",\"seconds\":" + json_number(s.seconds) +
           ",\"interrupted\":" + (s.interrupted ? "true" : "false") +
           ",\"tileset_written\":" + (s.tileset_written ? "true" : "false") +
           ",\"tiles_over_eps\":" + std::to_string(s.over_eps) + "}";
}

// The formats of tile `made`'s pyramid that `made` holds no tile of: an update removes them.
void note_removed(const BuildOptions& o, Made& made) {
    for (Format f : o.formats) {
        const bool has = std::any_of(
            made.tiles.begin(), made.tiles.end(), [f](const auto& t) { return t.first == f; });
        if (is_dem_format(f) == made.dem && !has) {
            made.removed.push_back(f);
        }
    }
}

// What a worker does with tile i of the plan: nothing (already in the store, empty, or failed;
// counted in `counters`), or the tiles for the writer, with an update's removals. An update
// remakes the tiles it touches whether they are in the store or not. IoError when the DEM
// became unreadable.
std::optional<Made> make_planned_tile(const BuildOptions& o,
                                      const Layer& layer,
                                      const TileStore& store,
                                      const Plan& plan,
                                      std::int64_t i,
                                      const std::optional<Update>& update,
                                      bool check_present,
                                      Counters& counters) {
    const ValidTile tile = plan.at(i);
    const TileId& id = tile.id();
    const bool dem = plan.dem(i);
    const bool remake = update && update->touches(id, dem);
    Made made{id, {}, dem, {}};
    if (!dem && !layer.may_have_tile(tile) && !wants_terrain(layer, o)) {
        ++counters.empty;
        if (remake) {
            note_removed(o, made);
            return made;
        }
        return std::nullopt;
    }
    std::vector<Format> formats;
    for (Format f : o.formats) {
        if (is_dem_format(f) == dem && makes(layer, f, tile)) {
            formats.push_back(f);
        }
    }
    if (formats.empty()) {
        // Beside a file of a collection, within the box around them: nothing to make.
        ++counters.empty;
        if (remake) {
            note_removed(o, made);
            return made;
        }
        return std::nullopt;
    }
    if (check_present && !remake && std::all_of(formats.begin(), formats.end(), [&](Format f) {
            return store.contains(TileKey{o.layer.name, id, f, -1});
        })) {
        ++counters.skipped;
        return std::nullopt;
    }
    try {
        if (dem) {
            for (Format f : formats) {
                try {
                    made.tiles.emplace_back(f, make_dem_tile(layer, tile, f));
                } catch (const NotFound&) {
                    // no data for this format here; the others may have some
                }
            }
        } else {
            // Formats without data here are left out; the others share meshes.
            made.tiles = layer.make_tiles(tile, formats);
            keep_terrain_extensions(made, o.terrain_extensions);
        }
    } catch (const IoError&) {
        throw; // the DEM became unreadable: no point going on
    } catch (const std::exception& e) {
        ++counters.failed;
        log::error(std::string("build: ") + (dem ? "DEM tile " : "tile ") + tile_name(id) + ": " +
                   e.what());
        return std::nullopt;
    }
    if (remake) {
        note_removed(o, made);
    }
    if (made.tiles.empty()) {
        ++counters.empty;
        return made.removed.empty() ? std::nullopt : std::optional<Made>(std::move(made));
    }
    return made;
}

// Writes the layer's documents once its tiles are in: the 3D Tiles tileset (mesh formats; a
// build of DEM tiles alone has no mesh tiles for one to list), layer.json, the terrain tileset,
// the static hosting files. Returns whether the tileset was written.
bool write_documents(
    const BuildOptions& o, const Layer& layer, TileStore& store, bool mesh_formats, bool terrain) {
    const std::string& name = o.layer.name;
    store.clean_up(name);
    const bool tileset = mesh_formats && write_tileset(layer, store, name, o.bbox.has_value());
    if (terrain && wants(o, Format::Terrain)) {
        write_layer_json(layer, store, name, o.terrain_extensions);
    }
    if (terrain && wants(o, Format::Terrain3d)) {
        write_terrain_tileset(layer, store, name);
    }
    write_static_hosting(o, layer, store, name);
    return tileset;
}

// --finalize: once every shard has reported under this build's manifest (their tiles are then
// all in: a shard reports last), writes the documents and ends an update.
BuildSummary finalize_shards(const BuildOptions& o,
                             const Layer& layer,
                             TileStore& store,
                             const Prepared& prepared,
                             bool mesh_formats,
                             bool terrain,
                             Clock::time_point start) {
    const std::string& name = o.layer.name;
    const std::string where = o.output + " (layer " + name + ")";
    const int shard_count = prepared.shard_count;
    BuildSummary summary;
    std::int64_t reported = 0;
    for (int i = 0; i < shard_count; ++i) {
        const ShardSpec s{i, shard_count};
        const auto text = store.get_document(name, shard_document(s));
        const auto record = text ? parse_shard_record(*text) : std::nullopt;
        if (!record || record->manifest != store_checksum(manifest_text(prepared.manifest))) {
            throw InputError(where + ": shard " + std::to_string(i) + "/" +
                             std::to_string(shard_count) + " has not finished (no " +
                             shard_document(s) + "); run it again with --shard " +
                             std::to_string(i) + "/" + std::to_string(shard_count) +
                             " --resume, then --finalize");
        }
        reported += record->present;
        summary.skipped += record->present;
        summary.empty += record->empty;
    }
    summary.planned = summary.skipped + summary.empty;
    summary.tileset_written = write_documents(o, layer, store, mesh_formats, terrain);
    if (mesh_formats && !summary.tileset_written) {
        throw IoError(where + ": --finalize: tiles the tileset lists are missing although "
                              "every shard reported (see the warning above); run each shard "
                              "again with --resume");
    }
    finish_update(store, name);
    store.finish();
    log::info("build: finalized " + std::to_string(shard_count) + " shard(s), " +
              std::to_string(reported) + " tiles");
    summary.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    return summary;
}

BuildSummary build_pyramid(const BuildOptions& o, const std::atomic<bool>& stop) {
    const auto start = Clock::now();
    check_options(o);
    // One writer per output (tiler/stores/output_lock.hpp): taken before anything reads or
    // writes the output and held until this returns. Only the shards of one build share it.
    OutputLock output_lock(
        o.output, o.shard ? LockMode::Shared : LockMode::Exclusive, lock_command(o));
    // The workers make tiles side by side, so each meshes its tile on its own thread: --threads
    // N then uses N cores.
    LayerOptions layer_options = o.layer;
    layer_options.mesh_threads = 1;
    const auto layer = Layer::open(layer_options);
    const std::string& name = o.layer.name;
    auto store = TileStore::open(o.output);
    const std::string where = o.output + " (layer " + name + ")";

    const Plan plan = make_plan(*layer, o);
    Prepared prepared;
    output_lock.setup([&] { prepared = prepare_output(o, *layer, plan, *store, where); });
    const std::optional<Update> update =
        prepared.updated
            ? std::optional<Update>(plan_update(*prepared.updated, prepared.manifest, *layer, plan))
            : std::nullopt;
    // The 3D Tiles tileset lists glb (or drc) tiles; terrain tiles have their layer.json.
    const bool mesh_formats = std::any_of(o.formats.begin(), o.formats.end(), [](Format f) {
        return f == Format::Glb || f == Format::Drc;
    });
    const bool terrain = wants_terrain(*layer, o);
    const bool check_present = o.resume || o.shard || o.finalize || o.update;
    BuildSummary summary;

    if (o.finalize) {
        return finalize_shards(o, *layer, *store, prepared, mesh_formats, terrain, start);
    }

    // This run's share of the plan.
    const auto mine = [&](const TileId& id) {
        return !o.shard || shard_of(id, o.shard->count) == o.shard->index;
    };
    if (!o.shard) {
        summary.planned = plan.total;
    } else {
        for (std::int64_t i = 0; i < plan.total; ++i) {
            summary.planned += mine(plan.at(i).id()) ? 1 : 0;
        }
    }
    const int threads = o.threads > 0 ? o.threads : usable_cpus();
    log::info("build: " + std::to_string(summary.planned) + " tiles, zoom " +
              std::to_string(layer->min_zoom()) + ".." + std::to_string(layer->max_zoom()) +
              (terrain ? " (terrain from zoom 0)" : "") + ", " + std::to_string(threads) +
              " thread(s), into " + store->describe() +
              (o.shard ? ", shard " + std::to_string(o.shard->index) + "/" +
                             std::to_string(o.shard->count)
                       : ""));

    Counters counters;
    std::atomic<std::int64_t> next{0};
    std::atomic<bool> abort{false}; // the writer failed: workers stop at once
    Queue queue(static_cast<std::size_t>(threads) * 2);
    std::mutex error_mutex;
    std::exception_ptr worker_error;

    auto work = [&] {
        try {
            for (;;) {
                if (stop.load() || abort.load()) {
                    return;
                }
                const std::int64_t i = next.fetch_add(1);
                if (i >= plan.total) {
                    return;
                }
                if (!mine(plan.at(i).id())) {
                    continue;
                }
                std::optional<Made> made =
                    make_planned_tile(o, *layer, *store, plan, i, update, check_present, counters);
                if (!made) {
                    continue;
                }
                if (!queue.push(std::move(*made))) {
                    return;
                }
            }
        } catch (...) {
            std::lock_guard lock(error_mutex);
            if (!worker_error) {
                worker_error = std::current_exception();
            }
            abort = true;
        }
    };

    std::vector<std::thread> workers;
    std::atomic<int> running{threads};
    for (int t = 0; t < threads; ++t) {
        workers.emplace_back([&] {
            work();
            --running;
        });
    }

    Progress progress(o.progress, summary.planned);
    std::vector<StoredTile> batch;
    auto last_flush = Clock::now();
    std::int64_t batch_tiles = 0;
    std::int64_t batch_dem_tiles = 0;
    std::exception_ptr writer_error;
    auto flush = [&] {
        if (batch.empty()) {
            return;
        }
        std::int64_t bytes = 0;
        for (const auto& t : batch) {
            bytes += static_cast<std::int64_t>(t.bytes.size());
        }
        store->put_batch(batch);
        summary.written += batch_tiles;
        summary.dem_written += batch_dem_tiles;
        batch_dem_tiles = 0;
        summary.bytes += bytes;
        batch.clear();
        batch_tiles = 0;
        last_flush = Clock::now();
    };
    // A made tile joins the batch; an update's removals happen at once (each is atomic).
    const auto take = [&](Made& m) {
        if (!m.removed.empty()) {
            remove_tile(*store, name, m.id, m.removed);
            summary.removed += m.tiles.empty() ? 1 : 0;
        }
        if (m.tiles.empty()) {
            return; // counted as empty by its worker
        }
        for (auto& [f, bytes] : m.tiles) {
            batch.push_back({TileKey{name, m.id, f, -1}, std::move(bytes)});
        }
        ++batch_tiles;
        batch_dem_tiles += m.dem ? 1 : 0;
        ++counters.made;
    };
    try {
        for (;;) {
            auto made = queue.pop(std::chrono::milliseconds(50));
            if (made) {
                take(*made);
            } else if (running.load() == 0) {
                // Workers are gone and nothing came within the wait: the queue is drained
                // (a worker's last push happens before it counts itself out).
                if (!(made = queue.pop(std::chrono::milliseconds(0)))) {
                    break;
                }
                take(*made);
            }
            const double since = std::chrono::duration<double>(Clock::now() - last_flush).count();
            if (batch_tiles >= static_cast<std::int64_t>(kBatchTiles) ||
                (since >= kBatchSeconds && !batch.empty())) {
                flush();
            }
            progress.update(counters.made + counters.skipped + counters.empty + counters.failed,
                            counters.skipped,
                            false);
        }
        flush();
    } catch (...) {
        writer_error = std::current_exception();
        abort = true;
        queue.close();
    }
    for (auto& w : workers) {
        w.join();
    }
    if (writer_error) {
        std::rethrow_exception(writer_error);
    }
    if (worker_error) {
        std::rethrow_exception(worker_error);
    }
    summary.skipped = counters.skipped;
    summary.empty = counters.empty;
    summary.failed = counters.failed;
    const std::int64_t done = summary.written + summary.skipped + summary.empty + summary.failed;
    progress.update(done, summary.skipped, true);
    summary.interrupted = stop.load() && done < summary.planned;

    if (!summary.interrupted && summary.failed == 0) {
        if (update) {
            summary.removed += remove_left_out(*store, o, update->mesh, false, mine);
            summary.removed += remove_left_out(*store, o, update->dem, true, mine);
        }
        if (o.shard) {
            store->put_document(name,
                                shard_document(*o.shard),
                                shard_record_text(*o.shard,
                                                  summary.written + summary.skipped,
                                                  summary.empty,
                                                  manifest_text(prepared.manifest)));
        } else {
            summary.tileset_written = write_documents(o, *layer, *store, mesh_formats, terrain);
            // Every planned tile is in: a tileset left out only for --bbox does not keep the
            // update pending.
            if (summary.tileset_written || !mesh_formats || o.bbox) {
                finish_update(*store, name);
            }
            store->finish();
        }
    }
    summary.over_eps = static_cast<std::int64_t>(layer->tiles_over_eps());
    if (summary.over_eps > 0) {
        log::info("build: " + std::to_string(summary.over_eps) +
                  " tile(s) measured above their zoom's eps at the source's pixels (zooms "
                  "meshed on a lattice coarser than the pixels, sources in another CRS than "
                  "the scheme's, or globe terrain whose quantization exceeds it; counted once "
                  "per format); each publishes its measured bound (its tileset or subtree "
                  "entry, the .drc's eps_m, the quantized-mesh metadata)");
    }
    summary.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    return summary;
}

} // namespace tb::tiler
