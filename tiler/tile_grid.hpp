#pragma once
// Tile pyramid arithmetic for the two tiling schemes. Plain arithmetic, no GDAL.
//   geodetic: EPSG:4326, two root tiles (2x1 at z=0), y counted from the south (TMS), as
//             CesiumJS's GeographicTilingScheme and quantized-mesh layers.
//   mercator: EPSG:3857, one root tile, XYZ (y counted from the north), as web slippy maps.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tb::tiler {

enum class Scheme { Geodetic, Mercator };

struct TileId {
    int z = 0;
    std::int64_t x = 0;
    std::int64_t y = 0;
    friend bool operator==(const TileId&, const TileId&) = default;
    friend auto operator<=>(const TileId&, const TileId&) = default;
};

// Degrees, WGS84.
struct LonLatBox {
    double west = 0, south = 0, east = 0, north = 0;
};

// Inclusive tile ranges of one zoom.
struct TileRange {
    int z = 0;
    std::int64_t x0 = 0, y0 = 0, x1 = -1, y1 = -1; // empty when x1 < x0
    bool empty() const { return x1 < x0 || y1 < y0; }
    std::int64_t count() const { return empty() ? 0 : (x1 - x0 + 1) * (y1 - y0 + 1); }
    bool contains(std::int64_t x, std::int64_t y) const {
        return x >= x0 && x <= x1 && y >= y0 && y <= y1;
    }
};

// The smallest range of zoom z holding every one of `ranges` (empty when they all are).
TileRange bounding(int z, const std::vector<TileRange>& ranges);
// How many tiles the ranges (of one zoom) cover together, each counted once.
std::int64_t union_count(const std::vector<TileRange>& ranges);

// The tiles of one zoom that any of some ranges holds, kept as disjoint rectangles: bands of
// rows, each with its sorted, disjoint column spans, and next bands with the same spans joined.
// So thousands of overlapping ranges (one per file of a collection) are looked up in
// logarithmic time, counted exactly, and listed as few rectangles as their union allows: the
// files of a regular grid become one rectangle.
class TileCover {
public:
    TileCover() = default;
    TileCover(int z, const std::vector<TileRange>& ranges);

    bool empty() const { return bands_.empty(); }
    bool contains(std::int64_t x, std::int64_t y) const;
    std::int64_t count() const;
    TileRange bounding() const;
    // The disjoint rectangles, by band from the first row, then by column.
    std::vector<TileRange> ranges() const;
    // Those rectangles cut to `window` (of this zoom), found by binary search: a tile's
    // descendants without a walk over the whole zoom.
    std::vector<TileRange> ranges_within(const TileRange& window) const;

private:
    struct Band {
        std::int64_t y0 = 0, y1 = -1;
        std::vector<std::pair<std::int64_t, std::int64_t>> spans; // [x0, x1], sorted, apart
    };
    int z_ = 0;
    std::vector<Band> bands_; // by y0, apart
};

inline constexpr int kMaxZoom = 24;

Scheme parse_scheme(std::string_view name); // "geodetic" | "mercator"; InputError otherwise
const char* to_string(Scheme scheme);

std::int64_t tiles_across(Scheme scheme, int z); // number of columns at zoom z
std::int64_t tiles_down(Scheme scheme, int z);   // number of rows at zoom z

// A tile id of a scheme, valid by construction: 0 <= z <= kMaxZoom and x, y within the zoom's
// columns and rows. Requests are parsed into one once, where they enter (a route, the `tile`
// command, a tileset path); everything past that takes it and checks only what is its own
// (a layer's zooms and data). The tiles it derives (parent, children, the tiles of a range
// tiles_covering gave) are valid too, so they are made without another check.
class ValidTile {
public:
    // The tile, or nullopt when id lies outside the scheme.
    static std::optional<ValidTile> of(Scheme scheme, const TileId& id);
    // The tile; InputError naming the id and the scheme's ranges when it lies outside.
    static ValidTile parse(Scheme scheme, const TileId& id);
    // The k-th tile (0 <= k < range.count()) of a range that lies in the scheme (as
    // tiles_covering gives them), rows first: y0 row from x0 to x1, then the next row.
    static ValidTile in_range(Scheme scheme, const TileRange& range, std::int64_t k);

    Scheme scheme() const { return scheme_; }
    const TileId& id() const { return id_; }
    int z() const { return id_.z; }
    std::int64_t x() const { return id_.x; }
    std::int64_t y() const { return id_.y; }

    // The tile of zoom z - 1 that holds it; nullopt at zoom 0.
    std::optional<ValidTile> parent() const;
    // The four tiles of zoom z + 1 it holds, (dx, dy) = (0, 0), (1, 0), (0, 1), (1, 1) in the
    // scheme's own x and y directions; empty at kMaxZoom.
    std::vector<ValidTile> children() const;

    friend bool operator==(const ValidTile&, const ValidTile&) = default;
    friend auto operator<=>(const ValidTile&, const ValidTile&) = default;

private:
    ValidTile(Scheme scheme, const TileId& id) : scheme_(scheme), id_(id) {}
    Scheme scheme_;
    TileId id_;
};

// Every tile of a range that lies in the scheme (ValidTile::in_range), in its order.
std::vector<ValidTile> tiles_in(Scheme scheme, const TileRange& range);

// "z/x/y", as messages name a tile.
std::string tile_name(const TileId& id);

// Lon/lat bounds of a tile (mercator tiles are converted from EPSG:3857 metres).
LonLatBox tile_bounds(Scheme scheme, const TileId& id);

// Tiles of zoom z that intersect a lon/lat box (clamped to the scheme's extent).
TileRange tiles_covering(Scheme scheme, const LonLatBox& box, int z);

// The tiles of zoom z over `deep` (where data goes this deep), widened to whole families (the
// four children of one parent) and cut to the tiles over `all` (where any data lies): a parent
// that refines into children refines into every child over its data, so a client replacing it
// never loses the part of it that no deep data covers. For z = 0, or `deep` = `all`, the tiles
// over `deep`.
TileRange tiles_in_families(Scheme scheme, const LonLatBox& deep, const LonLatBox& all, int z);
// r widened to whole families (even first, odd last index); r itself at z = 0 or when empty.
TileRange whole_families(TileRange r);

} // namespace tb::tiler
