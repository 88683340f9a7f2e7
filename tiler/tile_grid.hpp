#pragma once
// Tile pyramid arithmetic for the two tiling schemes. Plain arithmetic, no GDAL.
//   geodetic: EPSG:4326, two root tiles (2x1 at z=0), y counted from the south (TMS), as
//             CesiumJS's GeographicTilingScheme and quantized-mesh layers.
//   mercator: EPSG:3857, one root tile, XYZ (y counted from the north), as web slippy maps.
#include <cstdint>
#include <string>
#include <string_view>

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
};

inline constexpr int kMaxZoom = 24;

Scheme parse_scheme(std::string_view name); // "geodetic" | "mercator"; InputError otherwise
const char* to_string(Scheme scheme);

std::int64_t tiles_across(Scheme scheme, int z); // number of columns at zoom z
std::int64_t tiles_down(Scheme scheme, int z);   // number of rows at zoom z
bool is_valid(Scheme scheme, const TileId& id);  // 0 <= z <= kMaxZoom, x, y in range

// Lon/lat bounds of a tile (mercator tiles are converted from EPSG:3857 metres).
LonLatBox tile_bounds(Scheme scheme, const TileId& id);

// Tiles of zoom z that intersect a lon/lat box (clamped to the scheme's extent).
TileRange tiles_covering(Scheme scheme, const LonLatBox& box, int z);

} // namespace tb::tiler
