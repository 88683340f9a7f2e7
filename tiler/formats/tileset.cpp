// The layer's 3D Tiles 1.1 tileset: explicit JSON, split into external tilesets.
//
// Why explicit and not implicit tiling: implicit subdivision halves a region in longitude and
// latitude, which matches the geodetic scheme but not mercator tiles (their latitude edges
// are not halvings), and it forces one geometricError per level. Explicit tiles carry their own
// region and error, so both schemes and per-tile bounds (chord sag) come out exact. To stay
// small for big layers, "tileset.json" lists min_zoom .. min_zoom+3; each tile at
// min_zoom + 4k (k >= 1, below max_zoom) is a reference to the external tileset
// "tilesets/{z}/{x}/{y}.json", which lists that tile and the next 3 levels below it, and so on. A
// document thus holds at most 85 tiles (+256 references) per root tile.
//
// Geometric error of a tile = eps(z), the published end-to-end bound of what a client draws:
// quantization and the chord sag of straight ECEF triangles are inside it (error_budget reserves
// a share of eps for sag and the mesher bounds edge lengths to keep sag within it). The region
// is padded by the quantization move and that sag. The virtual root (no content) holds the min_zoom
// tiles; its error is twice its largest child's, the tileset's twice the root's.
#include "tiler/formats/encode.hpp"
#include "tiler/geodesy.hpp"
#include "tiler/json_number.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <optional>
#include <vector>

namespace tb::tiler {
namespace {

constexpr int kLevelsPerDocument = 4;
constexpr double kPi = 3.14159265358979323846;
constexpr double kMinRadius = 6335439.0; // b^2/a of WGS84, metres: smallest curvature radius

std::string number(double v) {
    return json_number(v, "a tileset number");
}

std::string tile_path(const TileId& id) {
    return std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
}

ErrorBudget zoom_budget(const TilesetSpec& spec, int z) {
    return spec.budget_for_zoom
               ? spec.budget_for_zoom(z)
               : tile_error_budget(spec.eps_for_zoom(z), spec.scheme, z, spec.tile_size);
}

Region tile_region(const TilesetSpec& spec, const ValidTile& tile) {
    const LonLatBox b = tile_bounds(spec.scheme, tile.id());
    const ErrorBudget budget = zoom_budget(spec, tile.z());
    // Snapping moves a vertex by at most s*sqrt(3)/2 <= s in any direction; straight
    // triangles, no edge longer than max_edge_m, sag below their vertices by at most
    // budget.sag.
    const double move = budget.quant_step;
    const double dlat = move / kMinRadius;
    const double max_abs_lat = std::max(std::abs(b.south), std::abs(b.north)) * kPi / 180;
    const double cos_lat = std::cos(max_abs_lat);
    const double dlon = cos_lat > 1e-9 ? dlat / cos_lat : 2 * kPi;
    Region r;
    r.west = std::max(-kPi, b.west * kPi / 180 - dlon);
    r.east = std::min(kPi, b.east * kPi / 180 + dlon);
    r.south = std::max(-kPi / 2, b.south * kPi / 180 - dlat);
    r.north = std::min(kPi / 2, b.north * kPi / 180 + dlat);
    r.min_h = spec.min_height - move - budget.sag;
    r.max_h = spec.max_height + move;
    return r;
}

// The honest bound of what clients draw: eps(z) itself, chord sag being inside its budget
// (except at zooms so coarse that one sample step sags by most of eps: then that sag counts).
double tile_error(const TilesetSpec& spec, const ValidTile& tile) {
    return spec.error_for_tile ? spec.error_for_tile(tile)
                               : zoom_budget(spec, tile.z()).drawn_bound;
}

std::string region_json(const Region& r) {
    return R"({"region":[)" + number(r.west) + "," + number(r.south) + "," + number(r.east) + "," +
           number(r.north) + "," + number(r.min_h) + "," + number(r.max_h) + "]}";
}

std::vector<ValidTile> children(const TilesetSpec& spec, const ValidTile& tile) {
    std::vector<ValidTile> out;
    if (tile.z() >= spec.max_zoom) {
        return out;
    }
    // Order: south-west, south-east, north-west, north-east in the scheme's own y direction;
    // deterministic either way.
    for (const ValidTile& c : tile.children()) {
        if (spec.has_tile(c)) {
            out.push_back(c);
        }
    }
    return out;
}

// Tiles at min_zoom + 4k (k >= 1) head an external tileset, except at max_zoom: a document of
// one leaf would cost a request for nothing, so leaves stay inline.
bool starts_document(const TilesetSpec& spec, int z) {
    return z > spec.min_zoom && z < spec.max_zoom && (z - spec.min_zoom) % kLevelsPerDocument == 0;
}

// Appends tile `id` (with content) and its subtree down to the next document boundary.
// `up` is the prefix from the current document's directory back to the layer root.
void write_tile(const TilesetSpec& spec,
                const ValidTile& tile,
                const std::string& up,
                std::string& j) {
    j += R"({"boundingVolume":)" + region_json(tile_region(spec, tile));
    j += R"(,"geometricError":)" + number(tile_error(spec, tile));
    j += R"(,"refine":"REPLACE","content":{"uri":")" + up + tile_path(tile.id()) + ".glb\"}";
    const std::vector<ValidTile> kids = children(spec, tile);
    if (!kids.empty()) {
        j += R"(,"children":[)";
        for (std::size_t k = 0; k < kids.size(); ++k) {
            if (k > 0) {
                j += ",";
            }
            if (starts_document(spec, kids[k].z())) {
                j += R"({"boundingVolume":)" + region_json(tile_region(spec, kids[k]));
                j += R"(,"geometricError":)" + number(tile_error(spec, kids[k]));
                j += R"(,"content":{"uri":")" + up + "tilesets/" + tile_path(kids[k].id()) +
                     ".json\"}}";
            } else {
                write_tile(spec, kids[k], up, j);
            }
        }
        j += "]";
    }
    j += "}";
}

std::string document(double geometric_error, const std::string& root) {
    // What the numbers mean, for whoever reads the tileset.
    return R"({"asset":{"version":"1.1","generator":"Terrabound","extras":{"geometricError":)"
           R"("metres: every valid pixel of the source DEM whose centre lies under a tile is )"
           R"(within the tile's geometricError, vertically, of the surface drawn from its )"
           R"(decoded content (quantization and chord sag included), at every zoom"}},)"
           R"("geometricError":)" +
           number(geometric_error) + R"(,"root":)" + root + "}\n";
}

// The tile of spec's scheme a path names: "{z}/{x}/{y}" with plain decimal numbers.
std::optional<ValidTile> parse_tile(const TilesetSpec& spec, const std::string& text) {
    std::int64_t parts[3];
    const char* p = text.data();
    const char* end = text.data() + text.size();
    for (int k = 0; k < 3; ++k) {
        const auto r = std::from_chars(p, end, parts[k]);
        if (r.ec != std::errc() || r.ptr == p) {
            return std::nullopt;
        }
        p = r.ptr;
        if (k < 2) {
            if (p == end || *p != '/') {
                return std::nullopt;
            }
            ++p;
        }
    }
    if (p != end || parts[0] < 0 || parts[0] > kMaxZoom) {
        return std::nullopt; // before narrowing z to an int
    }
    const TileId id{static_cast<int>(parts[0]), parts[1], parts[2]};
    if (tile_path(id) != text) {
        return std::nullopt; // canonical only: no leading zeros or signs
    }
    return ValidTile::of(spec.scheme, id);
}

} // namespace

bool tileset_document(const TilesetSpec& spec, const std::string& path, std::string& out) {
    TB_ASSERT(spec.min_zoom >= 0 && spec.min_zoom <= spec.max_zoom && spec.max_zoom <= kMaxZoom);
    TB_ASSERT(spec.eps_for_zoom && spec.has_tile);
    if (path == "tileset.json") {
        std::vector<ValidTile> tops;
        const TileRange range = tiles_covering(spec.scheme, spec.data_bounds, spec.min_zoom);
        for (const ValidTile& tile : tiles_in(spec.scheme, range)) {
            if (spec.has_tile(tile)) {
                tops.push_back(tile);
            }
        }
        // The virtual root: the union of its children's regions, no content.
        Region all{kPi, kPi / 2, -kPi, -kPi / 2, spec.min_height, spec.max_height};
        double max_error = spec.eps_for_zoom(spec.min_zoom);
        std::string kids;
        for (std::size_t k = 0; k < tops.size(); ++k) {
            const Region r = tile_region(spec, tops[k]);
            all = {std::min(all.west, r.west),
                   std::min(all.south, r.south),
                   std::max(all.east, r.east),
                   std::max(all.north, r.north),
                   std::min(all.min_h, r.min_h),
                   std::max(all.max_h, r.max_h)};
            max_error = std::max(max_error, tile_error(spec, tops[k]));
            if (k > 0) {
                kids += ",";
            }
            write_tile(spec, tops[k], "", kids);
        }
        if (tops.empty()) {
            const LonLatBox b = spec.data_bounds;
            all = {b.west * kPi / 180,
                   b.south * kPi / 180,
                   b.east * kPi / 180,
                   b.north * kPi / 180,
                   spec.min_height,
                   spec.max_height};
        }
        // The virtual root has nothing to draw, so a client must always refine it: its error is
        // the size of the whole region (at least twice its children's), which makes its
        // screen-space error exceed any sensible threshold at every distance a view of the
        // layer can have.
        const double region_size =
            kMinRadius *
            std::hypot(all.north - all.south,
                       (all.east - all.west) *
                           std::cos(std::min(std::abs(all.south), std::abs(all.north))));
        const double root_error = std::max(2 * max_error, region_size);
        std::string root = R"({"boundingVolume":)" + region_json(all) + R"(,"geometricError":)" +
                           number(root_error) + R"(,"refine":"REPLACE","children":[)" + kids + "]}";
        out = document(2 * root_error, root);
        return true;
    }
    constexpr std::string_view kPrefix = "tilesets/";
    constexpr std::string_view kSuffix = ".json";
    if (path.size() <= kPrefix.size() + kSuffix.size() || !path.starts_with(kPrefix) ||
        !path.ends_with(kSuffix)) {
        return false;
    }
    const std::optional<ValidTile> tile = parse_tile(
        spec, path.substr(kPrefix.size(), path.size() - kPrefix.size() - kSuffix.size()));
    if (!tile || tile->z() > spec.max_zoom || !starts_document(spec, tile->z()) ||
        !spec.has_tile(*tile)) {
        return false;
    }
    std::string root;
    write_tile(spec, *tile, "../../../", root);
    out = document(2 * tile_error(spec, *tile), root);
    return true;
}

} // namespace tb::tiler
