#pragma once
// Tile stores: where encoded tiles live once made. Four stores behind one interface:
//   directory: OUT/{layer}/{z}/{x}/{y}.{ext}, eps variants under
//   OUT/{layer}/eps{k}/{z}/{x}/{y}.{ext}, raster DEM tiles under OUT/{layer}/dem/{z}/{x}/{y}.png
//              (terrarium) and OUT/{layer}/dem/mapbox/{z}/{x}/{y}.png,
//              documents at OUT/{layer}/{name} (name may hold '/': "subtrees/0/0/0.subtree");
//   SQLite:    one file (*.sqlite or *.db), WAL, tables tiles(layer, format, eps_level, z, x, y,
//              data), documents(layer, name, data) and meta(name, value).
//   MBTiles:   OUT.mbtiles, one layer's raster DEM tiles in one encoding, as MBTiles 1.3 has
//              them (tiler/stores/store_mbtiles.hpp); a build's documents in an extra table.
//   PMTiles:   OUT.pmtiles, the same tiles as a PMTiles v3 archive, staged in OUT.pmtiles.staging
//              while built and assembled by finish() (tiler/stores/store_pmtiles.cpp).
// Every write is atomic: a reader never sees a truncated tile or document. The directory store
// writes a temporary file next to the target, fsyncs it and renames it over the target; the
// SQLite store commits each put (or each put_batch) as one transaction.
// Every store is safe to use from many threads at once.
#include "tiler/formats/format.hpp"
#include "tiler/tile_grid.hpp"

#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace tb::tiler {

struct TileKey {
    std::string layer;
    TileId id;
    Format format = Format::Glb;
    int eps_level = -1; // as EpsChoice::level
};

struct StoredTile {
    TileKey key;
    std::string bytes;
};

class TileStore {
public:
    virtual ~TileStore() = default;

    // A path ending in .sqlite (or .db) opens/creates an SQLite store, .mbtiles an MBTiles 1.3
    // file and .pmtiles a PMTiles v3 archive (raster DEM tiles of one layer in one encoding),
    // anything else a directory store. Throws
    // IoError naming the path when it cannot be opened or created, InputError when an existing
    // container is not one Terrabound reads.
    static std::unique_ptr<TileStore> open(const std::string& path);

    // Keys and document names are validated first (validate_key, validate_document_name):
    // InputError for a bad one. Read and write failures throw IoError naming the path.
    virtual std::optional<std::string> get(const TileKey& key) const = 0;
    virtual bool contains(const TileKey& key) const = 0;
    virtual void put(const TileKey& key, std::string_view bytes) = 0;
    // Writes many tiles; each one is atomic, and the SQLite store commits them in one
    // transaction (all or none), which is what makes bulk building fast.
    virtual void put_batch(std::span<const StoredTile> tiles);

    // Per-layer documents (tileset.json, build manifest, ...), keyed by file name.
    virtual std::optional<std::string> get_document(const std::string& layer,
                                                    const std::string& name) const = 0;
    virtual void
    put_document(const std::string& layer, const std::string& name, std::string_view bytes) = 0;

    // Remove one tile, or one document, when present (`build --update` drops what a change of
    // sources leaves without data); each removal is atomic. The directory and SQLite stores do;
    // the containers written once (MBTiles, PMTiles) throw InputError.
    virtual void remove(const TileKey& key);
    virtual void remove_document(const std::string& layer, const std::string& name);

    // True when the store holds any tile or document of `layer`.
    virtual bool has_layer(const std::string& layer) const = 0;
    // Deletes every tile and document of `layer` (the builder's --force).
    virtual void remove_layer(const std::string& layer) = 0;
    // Removes what interrupted writers may leave behind (the directory store's temporary files
    // after a crash). Call only while no other process writes the layer.
    virtual void clean_up(const std::string& layer) = 0;

    // Called by the builder once every tile and document of a build is in (not after an
    // interrupted or failed run, nor by a shard): containers written once assemble themselves
    // here (PMTiles), MBTiles records its bounds and zooms. The other stores have nothing to do.
    virtual void finish() {}

    // Whether put(key) would keep the tile: false where a container cannot hold it (another
    // layer, format or encoding than its own) or no longer takes tiles (a finished PMTiles
    // archive), so that a server asks before it writes instead of logging a refusal per tile.
    virtual bool keeps(const TileKey& key) const {
        (void)key;
        return true;
    }

    virtual std::string describe() const = 0; // "directory OUT" / "sqlite OUT.sqlite"
    // True when only Terrabound writes what the store holds (an SQLite store's tables), false
    // when other programs may have put files there too (a directory).
    virtual bool written_by_terrabound_only() const = 0;
};

// True for the paths TileStore::open makes a single-file store of (.sqlite, .db, .mbtiles,
// .pmtiles).
bool is_single_file_store(const std::string& path);
// Throws InputError naming the problem and what to do when the store at `path` cannot hold
// tiles of every one of `formats`: an .mbtiles or .pmtiles file holds exactly one raster DEM
// encoding (terrarium or mapbox), which tiles EPSG:3857 XYZ as those containers do.
void check_store_formats(const std::string& path, std::span<const Format> formats);

// Layer names are URL-safe: [A-Za-z0-9_-]+, at most 64 characters. InputError otherwise.
void validate_layer_name(const std::string& layer);
// A document name is a relative path of '/'-separated parts made of printable ASCII, with no
// empty part, no part starting with '.' (so no "..", "." or hidden file), no backslash and no
// NUL, at most 512 bytes, so that nothing escapes the layer. InputError otherwise.
void validate_document_name(const std::string& name);
// The layer name plus a tile inside the scheme-independent bounds (0 <= z <= kMaxZoom,
// 0 <= x, y < 2^(z+1)) and eps_level >= -1 (exactly -1 for DEM formats). InputError otherwise.
void validate_key(const TileKey& key);

} // namespace tb::tiler
