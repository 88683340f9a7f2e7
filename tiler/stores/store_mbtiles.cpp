// The MBTiles 1.3 store (see store_mbtiles.hpp for the tables).
#include "tiler/stores/store_mbtiles.hpp"

#include "core/error.hpp"
#include "tiler/json_number.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/checksum.hpp"

#include <algorithm>

namespace tb::tiler {
namespace {

// MBTiles 1.3: "MPBX" in the SQLite header's application_id.
constexpr const char* kApplicationId = "1297105496";

std::int64_t rows_at(int z) {
    return std::int64_t{1} << z;
}

std::string tile_text(const TileId& id) {
    return std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
}

// Binds ?1, ?2, ?3 to the zoom, column and TMS row of the XYZ tile `id`.
void bind_position(sqlite3_stmt* s, const TileId& id) {
    sqlite3_bind_int(s, 1, id.z);
    sqlite3_bind_int64(s, 2, id.x);
    sqlite3_bind_int64(s, 3, rows_at(id.z) - 1 - id.y);
}

// A tile row joined with its checksum: data, then crc (NULL for a tile another program wrote).
constexpr const char* kTileWithCrc =
    "SELECT t.zoom_level, t.tile_column, t.tile_row, t.tile_data, c.crc FROM tiles t"
    " LEFT JOIN terrabound_tile_crc c ON c.zoom_level=t.zoom_level AND"
    " c.tile_column=t.tile_column AND c.tile_row=t.tile_row";

// Whether column 3's data of a kTileWithCrc row matches its checksum (column 4), or has none.
bool intact(sqlite3_stmt* s, const std::string& data) {
    return sqlite3_column_type(s, 4) == SQLITE_NULL ||
           sqlite3_column_int64(s, 4) == store_checksum(data);
}

} // namespace

MbtilesStore::MbtilesStore(std::string path, std::string shown_as, std::string kind)
    : shown_as_(shown_as.empty() ? path : std::move(shown_as)), kind_(std::move(kind)),
      db_(std::move(path), true) {
    create_tables();
    get_ = db_.prepare((std::string(kTileWithCrc) +
                        " WHERE t.zoom_level=?1 AND t.tile_column=?2 AND t.tile_row=?3")
                           .c_str());
    put_ = db_.prepare("INSERT OR REPLACE INTO tiles(zoom_level, tile_column, tile_row, tile_data)"
                       " VALUES(?1, ?2, ?3, ?4)");
    put_crc_ = db_.prepare("INSERT OR REPLACE INTO terrabound_tile_crc(zoom_level, tile_column,"
                           " tile_row, crc) VALUES(?1, ?2, ?3, ?4)");
    get_doc_ = db_.prepare("SELECT data FROM terrabound_documents WHERE layer=?1 AND name=?2");
    put_doc_ = db_.prepare(
        "INSERT OR REPLACE INTO terrabound_documents(layer, name, data) VALUES(?1, ?2, ?3)");
    set_meta_ = db_.prepare("INSERT OR REPLACE INTO metadata(name, value) VALUES(?1, ?2)");
    load_identity();
}

void MbtilesStore::create_tables() {
    db_.transaction("create the MBTiles tables", [&] {
        db_.exec(std::string("PRAGMA application_id=") + kApplicationId +
                     ";"
                     "CREATE TABLE IF NOT EXISTS metadata(name TEXT NOT NULL, value TEXT);"
                     "CREATE UNIQUE INDEX IF NOT EXISTS metadata_name ON metadata(name);"
                     "CREATE TABLE IF NOT EXISTS tiles(zoom_level INTEGER NOT NULL,"
                     " tile_column INTEGER NOT NULL, tile_row INTEGER NOT NULL,"
                     " tile_data BLOB NOT NULL);"
                     "CREATE UNIQUE INDEX IF NOT EXISTS tile_index ON tiles(zoom_level,"
                     " tile_column, tile_row);"
                     "CREATE TABLE IF NOT EXISTS terrabound_documents(layer TEXT NOT NULL,"
                     " name TEXT NOT NULL, data BLOB NOT NULL, PRIMARY KEY(layer, name));"
                     "CREATE TABLE IF NOT EXISTS terrabound_tile_crc(zoom_level INTEGER NOT NULL,"
                     " tile_column INTEGER NOT NULL, tile_row INTEGER NOT NULL,"
                     " crc INTEGER NOT NULL, PRIMARY KEY(zoom_level, tile_column, tile_row))"
                     " WITHOUT ROWID;",
                 "create the MBTiles tables");
    });
}

// The held layer is the metadata's name, the encoding its `encoding` (a file another program
// wrote may have neither: nothing of it is then found).
void MbtilesStore::load_identity() {
    auto s = db_.prepare("SELECT name, value FROM metadata WHERE name IN ('name', 'encoding')");
    while (db_.step(s.get(), "read the metadata") == SQLITE_ROW) {
        const std::string key = SqliteDb::column_bytes(s.get(), 0);
        const std::string value = SqliteDb::column_bytes(s.get(), 1);
        if (key == "name") {
            layer_ = value;
        } else if (const auto f = parse_format(value); f && is_dem_format(*f)) {
            format_ = f;
        }
    }
}

void MbtilesStore::check_key(const TileKey& key) const {
    validate_key(key);
    if (!is_dem_format(key.format)) {
        throw InputError(shown_as_ + ": a " + kind_ +
                         " file holds raster DEM tiles (terrarium or mapbox) only, not " +
                         format_name(key.format) +
                         "; build those into a directory or an .sqlite file");
    }
    if (key.id.x >= rows_at(key.id.z) || key.id.y >= rows_at(key.id.z)) {
        throw InputError(shown_as_ + ": tile " + tile_text(key.id) +
                         " is outside EPSG:3857 XYZ (x and y below 2^z), the only scheme a " +
                         kind_ + " file holds");
    }
}

bool MbtilesStore::keeps(const TileKey& key) const {
    std::lock_guard lock(mutex_);
    return is_dem_format(key.format) && key.eps_level < 0 && key.id.x < rows_at(key.id.z) &&
           key.id.y < rows_at(key.id.z) && (layer_.empty() || key.layer == layer_) &&
           (!format_ || *format_ == key.format);
}

// Makes `layer` (and `format`, when given) what the file holds, or refuses a second one.
void MbtilesStore::claim(const std::string& layer, std::optional<Format> format) {
    if (layer_.empty()) {
        set_metadata("name", layer);
        layer_ = layer;
    } else if (layer_ != layer) {
        throw InputError(shown_as_ + " holds layer '" + layer_ + "'; a " + kind_ +
                         " file holds one layer, so write layer '" + layer +
                         "' into another file (or delete this one)");
    }
    if (!format || format_ == format) {
        return;
    }
    if (format_) {
        throw InputError(shown_as_ + " holds " + format_name(*format_) + " DEM tiles; a " + kind_ +
                         " file holds one encoding, so write " + format_name(*format) +
                         " into another file");
    }
    set_metadata("format", "png");
    set_metadata("type", "baselayer");
    set_metadata("encoding", format_name(*format));
    set_metadata("description",
                 std::string("Raster DEM tiles of layer ") + layer + " (" + format_name(*format) +
                     " encoding, heights in metres) made by Terrabound");
    format_ = format;
}

void MbtilesStore::set_metadata(const std::string& name, const std::string& value) {
    SqliteReset reset{set_meta_.get()};
    SqliteDb::bind_text(set_meta_.get(), 1, name);
    SqliteDb::bind_text(set_meta_.get(), 2, value);
    db_.step(set_meta_.get(), "write the metadata");
}

std::optional<std::string> MbtilesStore::get(const TileKey& key) const {
    validate_key(key);
    std::lock_guard lock(mutex_);
    const bool held = key.layer == layer_ && format_ == key.format &&
                      key.id.x < rows_at(key.id.z) && key.id.y < rows_at(key.id.z);
    if (!held) {
        return std::nullopt;
    }
    SqliteReset reset{get_.get()};
    bind_position(get_.get(), key.id);
    if (db_.step(get_.get(), "read a tile") != SQLITE_ROW) {
        return std::nullopt;
    }
    std::string data = SqliteDb::column_bytes(get_.get(), 3);
    if (!intact(get_.get(), data)) {
        log::warn(shown_as_ + ": tile " + tile_text(key.id) + " is damaged (" +
                  std::to_string(data.size()) +
                  " bytes that do not match their checksum); not served, it is made again");
        return std::nullopt;
    }
    return data;
}

void MbtilesStore::put_locked(const TileKey& key, std::string_view bytes) {
    claim(key.layer, key.format);
    SqliteReset reset{put_.get()};
    bind_position(put_.get(), key.id);
    SqliteDb::bind_blob(put_.get(), 4, bytes);
    db_.step(put_.get(), "write a tile");
    SqliteReset reset_crc{put_crc_.get()};
    bind_position(put_crc_.get(), key.id);
    sqlite3_bind_int64(put_crc_.get(), 4, store_checksum(bytes));
    db_.step(put_crc_.get(), "write a tile's checksum");
}

void MbtilesStore::put(const TileKey& key, std::string_view bytes) {
    const StoredTile tile{key, std::string(bytes)};
    put_batch(std::span<const StoredTile>(&tile, 1));
}

void MbtilesStore::put_batch(std::span<const StoredTile> tiles) {
    for (const auto& t : tiles) {
        check_key(t.key);
    }
    std::lock_guard lock(mutex_);
    const std::string layer = layer_;
    const auto format = format_;
    try {
        db_.transaction("write tiles", [&] {
            for (const auto& t : tiles) {
                put_locked(t.key, t.bytes);
            }
        });
    } catch (...) {
        layer_ = layer; // the claim was rolled back with the rest
        format_ = format;
        throw;
    }
}

std::optional<std::string> MbtilesStore::get_document(const std::string& layer,
                                                      const std::string& name) const {
    validate_layer_name(layer);
    validate_document_name(name);
    std::lock_guard lock(mutex_);
    SqliteReset reset{get_doc_.get()};
    SqliteDb::bind_text(get_doc_.get(), 1, layer);
    SqliteDb::bind_text(get_doc_.get(), 2, name);
    if (db_.step(get_doc_.get(), "read a document") != SQLITE_ROW) {
        return std::nullopt;
    }
    return SqliteDb::column_bytes(get_doc_.get(), 0);
}

void MbtilesStore::put_document(const std::string& layer,
                                const std::string& name,
                                std::string_view bytes) {
    validate_layer_name(layer);
    validate_document_name(name);
    std::lock_guard lock(mutex_);
    const std::string held = layer_;
    try {
        db_.transaction("write a document", [&] {
            claim(layer, std::nullopt);
            SqliteReset reset{put_doc_.get()};
            SqliteDb::bind_text(put_doc_.get(), 1, layer);
            SqliteDb::bind_text(put_doc_.get(), 2, name);
            SqliteDb::bind_blob(put_doc_.get(), 3, bytes);
            db_.step(put_doc_.get(), "write a document");
        });
    } catch (...) {
        layer_ = held;
        throw;
    }
}

bool MbtilesStore::has_layer(const std::string& layer) const {
    validate_layer_name(layer);
    std::lock_guard lock(mutex_);
    if (layer != layer_) {
        return false;
    }
    auto s = db_.prepare("SELECT EXISTS(SELECT 1 FROM tiles) OR EXISTS(SELECT 1 FROM "
                         "terrabound_documents)");
    db_.step(s.get(), "look up a layer");
    return sqlite3_column_int(s.get(), 0) != 0;
}

void MbtilesStore::remove_layer(const std::string& layer) {
    validate_layer_name(layer);
    std::lock_guard lock(mutex_);
    if (layer != layer_) {
        return;
    }
    db_.transaction("remove a layer", [&] {
        db_.exec("DELETE FROM tiles; DELETE FROM terrabound_tile_crc;"
                 " DELETE FROM terrabound_documents; DELETE FROM metadata;",
                 "remove a layer");
    });
    layer_.clear();
    format_.reset();
}

std::string MbtilesStore::layer() const {
    std::lock_guard lock(mutex_);
    return layer_;
}

std::optional<Format> MbtilesStore::format() const {
    std::lock_guard lock(mutex_);
    return format_;
}

void MbtilesStore::for_each_tile(
    const std::function<void(const TileId&, const std::string&)>& fn) const {
    std::lock_guard lock(mutex_);
    auto s = db_.prepare(
        (std::string(kTileWithCrc) + " ORDER BY t.zoom_level, t.tile_column, t.tile_row").c_str());
    while (db_.step(s.get(), "read the tiles") == SQLITE_ROW) {
        const int z = sqlite3_column_int(s.get(), 0);
        if (z < 0 || z > kMaxZoom) {
            continue; // not a tile Terrabound wrote or reads
        }
        const TileId id{
            z, sqlite3_column_int64(s.get(), 1), rows_at(z) - 1 - sqlite3_column_int64(s.get(), 2)};
        const std::string data = SqliteDb::column_bytes(s.get(), 3);
        if (!intact(s.get(), data)) {
            throw IoError(shown_as_ + ": tile " + tile_text(id) +
                          " is damaged (its bytes do not match their checksum); run the build "
                          "again with --resume, which makes it again");
        }
        fn(id, data);
    }
}

std::map<std::string, std::string> MbtilesStore::documents() const {
    std::lock_guard lock(mutex_);
    std::map<std::string, std::string> docs;
    auto s = db_.prepare("SELECT name, data FROM terrabound_documents WHERE layer=?1");
    SqliteDb::bind_text(s.get(), 1, layer_);
    while (db_.step(s.get(), "read the documents") == SQLITE_ROW) {
        docs[SqliteDb::column_bytes(s.get(), 0)] = SqliteDb::column_bytes(s.get(), 1);
    }
    return docs;
}

// Bounds are those of the finest zoom's tiles (the data's box, widened to whole tiles); the
// centre is their middle at the middle zoom.
void MbtilesStore::finish() {
    std::lock_guard lock(mutex_);
    int min_z = 0, max_z = 0;
    {
        auto zooms = db_.prepare("SELECT MIN(zoom_level), MAX(zoom_level) FROM tiles");
        db_.step(zooms.get(), "read the zoom levels");
        if (sqlite3_column_type(zooms.get(), 0) == SQLITE_NULL) {
            return; // no tile: nothing to describe
        }
        min_z = sqlite3_column_int(zooms.get(), 0);
        max_z = sqlite3_column_int(zooms.get(), 1);
    }
    LonLatBox b;
    {
        auto extent = db_.prepare("SELECT MIN(tile_column), MAX(tile_column), MIN(tile_row),"
                                  " MAX(tile_row) FROM tiles WHERE zoom_level=?1");
        sqlite3_bind_int(extent.get(), 1, max_z);
        db_.step(extent.get(), "read the extent");
        const auto corner = [&](int col, int row) {
            const std::int64_t y = rows_at(max_z) - 1 - sqlite3_column_int64(extent.get(), row);
            const std::int64_t x = sqlite3_column_int64(extent.get(), col);
            return tile_bounds(Scheme::Mercator, TileId{max_z, x, y});
        };
        const LonLatBox north_west = corner(0, 3), south_east = corner(1, 2);
        b = {north_west.west, south_east.south, south_east.east, north_west.north};
    }
    db_.transaction("write the metadata", [&] {
        set_metadata("bounds",
                     json_number(b.west) + "," + json_number(b.south) + "," + json_number(b.east) +
                         "," + json_number(b.north));
        set_metadata("center",
                     json_number((b.west + b.east) / 2) + "," +
                         json_number((b.south + b.north) / 2) + "," +
                         std::to_string((min_z + max_z) / 2));
        set_metadata("minzoom", std::to_string(min_z));
        set_metadata("maxzoom", std::to_string(max_z));
    });
    // One self-contained file to publish: no -wal beside it. Another connection (a shard's)
    // still open keeps WAL, which readers handle too.
    if (!db_.try_exec("PRAGMA journal_mode=DELETE")) {
        log::warn(shown_as_ + ": stays in WAL mode (another connection has it open)");
    }
}

} // namespace tb::tiler
