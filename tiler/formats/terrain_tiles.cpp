// 3D Tiles terrain (see terrain_tiles.hpp): the tileset, its binary subtrees, and the glb of a
// terrain tile with EXT_meshopt_compression.
#include "tiler/formats/terrain_tiles.hpp"

#include "core/error.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/geodesy.hpp"
#include "tiler/json_number.hpp"

#include <meshoptimizer.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace tb::tiler {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kQuantSteps = 65535.0; // 16-bit normalized positions

std::string num(double v) {
    return json_number(v, "a 3D Tiles terrain number");
}

void put_u32(std::string& out, std::uint32_t v) {
    for (int k = 0; k < 4; ++k) {
        out.push_back(static_cast<char>((v >> (8 * k)) & 0xff));
    }
}
void put_u64(std::string& out, std::uint64_t v) {
    for (int k = 0; k < 8; ++k) {
        out.push_back(static_cast<char>((v >> (8 * k)) & 0xff));
    }
}
void put_f64(std::string& out, double d) {
    std::uint64_t bits = 0;
    std::memcpy(&bits, &d, sizeof bits);
    put_u64(out, bits);
}
void pad_to(std::string& out, std::size_t alignment, char fill) {
    while (out.size() % alignment != 0) {
        out.push_back(fill);
    }
}

// Interleaves the bits of x (even positions) and y (odd): the tile's index within its level
// of a subtree, as 3D Tiles implicit tiling orders it.
std::uint64_t morton(std::uint64_t x, std::uint64_t y) {
    std::uint64_t m = 0;
    for (int b = 0; b < 32; ++b) {
        m |= ((x >> b) & 1u) << (2 * b);
        m |= ((y >> b) & 1u) << (2 * b + 1);
    }
    return m;
}

// The available tile of implicit coordinates, or nullopt.
std::optional<ValidTile>
available(const TerrainSpec& spec, int root, int level, std::int64_t x, std::int64_t y) {
    const std::optional<ValidTile> tile = terrain_tile_id(root, level, x, y);
    if (!tile) {
        return std::nullopt;
    }
    if (!terrain_lists(spec, tile->id())) {
        return std::nullopt;
    }
    return tile;
}

// The glb's position frame: an ENU frame at the tile's centre, scaled per axis so that the box
// [0, 1]^3 holds every vertex tightly (the up axis spans only the relief and the curvature, so
// heights get a fine step).
struct PositionBox {
    EnuFrame frame;
    std::array<double, 3> min{};  // ENU metres of the box's corner
    std::array<double, 3> size{}; // the box's sides, metres
};

double dot(const std::array<double, 3>& a, const std::array<double, 3>& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// What a client decodes from a 16-bit position: CesiumJS divides by 65535 into a float32, then
// applies the matrix in double precision.
std::array<double, 3> decoded_enu(const PositionBox& box, const std::array<std::uint16_t, 3>& q) {
    std::array<double, 3> out{};
    for (int k = 0; k < 3; ++k) {
        const float unit = static_cast<float>(q[static_cast<std::size_t>(k)] / kQuantSteps);
        out[static_cast<std::size_t>(k)] =
            box.min[static_cast<std::size_t>(k)] +
            box.size[static_cast<std::size_t>(k)] * static_cast<double>(unit);
    }
    return out;
}

// The positions of a mesh's vertices in their box: 16-bit (q), or with `exact` float32 metres
// from the box's corner (f; the box's sides are then 1).
struct QuantizedPositions {
    PositionBox box;
    bool exact = false;
    std::vector<std::array<std::uint16_t, 3>> q;
    std::vector<std::array<float, 3>> f;
    std::array<double, 3> decoded(std::size_t i) const {
        if (!exact) {
            return decoded_enu(box, q[i]);
        }
        return {box.min[0] + double{f[i][0]},
                box.min[1] + double{f[i][1]},
                box.min[2] + double{f[i][2]}};
    }
};

QuantizedPositions quantize_positions(const QuantizedMesh& m, bool exact) {
    const std::size_t n = m.u.size();
    QuantizedPositions out;
    const LonLatBox& b = m.bounds;
    out.box.frame = enu_frame({(b.west + b.east) / 2,
                               (b.south + b.north) / 2,
                               0.5 * (double{m.min_height} + double{m.max_height})});
    std::vector<std::array<double, 3>> enu(n);
    std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (std::size_t i = 0; i < n; ++i) {
        enu[i] = ecef_to_enu(out.box.frame, to_ecef({m.lon(i), m.lat(i), m.height(i)}));
        for (std::size_t k = 0; k < 3; ++k) {
            lo[k] = std::min(lo[k], enu[i][k]), hi[k] = std::max(hi[k], enu[i][k]);
        }
    }
    if (exact) {
        out.exact = true;
        out.box.min = lo;
        out.box.size = {1, 1, 1};
        out.f.resize(n);
        for (std::size_t i = 0; i < n; ++i) {
            for (std::size_t k = 0; k < 3; ++k) {
                out.f[i][k] = static_cast<float>(enu[i][k] - lo[k]);
            }
        }
        return out;
    }
    // East and north first. A vertex moved across the slope by that rounding takes the height
    // that keeps the surface through its old place: its height plus the slope (area-weighted
    // over the triangles around it) times the move.
    out.q.resize(n);
    std::vector<double> dx(n), dy(n);
    for (std::size_t k = 0; k < 2; ++k) {
        out.box.min[k] = lo[k];
        out.box.size[k] = std::max(hi[k] - lo[k], 1e-3);
    }
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < 2; ++k) {
            const double unit = (enu[i][k] - lo[k]) / out.box.size[k];
            out.q[i][k] = static_cast<std::uint16_t>(
                std::clamp(std::round(unit * kQuantSteps), 0.0, kQuantSteps));
        }
        const std::array<double, 3> moved = decoded_enu(out.box, out.q[i]);
        dx[i] = moved[0] - enu[i][0], dy[i] = moved[1] - enu[i][1];
    }
    std::vector<double> gx(n, 0), gy(n, 0), weight(n, 0);
    for (std::size_t t = 0; t + 2 < m.triangles.size(); t += 3) {
        const std::uint32_t a = m.triangles[t], b1 = m.triangles[t + 1], c = m.triangles[t + 2];
        const double ux = enu[b1][0] - enu[a][0], uy = enu[b1][1] - enu[a][1],
                     uz = enu[b1][2] - enu[a][2];
        const double vx = enu[c][0] - enu[a][0], vy = enu[c][1] - enu[a][1],
                     vz = enu[c][2] - enu[a][2];
        const double area = ux * vy - uy * vx; // twice the plan area
        if (std::abs(area) < 1e-9) {
            continue;
        }
        const double sx = (uz * vy - vz * uy) / area, sy = (vz * ux - uz * vx) / area;
        const double w = std::abs(area);
        for (std::uint32_t i : {a, b1, c}) {
            gx[i] += w * sx, gy[i] += w * sy, weight[i] += w;
        }
    }
    std::vector<double> z(n);
    double zlo = 1e300, zhi = -1e300;
    for (std::size_t i = 0; i < n; ++i) {
        z[i] = enu[i][2];
        if (weight[i] > 0) {
            z[i] += (gx[i] * dx[i] + gy[i] * dy[i]) / weight[i];
        }
        zlo = std::min(zlo, z[i]), zhi = std::max(zhi, z[i]);
    }
    out.box.min[2] = zlo;
    out.box.size[2] = std::max(zhi - zlo, 1e-3);
    for (std::size_t i = 0; i < n; ++i) {
        const double unit = (z[i] - zlo) / out.box.size[2];
        out.q[i][2] = static_cast<std::uint16_t>(
            std::clamp(std::round(unit * kQuantSteps), 0.0, kQuantSteps));
    }
    return out;
}

std::string bitstream_view_json(std::size_t offset, std::size_t length) {
    return "{\"buffer\":0,\"byteOffset\":" + std::to_string(offset) +
           ",\"byteLength\":" + std::to_string(length) + "}";
}

} // namespace

std::optional<ValidTile>
terrain_tile_id(std::int64_t root, std::int64_t level, std::int64_t x, std::int64_t y) {
    if (root < 0 || root > 1 || level < 0 || level > kMaxZoom) {
        return std::nullopt; // before the shift and the narrowing to an int
    }
    const std::int64_t side = std::int64_t{1} << level;
    if (x < 0 || x >= side) {
        return std::nullopt; // the other root's column
    }
    return ValidTile::of(Scheme::Geodetic, TileId{static_cast<int>(level), root * side + x, y});
}

TerrainTileBounds terrain_tile_bounds(const LonLatBox& box, double min_height, double max_height) {
    TerrainTileBounds out;
    out.min_height = min_height;
    out.max_height = max_height;
    const BoundingSphere s = bounding_sphere(box, min_height, max_height);
    out.bounding_sphere = {s.centre.x, s.centre.y, s.centre.z, s.radius};
    // The horizon point of a 17 x 17 lattice over the box, raised by the sag of one lattice
    // cell so that the surface between lattice points lies below what is tested.
    constexpr int kSteps = 16;
    const LonLatBox cell{box.west,
                         box.south,
                         box.west + (box.east - box.west) / kSteps,
                         box.south + (box.north - box.south) / kSteps};
    const double lift = max_height + chord_sag(cell) + 1.0;
    std::vector<std::array<double, 3>> points;
    for (int j = 0; j <= kSteps; ++j) {
        for (int i = 0; i <= kSteps; ++i) {
            const Ecef p = to_ecef({box.west + (box.east - box.west) * i / kSteps,
                                    box.south + (box.north - box.south) * j / kSteps,
                                    lift});
            points.push_back({p.x, p.y, p.z});
        }
    }
    out.horizon_occlusion =
        tile_horizon_point({s.centre.x, s.centre.y, s.centre.z}, points, min_height);
    return out;
}

std::string terrain_tileset_json(const TerrainTilesetSpec& spec) {
    const TerrainSpec& t = spec.terrain;
    const std::string heights = num(spec.min_height) + "," + num(spec.max_height);
    const auto region = [&](double west, double east) {
        return "{\"region\":[" + num(west) + "," + num(-kPi / 2) + "," + num(east) + "," +
               num(kPi / 2) + "," + heights + "]}";
    };
    const auto implicit_root = [&](int root) {
        const std::string r = std::to_string(root);
        return "{\"boundingVolume\":" + region(root == 0 ? -kPi : 0.0, root == 0 ? 0.0 : kPi) +
               ",\"geometricError\":" + num(spec.root_error) +
               ",\"refine\":\"REPLACE\",\"content\":{\"uri\":\"" + r +
               "/{level}/{x}/{y}.glb\"},\"implicitTiling\":{\"subdivisionScheme\":\"QUADTREE\","
               "\"subtreeLevels\":" +
               std::to_string(kTerrainSubtreeLevels) +
               ",\"availableLevels\":" + std::to_string(t.max_zoom + 1) +
               ",\"subtrees\":{\"uri\":\"" + r + "/{level}/{x}/{y}.subtree\"}}}";
    };
    const auto property = [](const char* name, const char* type, const char* semantic) {
        return std::string("\"") + name + "\":{\"type\":\"" + type +
               "\",\"componentType\":\"FLOAT64\",\"semantic\":\"" + semantic + "\"}";
    };
    std::string out =
        "{\"asset\":{\"version\":\"1.1\",\"generator\":\"Terrabound\","
        "\"extras\":{\"layer\":\"" +
        t.name +
        "\",\"eps_meaning\":\"a level's geometricError bounds, in metres, the "
        "vertical distance from each drawn tile to every valid source pixel centre "
        "under it (levels below " +
        std::to_string(t.min_zoom) +
        " are flat filler at sea level, as far from the DEM as its relief); a tile "
        "that could not be held to its level's bound publishes its own in its "
        "glb's asset.extras.geometricError\"}},\"schema\":{\"id\":\"terrabound_terrain\","
        "\"classes\":{\"tile\":{\"properties\":{" +
        property("minimumHeight", "SCALAR", "TILE_MINIMUM_HEIGHT") + "," +
        property("maximumHeight", "SCALAR", "TILE_MAXIMUM_HEIGHT") +
        ",\"boundingSphere\":{\"type\":\"SCALAR\",\"componentType\":\"FLOAT64\","
        "\"array\":true,\"count\":4,\"semantic\":\"TILE_BOUNDING_SPHERE\"}," +
        property("horizonOcclusionPoint", "VEC3", "TILE_HORIZON_OCCLUSION_POINT") +
        "}}}},\"geometricError\":" + num(2 * spec.root_error) +
        ",\"root\":{\"boundingVolume\":" + region(-kPi, kPi) +
        ",\"geometricError\":" + num(2 * spec.root_error) +
        ",\"refine\":\"REPLACE\",\"children\":[" + implicit_root(0) + "," + implicit_root(1) +
        "]}}\n";
    return out;
}

bool terrain_subtree(const TerrainTilesetSpec& spec,
                     int root,
                     int level,
                     std::int64_t x,
                     std::int64_t y,
                     std::string& out) {
    const TerrainSpec& t = spec.terrain;
    if (level % kTerrainSubtreeLevels != 0 || level > t.max_zoom ||
        !terrain_tile_id(root, level, x, y)) {
        return false;
    }
    constexpr int kLevels = kTerrainSubtreeLevels;
    // Tile availability, in tile-index order: level by level, Morton order within a level.
    const std::size_t tile_bits = ((std::size_t{1} << (2 * kLevels)) - 1) / 3;
    std::vector<std::uint8_t> tiles((tile_bits + 7) / 8, 0);
    std::vector<TerrainTileBounds> rows;
    for (int l = 0; l < kLevels && level + l <= t.max_zoom; ++l) {
        const std::int64_t side = std::int64_t{1} << l;
        const std::size_t offset = ((std::size_t{1} << (2 * l)) - 1) / 3;
        std::vector<std::pair<std::uint64_t, ValidTile>> found;
        for (std::int64_t j = 0; j < side; ++j) {
            for (std::int64_t i = 0; i < side; ++i) {
                const std::int64_t gx = x * side + i, gy = y * side + j;
                if (const std::optional<ValidTile> tile = available(t, root, level + l, gx, gy)) {
                    found.emplace_back(
                        morton(static_cast<std::uint64_t>(i), static_cast<std::uint64_t>(j)),
                        *tile);
                }
            }
        }
        std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) {
            return a.first < b.first;
        });
        for (const auto& [index, id] : found) {
            const std::size_t bit = offset + static_cast<std::size_t>(index);
            tiles[bit / 8] |= static_cast<std::uint8_t>(1u << (bit % 8));
            rows.push_back(spec.bounds(id));
        }
    }
    // Child subtrees: those whose root tile is available.
    const std::int64_t child_side = std::int64_t{1} << kLevels;
    const std::size_t child_bits = std::size_t{1} << (2 * kLevels);
    std::vector<std::uint8_t> children((child_bits + 7) / 8, 0);
    std::size_t child_count = 0;
    if (level + kLevels <= t.max_zoom) {
        for (std::int64_t j = 0; j < child_side; ++j) {
            for (std::int64_t i = 0; i < child_side; ++i) {
                if (available(t, root, level + kLevels, x * child_side + i, y * child_side + j)) {
                    const std::uint64_t bit =
                        morton(static_cast<std::uint64_t>(i), static_cast<std::uint64_t>(j));
                    children[bit / 8] |= static_cast<std::uint8_t>(1u << (bit % 8));
                    ++child_count;
                }
            }
        }
    }

    // The binary chunk: bitstreams, then the metadata columns, each 8-byte aligned.
    std::string bin;
    std::vector<std::string> views;
    const auto add_view = [&](const void* data, std::size_t length) {
        pad_to(bin, 8, '\0');
        views.push_back(bitstream_view_json(bin.size(), length));
        bin.append(static_cast<const char*>(data), length);
        return views.size() - 1;
    };
    const std::size_t tile_view = add_view(tiles.data(), tiles.size());
    std::string json = "{";
    std::string availability;
    if (rows.empty()) {
        availability = "{\"constant\":0,\"availableCount\":0}";
    } else {
        availability = "{\"bitstream\":" + std::to_string(tile_view) +
                       ",\"availableCount\":" + std::to_string(rows.size()) + "}";
    }
    std::string child_json = "{\"constant\":0,\"availableCount\":0}";
    if (child_count > 0) {
        const std::size_t child_view = add_view(children.data(), children.size());
        child_json = "{\"bitstream\":" + std::to_string(child_view) +
                     ",\"availableCount\":" + std::to_string(child_count) + "}";
    }
    std::string table;
    if (!rows.empty()) {
        const auto column = [&](auto value_of, int components) {
            std::string values;
            for (const TerrainTileBounds& r : rows) {
                for (int k = 0; k < components; ++k) {
                    put_f64(values, value_of(r, k));
                }
            }
            return add_view(values.data(), values.size());
        };
        const std::size_t lo =
            column([](const TerrainTileBounds& r, int) { return r.min_height; }, 1);
        const std::size_t hi =
            column([](const TerrainTileBounds& r, int) { return r.max_height; }, 1);
        const std::size_t sphere =
            column([](const TerrainTileBounds& r,
                      int k) { return r.bounding_sphere[static_cast<std::size_t>(k)]; },
                   4);
        const std::size_t horizon =
            column([](const TerrainTileBounds& r,
                      int k) { return r.horizon_occlusion[static_cast<std::size_t>(k)]; },
                   3);
        const auto values = [](std::size_t view) {
            return "{\"values\":" + std::to_string(view) + "}";
        };
        table =
            ",\"propertyTables\":[{\"class\":\"tile\",\"count\":" + std::to_string(rows.size()) +
            ",\"properties\":{\"minimumHeight\":" + values(lo) +
            ",\"maximumHeight\":" + values(hi) + ",\"boundingSphere\":" + values(sphere) +
            ",\"horizonOcclusionPoint\":" + values(horizon) + "}}],\"tileMetadata\":0";
    }
    pad_to(bin, 8, '\0');
    json += "\"buffers\":[{\"byteLength\":" + std::to_string(bin.size()) + "}],\"bufferViews\":[";
    for (std::size_t i = 0; i < views.size(); ++i) {
        json += (i ? "," : "") + views[i];
    }
    json += "],\"tileAvailability\":" + availability + ",\"contentAvailability\":[" + availability +
            "],\"childSubtreeAvailability\":" + child_json + table + "}";
    pad_to(json, 8, ' ');

    out.clear();
    out += "subt";
    put_u32(out, 1);
    put_u64(out, json.size());
    put_u64(out, bin.size());
    out += json;
    out += bin;
    return true;
}

SurfaceMesh terrain_glb_surface(const QuantizedMesh& mesh, bool exact_positions) {
    const QuantizedPositions pos = quantize_positions(mesh, exact_positions);
    const LonLatBox& b = mesh.bounds;
    SurfaceMesh out;
    out.bounds = b;
    const std::size_t n = mesh.u.size();
    out.u.resize(n), out.v.resize(n), out.h.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        const Geodetic g = to_geodetic(enu_to_ecef(pos.box.frame, pos.decoded(i)));
        out.u[i] = (g.lon - b.west) / (b.east - b.west) * kQuantizedMax;
        out.v[i] = (g.lat - b.south) / (b.north - b.south) * kQuantizedMax;
        out.h[i] = g.h;
        // CesiumJS places edge vertices exactly on their tile's edge (CESIUM_tile_edges).
        if (mesh.u[i] == 0 || mesh.u[i] == kQuantizedMax) {
            out.u[i] = mesh.u[i];
        }
        if (mesh.v[i] == 0 || mesh.v[i] == kQuantizedMax) {
            out.v[i] = mesh.v[i];
        }
    }
    out.triangles = mesh.triangles;
    return out;
}

std::string encode_terrain_glb(const TerrainTile& tile) {
    const QuantizedMesh& m = tile.mesh;
    const std::size_t n = m.u.size();
    TB_ASSERT(n > 0 && !m.triangles.empty());
    TB_ASSERT(tile.extras.normals.empty() || tile.extras.normals.size() == n);
    const QuantizedPositions pos = quantize_positions(m, tile.exact_positions);

    // Vertices in order of first use (meshopt codes such indices compactly).
    const VertexOrder vo = first_use_order(m);
    const std::vector<std::uint32_t>&order = vo.order, &old_of = vo.old_of;

    std::vector<std::uint16_t> positions;
    std::vector<float> exact;
    std::array<double, 3> qmin{1e300, 1e300, 1e300}, qmax{-1e300, -1e300, -1e300};
    if (pos.exact) {
        exact.resize(3 * n);
    } else {
        positions.assign(4 * n, 0);
    }
    for (std::size_t k = 0; k < n; ++k) {
        for (std::size_t c = 0; c < 3; ++c) {
            double value = 0;
            if (pos.exact) {
                exact[3 * k + c] = pos.f[old_of[k]][c];
                value = exact[3 * k + c];
            } else {
                positions[4 * k + c] = pos.q[old_of[k]][c];
                value = positions[4 * k + c] / kQuantSteps;
            }
            qmin[c] = std::min(qmin[c], value);
            qmax[c] = std::max(qmax[c], value);
        }
    }
    // Normals in the node's local frame as CesiumJS reads them: it applies the node matrix to a
    // normal as to a direction (not its inverse transpose), so the local normal is the ENU normal
    // divided by the box's sides. (A generic glTF viewer, which uses the inverse transpose, sees
    // them tilted towards the up axis: this glb is made for Cesium3DTilesTerrainProvider; the
    // layer's Draco tileset is the one for glTF viewers.)
    std::vector<float> normals;
    if (!tile.extras.normals.empty()) {
        normals.resize(3 * n);
        const auto& axes = pos.box.frame.axes;
        for (std::size_t k = 0; k < n; ++k) {
            const auto& e = tile.extras.normals[old_of[k]];
            std::array<double, 3> local{dot(axes[0], e) / pos.box.size[0],
                                        dot(axes[1], e) / pos.box.size[1],
                                        dot(axes[2], e) / pos.box.size[2]};
            const double len = std::sqrt(dot(local, local));
            for (std::size_t c = 0; c < 3; ++c) {
                normals[3 * k + c] = static_cast<float>(local[c] / len);
            }
        }
    }
    const bool wide = n > 65535; // 16-bit indices may not hold 65535 (primitive restart)
    const std::size_t index_size = wide ? 4 : 2;
    std::vector<std::uint32_t> indices(m.triangles.size());
    for (std::size_t k = 0; k < indices.size(); ++k) {
        indices[k] = order[m.triangles[k]];
    }
    // Edge lists (west, south, east, north), along their side.
    const std::array<std::vector<std::uint32_t>, 4> edges = edge_lists(m, old_of);
    // The mesh covers its rectangle, corners included, so no side is empty.
    TB_ASSERT(std::none_of(edges.begin(), edges.end(), [](const auto& l) { return l.empty(); }));

    // The BIN chunk holds the compressed streams and the plain normals; the uncompressed
    // streams live in a fallback buffer with no data, as EXT_meshopt_compression allows.
    std::string bin, views, accessors;
    std::size_t fallback = 0, view_count = 0;
    const auto add_compressed = [&](std::vector<unsigned char> data,
                                    std::size_t size,
                                    std::size_t length,
                                    std::size_t stride,
                                    std::size_t count,
                                    const char* mode,
                                    const char* target) {
        pad_to(bin, 4, '\0');
        fallback = (fallback + 7) / 8 * 8;
        views += std::string(view_count ? "," : "") +
                 "{\"buffer\":1,\"byteOffset\":" + std::to_string(fallback) +
                 ",\"byteLength\":" + std::to_string(length) +
                 (std::strcmp(mode, "ATTRIBUTES") == 0 ? ",\"byteStride\":" + std::to_string(stride)
                                                       : std::string()) +
                 target + ",\"extensions\":{\"EXT_meshopt_compression\":{\"buffer\":0," +
                 "\"byteOffset\":" + std::to_string(bin.size()) +
                 ",\"byteLength\":" + std::to_string(size) +
                 ",\"byteStride\":" + std::to_string(stride) +
                 ",\"count\":" + std::to_string(count) + ",\"mode\":\"" + mode + "\"}}}";
        bin.append(reinterpret_cast<const char*>(data.data()), size);
        fallback += length;
        return view_count++;
    };
    const auto encode_indices = [&](const std::vector<std::uint32_t>& list, bool triangles) {
        const std::size_t bound = triangles ? meshopt_encodeIndexBufferBound(list.size(), n)
                                            : meshopt_encodeIndexSequenceBound(list.size(), n);
        std::vector<unsigned char> data(bound);
        const std::size_t size =
            triangles ? meshopt_encodeIndexBuffer(data.data(), bound, list.data(), list.size())
                      : meshopt_encodeIndexSequence(data.data(), bound, list.data(), list.size());
        if (size == 0) {
            throw Error("meshoptimizer could not encode the indices of a terrain tile");
        }
        return add_compressed(std::move(data),
                              size,
                              list.size() * index_size,
                              index_size,
                              list.size(),
                              triangles ? "TRIANGLES" : "INDICES",
                              triangles ? ",\"target\":34963" : "");
    };
    std::size_t position_view = 0;
    if (pos.exact) {
        views += std::string(view_count ? "," : "") +
                 "{\"buffer\":0,\"byteOffset\":" + std::to_string(bin.size()) +
                 ",\"byteLength\":" + std::to_string(4 * exact.size()) + ",\"target\":34962}";
        bin.append(reinterpret_cast<const char*>(exact.data()), 4 * exact.size());
        position_view = view_count++;
    } else {
        // Meshopt's bitstream version 0, the one EXT_meshopt_compression specifies.
        meshopt_encodeVertexVersion(0);
        std::vector<unsigned char> vdata(meshopt_encodeVertexBufferBound(n, 8));
        const std::size_t vsize =
            meshopt_encodeVertexBuffer(vdata.data(), vdata.size(), positions.data(), n, 8);
        if (vsize == 0) {
            throw Error("meshoptimizer could not encode the positions of a terrain tile");
        }
        position_view =
            add_compressed(std::move(vdata), vsize, 8 * n, 8, n, "ATTRIBUTES", ",\"target\":34962");
    }
    std::size_t normal_view = 0;
    if (!normals.empty()) {
        pad_to(bin, 4, '\0');
        views += ",{\"buffer\":0,\"byteOffset\":" + std::to_string(bin.size()) +
                 ",\"byteLength\":" + std::to_string(4 * normals.size()) + ",\"target\":34962}";
        bin.append(reinterpret_cast<const char*>(normals.data()), 4 * normals.size());
        normal_view = view_count++;
    }
    const std::size_t index_view = encode_indices(indices, true);
    std::array<std::size_t, 4> edge_views{};
    for (int s = 0; s < 4; ++s) {
        edge_views[static_cast<std::size_t>(s)] =
            encode_indices(edges[static_cast<std::size_t>(s)], false);
    }
    pad_to(bin, 4, '\0');

    const std::string index_type = wide ? "5125" : "5123";
    const auto vec = [](const std::array<double, 3>& v) {
        std::string out(1, '[');
        for (std::size_t k = 0; k < 3; ++k) {
            out += num(v[k]);
            out += k < 2 ? ',' : ']';
        }
        return out;
    };
    std::size_t accessor_count = 0;
    const auto add_accessor = [&](const std::string& body) {
        accessors += std::string(accessor_count ? "," : "") + body;
        return accessor_count++;
    };
    const std::size_t position_accessor = add_accessor(
        "{\"bufferView\":" + std::to_string(position_view) +
        (pos.exact ? ",\"componentType\":5126" : ",\"componentType\":5123,\"normalized\":true") +
        ",\"count\":" + std::to_string(n) + ",\"type\":\"VEC3\",\"min\":" + vec(qmin) +
        ",\"max\":" + vec(qmax) + "}");
    std::string attributes = "\"POSITION\":" + std::to_string(position_accessor);
    if (!normals.empty()) {
        attributes +=
            ",\"NORMAL\":" +
            std::to_string(add_accessor("{\"bufferView\":" + std::to_string(normal_view) +
                                        ",\"componentType\":5126,\"count\":" + std::to_string(n) +
                                        ",\"type\":\"VEC3\"}"));
    }
    const std::size_t index_accessor = add_accessor(
        "{\"bufferView\":" + std::to_string(index_view) + ",\"componentType\":" + index_type +
        ",\"count\":" + std::to_string(indices.size()) + ",\"type\":\"SCALAR\"}");
    std::array<std::size_t, 4> edge_accessors{};
    for (std::size_t s = 0; s < 4; ++s) {
        edge_accessors[s] = add_accessor("{\"bufferView\":" + std::to_string(edge_views[s]) +
                                         ",\"componentType\":" + index_type + ",\"count\":" +
                                         std::to_string(edges[s].size()) + ",\"type\":\"SCALAR\"}");
    }

    // nodes[0].matrix takes the unit cube to glTF's y-up axes: ECEF = Y_UP_TO_Z_UP * matrix * p.
    // In ECEF: p -> origin + axes^T * (min + size * p); then (x, y, z) -> (x, z, -y).
    const EnuFrame& f = pos.box.frame;
    const Ecef corner = enu_to_ecef(f, pos.box.min);
    std::array<double, 16> matrix{}; // column-major
    for (int c = 0; c < 3; ++c) {
        const std::array<double, 3>& axis = f.axes[static_cast<std::size_t>(c)];
        const std::array<double, 3> yup{axis[0], axis[2], -axis[1]};
        for (int r = 0; r < 3; ++r) {
            matrix[static_cast<std::size_t>(4 * c + r)] =
                pos.box.size[static_cast<std::size_t>(c)] * yup[static_cast<std::size_t>(r)];
        }
    }
    matrix[12] = corner.x, matrix[13] = corner.z, matrix[14] = -corner.y, matrix[15] = 1;
    std::string matrix_json(1, '[');
    for (std::size_t k = 0; k < 16; ++k) {
        matrix_json += num(matrix[k]);
        matrix_json += k < 15 ? ',' : ']';
    }

    std::string json =
        "{\"asset\":{\"version\":\"2.0\",\"generator\":\"Terrabound\",\"extras\":{"
        "\"geometricError\":" +
        num(tile.glb_error) + ",\"filler\":" + (tile.filler ? "true" : "false") +
        ",\"eps_meaning\":\"bound, in metres, on the vertical distance from the drawn tile to "
        "every valid source pixel centre under it\"}},"
        "\"extensionsUsed\":[\"EXT_meshopt_compression\"," +
        std::string(pos.exact ? "" : "\"KHR_mesh_quantization\",") +
        "\"CESIUM_tile_edges\"],\"extensionsRequired\":[\"EXT_meshopt_compression\"" +
        (pos.exact ? "" : ",\"KHR_mesh_quantization\"") +
        "],\"scene\":0,\"scenes\":[{\"nodes\":[0]}],"
        "\"nodes\":[{\"mesh\":0,\"matrix\":" +
        matrix_json + "}],\"meshes\":[{\"primitives\":[{\"attributes\":{" + attributes +
        "},\"indices\":" + std::to_string(index_accessor) +
        ",\"material\":0,\"mode\":4,\"extensions\":{\"CESIUM_tile_edges\":{\"left\":" +
        std::to_string(edge_accessors[0]) + ",\"bottom\":" + std::to_string(edge_accessors[1]) +
        ",\"right\":" + std::to_string(edge_accessors[2]) +
        ",\"top\":" + std::to_string(edge_accessors[3]) +
        "}}}]}],\"materials\":[{\"name\":\"terrain\",\"pbrMetallicRoughness\":{"
        "\"baseColorFactor\":[0.62,0.58,0.5,1],\"metallicFactor\":0,\"roughnessFactor\":1}}],"
        "\"accessors\":[" +
        accessors + "],\"bufferViews\":[" + views +
        "],\"buffers\":[{\"byteLength\":" + std::to_string(bin.size()) +
        "},{\"byteLength\":" + std::to_string(fallback) +
        ",\"extensions\":{\"EXT_meshopt_compression\":{\"fallback\":true}}}]}";
    return glb_container(std::move(json), bin);
}

} // namespace tb::tiler
