// Converting a Terrabound SQLite store into an MBTiles or PMTiles container (see convert.hpp).
// The store is read through its own tables (tiles, documents, meta; tiler/stores/
// store_sqlite.cpp) on a read-only connection, so converting never migrates, creates or
// switches the journal of the input; the container is written by the containers' own code
// (MbtilesStore, pmtiles::write_archive), so its metadata is what a build writes.
#include "tiler/pyramid/convert.hpp"

#include "core/error.hpp"
#include "tiler/json_number.hpp"
#include "tiler/log.hpp"
#include "tiler/pyramid/hosting.hpp"
#include "tiler/stores/atomic_file.hpp"
#include "tiler/stores/checksum.hpp"
#include "tiler/stores/manifest.hpp"
#include "tiler/stores/output_lock.hpp"
#include "tiler/stores/pmtiles_format.hpp"
#include "tiler/stores/sqlite_db.hpp"
#include "tiler/stores/store_mbtiles.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <tuple>
#include <vector>

namespace tb::tiler {
namespace {

using Clock = std::chrono::steady_clock;

constexpr std::size_t kBatchTiles = 256; // tiles per MBTiles transaction
constexpr double kLogEverySeconds = 5.0; // progress lines

// Thrown from the copy loops when the stop flag is seen; caught in convert_store.
struct Interrupted {};

bool ends_with(const std::string& s, std::string_view suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::string key_text(const std::string& layer, Format format, const TileId& id) {
    return "tile " + layer + "/" + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
           std::to_string(id.y) + ".png (" + format_name(format) + ")";
}

// What a store holds: layer -> format name -> tiles (every eps level counted).
using Holdings = std::map<std::string, std::map<std::string, std::int64_t>>;

// "glb 120, terrarium 85"
std::string describe_formats(const std::map<std::string, std::int64_t>& formats) {
    std::string text;
    for (const auto& [format, count] : formats) {
        text += std::string(text.empty() ? "" : ", ") + format + " " + std::to_string(count);
    }
    return text;
}

// "layer a (glb 120, terrarium 85), layer b (mapbox 12)"
std::string describe(const Holdings& held) {
    std::string text;
    for (const auto& [layer, formats] : held) {
        text += std::string(text.empty() ? "" : ", ") + "layer " + layer + " (" +
                describe_formats(formats) + ")";
    }
    return text.empty() ? "no tiles" : text;
}

// The store's tables and schema version checked, and what it holds. InputError when it is not
// a Terrabound store this terrabound converts.
Holdings inspect(const SqliteDb& db) {
    const std::string& path = db.path();
    const std::string not_store = path + ": not a Terrabound store (an SQLite file that "
                                         "terrabound build -o OUT.sqlite or serve wrote)";
    std::int64_t tables = 0;
    try {
        auto s = db.prepare("SELECT COUNT(*) FROM sqlite_master WHERE type='table' AND name IN"
                            " ('meta', 'tiles', 'documents')");
        db.step(s.get(), "read the tables");
        tables = sqlite3_column_int64(s.get(), 0);
    } catch (const IoError& e) {
        throw InputError(not_store + ": " + e.what());
    }
    if (tables != 3) {
        throw InputError(not_store + ": it has no meta, tiles and documents tables; build "
                                     "converts such a store, and reads anything else as a DEM "
                                     "only when its name does not end in .sqlite or .db");
    }
    auto version = db.prepare("SELECT value FROM meta WHERE name='schema_version'");
    const bool has_version = db.step(version.get(), "read the schema version") == SQLITE_ROW;
    const std::string v = has_version ? SqliteDb::column_bytes(version.get(), 0) : "";
    if (v == "1") {
        throw InputError(path + ": store schema version 1 keeps no checksums to check the tiles "
                                "against; open it once with this terrabound (serve, or build "
                                "--resume), which migrates it to version 2, then convert it");
    }
    if (v != "2") {
        throw InputError(not_store + ": its schema version is '" + v +
                         "', this terrabound reads version 2");
    }
    Holdings held;
    auto s = db.prepare(
        "SELECT layer, format, COUNT(*) FROM tiles GROUP BY layer, format ORDER BY layer, format");
    while (db.step(s.get(), "list the tiles") == SQLITE_ROW) {
        held[SqliteDb::column_bytes(s.get(), 0)][SqliteDb::column_bytes(s.get(), 1)] =
            sqlite3_column_int64(s.get(), 2);
    }
    return held;
}

struct Choice {
    std::string layer;
    Format format = Format::Terrarium;
    std::int64_t tiles = 0;
};

// The layer and encoding to convert: as asked, or the only ones there. InputError listing what
// the store holds when the asked-for ones are not there or the choice is not clear.
Choice choose(const Holdings& held, const ConvertOptions& o) {
    const std::string where = o.input + " holds " + describe(held);
    const auto dem_formats = [](const std::map<std::string, std::int64_t>& formats) {
        std::vector<Format> out;
        for (const auto& [name, count] : formats) {
            if (const auto f = parse_format(name); f && is_dem_format(*f) && count > 0) {
                out.push_back(*f);
            }
        }
        return out;
    };
    Choice c;
    if (!o.layer.empty()) {
        if (!held.count(o.layer)) {
            throw InputError(where + ", no layer " + o.layer + "; name one of those with --layer");
        }
        c.layer = o.layer;
    } else {
        std::vector<std::string> with_dem;
        for (const auto& [layer, formats] : held) {
            if (!dem_formats(formats).empty()) {
                with_dem.push_back(layer);
            }
        }
        if (with_dem.size() != 1) {
            throw InputError(where + (with_dem.empty() ? ": no raster DEM tiles (terrarium or "
                                                         "mapbox), which is all an MBTiles or "
                                                         "PMTiles file holds; build the container "
                                                         "from the DEM instead"
                                                       : ": choose a layer with --layer"));
        }
        c.layer = with_dem[0];
    }
    const std::vector<Format> formats = dem_formats(held.at(c.layer));
    const std::string in_layer =
        o.input + " layer " + c.layer + " holds " + describe_formats(held.at(c.layer));
    if (o.format) {
        if (std::find(formats.begin(), formats.end(), *o.format) == formats.end()) {
            throw InputError(in_layer + ", no " + format_name(*o.format) + " DEM tiles" +
                             (formats.empty()
                                  ? std::string()
                                  : "; convert --formats " + std::string(format_name(formats[0]))));
        }
        c.format = *o.format;
    } else if (formats.size() != 1) {
        throw InputError(in_layer + (formats.empty() ? ": no raster DEM tiles (terrarium or "
                                                       "mapbox) to put in a container"
                                                     : ": choose one encoding with --formats "
                                                       "terrarium or --formats mapbox"));
    } else {
        c.format = formats[0];
    }
    c.tiles = held.at(c.layer).at(format_name(c.format));
    return c;
}

// A document of the store, checked against its checksum; nullopt when absent. IoError when
// damaged.
std::optional<std::string>
read_document(const SqliteDb& db, const std::string& layer, const std::string& name) {
    auto s = db.prepare("SELECT data, crc FROM documents WHERE layer=?1 AND name=?2");
    SqliteDb::bind_text(s.get(), 1, layer);
    SqliteDb::bind_text(s.get(), 2, name);
    if (db.step(s.get(), "read a document") != SQLITE_ROW) {
        return std::nullopt;
    }
    std::string bytes = SqliteDb::column_bytes(s.get(), 0);
    if (sqlite3_column_type(s.get(), 1) != SQLITE_INTEGER ||
        sqlite3_column_int64(s.get(), 1) != store_checksum(bytes)) {
        throw IoError(db.path() + ": document " + layer + "/" + name +
                      " is damaged (it does not match its checksum); nothing was converted; make "
                      "it again with terrabound build DEM -o " +
                      db.path() + " --resume, then convert");
    }
    return bytes;
}

// What the container carries beside its tiles: the build manifest as a build of this encoding
// alone writes it, and the encoding's TileJSON. InputError when the layer's build did not make
// these tiles or has not finished (so the container would miss tiles).
std::map<std::string, std::string>
container_documents(const SqliteDb& db, const std::string& input, const Choice& c) {
    const std::string format = format_name(c.format);
    const auto text = read_document(db, c.layer, kBuildManifest);
    if (!text) {
        throw InputError(input + ": layer " + c.layer + " has no " + kBuildManifest +
                         ": its tiles were cached by terrabound serve, not built, and may not be "
                         "the whole pyramid; build the container from the DEM instead "
                         "(terrabound build DEM -o OUT.pmtiles --formats " +
                         format + ")");
    }
    if (read_document(db, c.layer, kUpdateRecord)) {
        throw InputError(input + ": an update of layer " + c.layer +
                         " (terrabound build --update) has not finished, so its tiles are part "
                         "old, part new; finish it by running that build again with --update, "
                         "then convert");
    }
    Manifest manifest = parse_manifest(*text);
    if (manifest_value(manifest, "formats").find(json_string(format)) == std::string::npos) {
        throw InputError(input + ": layer " + c.layer + " was built without " + format +
                         " (formats " + manifest_value(manifest, "formats") + "): its " + format +
                         " tiles were cached by terrabound serve; build the container from the "
                         "DEM instead (terrabound build DEM -o OUT.pmtiles --formats " +
                         format + ")");
    }
    std::map<std::string, std::string> docs;
    const std::string tilejson = dem_tilejson_name(c.format);
    if (const auto t = read_document(db, c.layer, tilejson)) {
        docs[tilejson] = *t;
    } else if (manifest_value(manifest, "bbox") == "null") {
        throw InputError(input + ": the build of layer " + c.layer + " has not finished (no " +
                         tilejson +
                         ", which a build writes last); finish it with terrabound build DEM -o " +
                         input + " --resume (or --finalize after shards), then convert");
    }
    // As a build of this encoding alone records it: one format, no terrain extensions, no
    // shards, no mesh tiles; everything that decides the tiles' bytes as it was.
    Manifest alone;
    for (auto& [key, value] : manifest) {
        if (key == "formats") {
            value = "[" + json_string(format) + "]";
        } else if (key == "mesh_ranges") {
            value = "[]";
        } else if (key == "shard_count") {
            value = "1";
        } else if (key == "terrain_extensions") {
            continue;
        }
        alone.emplace_back(key, value);
    }
    docs[kBuildManifest] = manifest_text(alone);
    return docs;
}

// Calls fn(id, bytes) for every tile of the choice, in (z, x, y) order, each checked against
// its checksum and the EPSG:3857 XYZ grid. IoError when one is damaged.
void for_each_tile(const SqliteDb& db,
                   const Choice& c,
                   const std::function<void(const TileId&, const std::string&)>& fn) {
    auto s = db.prepare("SELECT z, x, y, data, crc FROM tiles WHERE layer=?1 AND format=?2"
                        " AND eps_level=-1 ORDER BY z, x, y");
    SqliteDb::bind_text(s.get(), 1, c.layer);
    SqliteDb::bind_text(s.get(), 2, format_name(c.format));
    while (db.step(s.get(), "read the tiles") == SQLITE_ROW) {
        const int z = sqlite3_column_int(s.get(), 0);
        const TileId id{z, sqlite3_column_int64(s.get(), 1), sqlite3_column_int64(s.get(), 2)};
        const std::int64_t n = std::int64_t{1} << std::clamp(z, 0, kMaxZoom);
        if (z < 0 || z > kMaxZoom || id.x < 0 || id.y < 0 || id.x >= n || id.y >= n) {
            throw InputError(db.path() + ": " + key_text(c.layer, c.format, id) +
                             " lies outside EPSG:3857 XYZ, where every DEM tile Terrabound "
                             "makes lies; the store was not written by terrabound");
        }
        const std::string bytes = SqliteDb::column_bytes(s.get(), 3);
        if (sqlite3_column_type(s.get(), 4) != SQLITE_INTEGER ||
            sqlite3_column_int64(s.get(), 4) != store_checksum(bytes)) {
            throw IoError(db.path() + ": " + key_text(c.layer, c.format, id) + " is damaged (" +
                          std::to_string(bytes.size()) +
                          " bytes that do not match their checksum); nothing was converted; "
                          "make it again with terrabound build DEM -o " +
                          db.path() + " --resume (which re-makes damaged tiles), then convert");
        }
        fn(id, bytes);
    }
}

// A log line every few seconds: "build: converting, 1234/5000 tiles read (24.7%)".
class Progress {
public:
    Progress(std::int64_t total, std::string what) : total_(total), what_(std::move(what)) {}
    void step(const std::atomic<bool>& stop) {
        if (stop.load()) {
            throw Interrupted{};
        }
        ++done_;
        const auto now = Clock::now();
        if (std::chrono::duration<double>(now - last_).count() < kLogEverySeconds) {
            return;
        }
        last_ = now;
        char line[160];
        std::snprintf(line,
                      sizeof line,
                      "build: converting, %lld/%lld tiles %s (%.1f%%)",
                      static_cast<long long>(done_),
                      static_cast<long long>(total_),
                      what_.c_str(),
                      total_ > 0 ? 100.0 * static_cast<double>(done_) / total_ : 100.0);
        log::info(line);
    }

private:
    std::int64_t total_, done_ = 0;
    std::string what_;
    Clock::time_point last_ = Clock::now();
};

void remove_sqlite_files(const std::string& path) {
    for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
        std::error_code ec;
        std::filesystem::remove(path + suffix, ec);
    }
}

// Flushes the finished file to disk before it is renamed into place.
void sync_file(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    const bool ok = fd >= 0 && ::fsync(fd) == 0;
    if (fd >= 0) {
        ::close(fd);
    }
    if (!ok) {
        throw IoError(path + ": cannot flush it to disk; check the disk and convert again");
    }
}

// The MBTiles file, written to OUT.converting and renamed into place once finished.
void write_mbtiles(const SqliteDb& db,
                   const Choice& c,
                   const std::map<std::string, std::string>& docs,
                   const std::string& out,
                   const std::atomic<bool>& stop,
                   ConvertSummary& summary) {
    const std::string temp = out + ".converting";
    remove_sqlite_files(temp); // a killed conversion's, under the same output lock
    try {
        {
            MbtilesStore store(temp, out);
            store.put_document(c.layer, kBuildManifest, docs.at(kBuildManifest));
            std::vector<StoredTile> batch;
            Progress progress(c.tiles, "copied");
            for_each_tile(db, c, [&](const TileId& id, const std::string& bytes) {
                progress.step(stop);
                batch.push_back({TileKey{c.layer, id, c.format, -1}, bytes});
                ++summary.tiles;
                summary.bytes += static_cast<std::int64_t>(bytes.size());
                if (batch.size() >= kBatchTiles) {
                    store.put_batch(batch);
                    batch.clear();
                }
            });
            store.put_batch(batch);
            for (const auto& [name, bytes] : docs) {
                if (name != kBuildManifest) {
                    store.put_document(c.layer, name, bytes);
                }
            }
            store.finish();
        }
        sync_file(temp);
        remove_sqlite_files(out + "-wal"); // an old file's journals would apply to the new one
        remove_sqlite_files(out + "-shm");
        remove_sqlite_files(out + "-journal");
        move_into_place(temp, out);
    } catch (...) {
        remove_sqlite_files(temp);
        throw;
    }
}

// The PMTiles archive: every tile read and hashed, then the archive written by
// pmtiles::write_archive (temporary file, fsync, rename), reading each distinct tile again.
void write_pmtiles(const SqliteDb& db,
                   const Choice& c,
                   const std::map<std::string, std::string>& docs,
                   const std::string& out,
                   const std::atomic<bool>& stop,
                   ConvertSummary& summary) {
    std::vector<pmtiles::PlannedTile> tiles;
    Progress progress(c.tiles, "read");
    for_each_tile(db, c, [&](const TileId& id, const std::string& bytes) {
        progress.step(stop);
        pmtiles::PlannedTile t;
        t.id = id;
        t.tile_id = pmtiles::tile_id(id);
        pmtiles::hash_tile(bytes, t);
        tiles.push_back(t);
        ++summary.tiles;
        summary.bytes += static_cast<std::int64_t>(bytes.size());
    });
    std::set<std::tuple<std::uint32_t, std::uint64_t, std::uint64_t>> contents;
    for (const auto& t : tiles) {
        contents.emplace(t.length, t.hash_a, t.hash_b);
    }
    Progress written(static_cast<std::int64_t>(contents.size()), "written (distinct contents)");
    auto one = db.prepare("SELECT data, crc FROM tiles WHERE layer=?1 AND format=?2"
                          " AND eps_level=-1 AND z=?3 AND x=?4 AND y=?5");
    const pmtiles::ArchiveContent content{c.layer, format_name(c.format), docs};
    pmtiles::write_archive(out, std::move(tiles), content, [&](const TileId& id) {
        written.step(stop);
        SqliteReset reset{one.get()};
        SqliteDb::bind_text(one.get(), 1, c.layer);
        SqliteDb::bind_text(one.get(), 2, format_name(c.format));
        sqlite3_bind_int(one.get(), 3, id.z);
        sqlite3_bind_int64(one.get(), 4, id.x);
        sqlite3_bind_int64(one.get(), 5, id.y);
        // Read in the same transaction as the first pass, so it is there and hashes as planned
        // (write_archive checks).
        db.step(one.get(), "read a tile");
        return SqliteDb::column_bytes(one.get(), 0);
    });
    remove_sqlite_files(out + ".staging"); // an unfinished build's, replaced (--force)
}

// Refuses an existing output (or a PMTiles build's staging file) without --force.
void check_output(const ConvertOptions& o) {
    const bool pmtiles = ends_with(o.output, ".pmtiles");
    if (!pmtiles && !ends_with(o.output, ".mbtiles")) {
        throw InputError("build: converting " + o.input +
                         " writes an MBTiles or PMTiles file; name it -o OUT.mbtiles or -o "
                         "OUT.pmtiles");
    }
    if (o.force) {
        return;
    }
    std::error_code ec;
    if (std::filesystem::exists(std::filesystem::symlink_status(o.output, ec))) {
        throw InputError(o.output + " exists; use --force to replace it with the conversion of " +
                         o.input);
    }
    const std::string staging = o.output + ".staging";
    if (pmtiles && std::filesystem::exists(std::filesystem::symlink_status(staging, ec))) {
        throw InputError(staging + " exists (an unfinished build of " + o.output +
                         "); use --force to replace it with the conversion of " + o.input);
    }
}

} // namespace

bool is_store_input(const std::string& path) {
    return ends_with(path, ".sqlite") || ends_with(path, ".db");
}

ConvertSummary convert_store(const ConvertOptions& o, const std::atomic<bool>& stop) {
    const auto start = Clock::now();
    if (o.format && !is_dem_format(*o.format)) {
        throw InputError(std::string("build: --formats ") + format_name(*o.format) +
                         ": an MBTiles or PMTiles file holds raster DEM tiles only; convert "
                         "--formats terrarium or mapbox");
    }
    check_output(o);
    std::error_code ec;
    if (!std::filesystem::is_regular_file(o.input, ec)) {
        throw InputError(o.input + ": no such file; name a Terrabound SQLite store to convert");
    }
    OutputLock lock(
        o.output, LockMode::Exclusive, "terrabound build " + o.input + " -o " + o.output);
    check_output(o); // again under the lock: a build may have made it meanwhile
    const SqliteDb db(o.input, SqliteReadOnly{});
    db.exec("BEGIN", "start a read transaction"); // one snapshot for every read below
    const Choice c = choose(inspect(db), o);
    const auto docs = container_documents(db, o.input, c);
    log::info("build: converting " + std::to_string(c.tiles) + " " + format_name(c.format) +
              " DEM tiles of layer " + c.layer + " from " + o.input + " into " + o.output);
    ConvertSummary summary{c.layer, c.format, 0, 0, 0, false};
    try {
        if (ends_with(o.output, ".mbtiles")) {
            write_mbtiles(db, c, docs, o.output, stop, summary);
        } else {
            write_pmtiles(db, c, docs, o.output, stop, summary);
        }
    } catch (const Interrupted&) {
        summary.interrupted = true;
        summary.tiles = 0;
        summary.bytes = 0;
    }
    summary.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    return summary;
}

} // namespace tb::tiler
