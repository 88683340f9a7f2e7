#pragma once
// Decoding what encode_tile writes, back to positions, normals, triangles and metadata: used by
// tests and by build/server self-checks. Reads the glb layout encode_tile produces (one primitive
// whose Draco data is buffer view 0), not arbitrary glTF.
#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace tb::tiler {

// The .drc geometry metadata (draco::GeometryMetadata on the mesh), schema "terrabound-tile-1".
// Draco metadata entries carry no type, so the key lists below are the schema.
struct DrcMetadata {
    std::map<std::string, std::string> strings; // schema, crs, frame, up_axis, scheme
    std::map<std::string, double> doubles;      // origin_lon_deg ... quant_step_m
    std::map<std::string, std::int32_t> ints;   // level, x, y
};
inline constexpr const char* kDrcSchema = "terrabound-tile-1";
inline constexpr std::array<const char*, 5> kDrcStringKeys{
    "schema", "crs", "frame", "up_axis", "scheme"};
inline constexpr std::array<const char*, 12> kDrcDoubleKeys{"origin_lon_deg",
                                                            "origin_lat_deg",
                                                            "origin_h_m",
                                                            "west_deg",
                                                            "south_deg",
                                                            "east_deg",
                                                            "north_deg",
                                                            "min_h_m",
                                                            "max_h_m",
                                                            "eps_m",
                                                            "quant_step_m",
                                                            "quant_error_m"};
inline constexpr std::array<const char*, 3> kDrcIntKeys{"level", "x", "y"};

struct DecodedTile {
    // Positions exactly as a client decodes them (float32 widened to double), in the file's
    // frame: glb = glTF y-up axes relative to `translation`; drc = ENU metres, z up.
    std::vector<std::array<double, 3>> positions;
    // Vertex normals as decoded (Draco's octahedral dequantization, unit length), in the
    // positions' axes, one per position; empty when the mesh has no NORMAL attribute.
    std::vector<std::array<double, 3>> normals;
    std::vector<std::uint32_t> indices;  // 3 per triangle, in decoded order
    std::array<double, 3> translation{}; // glb root node translation (y-up axes); drc: zero
    std::string json;                    // glb JSON chunk; empty for drc
    DrcMetadata metadata;                // drc only
};

// Throws InputError naming the problem when the bytes are not a well-formed tile.
DecodedTile decode_glb(std::string_view bytes);
DecodedTile decode_drc(std::string_view bytes);

} // namespace tb::tiler
