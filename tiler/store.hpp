#pragma once
// Tile stores: where encoded tiles live once made. Two stores behind one interface:
//   directory: OUT/{layer}/{z}/{x}/{y}.{ext} and OUT/{layer}/tileset.json (static hosting);
//   SQLite:    one file (*.sqlite), WAL, tiles keyed by (layer, format, eps level, z, x, y).
// Every write is atomic: a reader never sees a truncated tile.
#include "tiler/format.hpp"
#include "tiler/tile_grid.hpp"

#include <memory>
#include <optional>
#include <string>
#include <string_view>

namespace tb::tiler {

struct TileKey {
    std::string layer;
    TileId id;
    Format format = Format::Glb;
    int eps_level = -1;  // as EpsChoice::level
};

class TileStore {
public:
    virtual ~TileStore() = default;

    // A path ending in .sqlite (or .db) opens/creates an SQLite store, anything else a
    // directory store. Throws IoError naming the path when it cannot be opened or created.
    static std::unique_ptr<TileStore> open(const std::string& path);

    virtual std::optional<std::string> get(const TileKey& key) const = 0;
    virtual bool contains(const TileKey& key) const = 0;
    virtual void put(const TileKey& key, std::string_view bytes) = 0;

    // Per-layer documents (tileset.json, build manifest, ...), keyed by file name.
    virtual std::optional<std::string> get_document(const std::string& layer,
                                                    const std::string& name) const = 0;
    virtual void put_document(const std::string& layer,
                              const std::string& name,
                              std::string_view bytes) = 0;

    virtual std::string describe() const = 0;  // "directory OUT" / "sqlite OUT.sqlite"
};

}  // namespace tb::tiler
