#pragma once
// The MBTiles 1.3 store (OUT.mbtiles): one layer's raster DEM tiles in one encoding, in the
// tables GDAL's MBTiles driver, tileserver-gl, martin and MapLibre tools read:
//   metadata(name, value)                       unique index on name; the keys of MBTiles 1.3:
//       name (the layer), format=png, type=baselayer, description, encoding (terrarium |
//       mapbox, as MapLibre's raster-dem sources name it), and, once the build has finished
//       (finish()), bounds, center, minzoom, maxzoom;
//   tiles(zoom_level, tile_column, tile_row, tile_data)
//       unique index on (zoom_level, tile_column, tile_row); TMS rows: tile_row = 2^z - 1 - y
//       for the XYZ tile (z, x, y) Terrabound's DEM tiles use;
//   terrabound_documents(layer, name, data)     the build's documents (build-manifest.json and
//       the like), which MBTiles has no place for; readers of MBTiles ignore the table.
//   terrabound_tile_crc(zoom_level, tile_column, tile_row, crc)   the CRC-32 of each tile's data
//       (tiler/stores/checksum.hpp): a tile that does not match it is damaged and reads as
//       missing, with a warning (so it is made again, never served); a tile without one (another
//       program wrote it) reads as it is.
// The file's application_id is 0x4d504258 ("MPBX"), as the spec recommends. Every put is one
// transaction (put_batch one for the batch), in WAL mode while open; finish() switches the file
// back to a rollback journal so that it is one self-contained file to copy or publish.
// The PMTiles store stages its tiles in one of these (tiler/stores/store_pmtiles.cpp).
#include "tiler/stores/sqlite_db.hpp"
#include "tiler/stores/store.hpp"

#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>

namespace tb::tiler {

class MbtilesStore final : public TileStore {
public:
    // Opens or creates the file at `path`. Messages name `shown_as` (default: the path) and
    // call the container `kind` ("MBTiles", or "PMTiles" for a staging file).
    explicit MbtilesStore(std::string path,
                          std::string shown_as = {},
                          std::string kind = "MBTiles");

    // Only the held layer's DEM tiles of the held encoding are found; other keys read as
    // missing. put refuses (InputError) mesh formats, eps variants, tiles outside EPSG:3857
    // XYZ, a second layer and a second encoding.
    std::optional<std::string> get(const TileKey& key) const override;
    bool contains(const TileKey& key) const override { return get(key).has_value(); }
    void put(const TileKey& key, std::string_view bytes) override;
    void put_batch(std::span<const StoredTile> tiles) override;
    bool keeps(const TileKey& key) const override;
    std::optional<std::string> get_document(const std::string& layer,
                                            const std::string& name) const override;
    void put_document(const std::string& layer,
                      const std::string& name,
                      std::string_view bytes) override;
    bool has_layer(const std::string& layer) const override;
    void remove_layer(const std::string& layer) override;
    void clean_up(const std::string& layer) override { validate_layer_name(layer); }
    // Writes bounds, center, minzoom and maxzoom from the tiles, and leaves WAL mode.
    void finish() override;
    std::string describe() const override { return "mbtiles " + shown_as_; }
    bool written_by_terrabound_only() const override { return true; }

    // What it holds: the layer ("" while empty) and the DEM encoding (nullopt before a tile).
    std::string layer() const;
    std::optional<Format> format() const;
    // Calls fn(XYZ id, bytes) for every tile, in (zoom, column, row) order. Throws IoError at a
    // damaged tile.
    void for_each_tile(const std::function<void(const TileId&, const std::string&)>& fn) const;
    // The held layer's documents: name -> bytes.
    std::map<std::string, std::string> documents() const;

private:
    void create_tables();
    void load_identity();
    void check_key(const TileKey& key) const;
    void claim(const std::string& layer, std::optional<Format> format);
    void put_locked(const TileKey& key, std::string_view bytes);
    void set_metadata(const std::string& name, const std::string& value);

    std::string shown_as_, kind_;
    SqliteDb db_;
    mutable std::mutex mutex_;
    std::string layer_;
    std::optional<Format> format_;
    SqliteStmt get_, put_, put_crc_, get_doc_, put_doc_, set_meta_;
};

} // namespace tb::tiler
