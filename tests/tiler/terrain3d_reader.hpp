#pragma once
// An independent reader of 3D Tiles terrain, doing what CesiumJS's Cesium3DTilesTerrainProvider
// does with our bytes and nothing from tiler/: .subtree files (header, JSON, bitstreams, the
// FLOAT64 tile metadata columns) and glb tiles, whose EXT_meshopt_compression streams are
// decoded with meshoptimizer's own decoder and whose positions are placed in ECEF as CesiumJS
// places them: p / 65535 (16-bit) or the float32 values, through nodes[0].matrix, then glTF's
// y-up to z-up.
#include <doctest/doctest.h>
#include <meshoptimizer.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace tb_terrain3d {

using json = nlohmann::json;
using V3 = std::array<double, 3>;

// Triangles between ECEF vertices (the layout of tb_oracle::Drawn, source_oracle.hpp).
struct Drawn {
    std::vector<V3> ecef;
    std::vector<std::uint32_t> indices;
};

inline std::uint32_t u32(const std::string& b, std::size_t at) {
    REQUIRE(at + 4 <= b.size());
    std::uint32_t v = 0;
    std::memcpy(&v, b.data() + at, 4);
    return v;
}
inline std::uint64_t u64(const std::string& b, std::size_t at) {
    REQUIRE(at + 8 <= b.size());
    std::uint64_t v = 0;
    std::memcpy(&v, b.data() + at, 8);
    return v;
}

struct Subtree {
    json doc;
    std::string bin;
    // The bytes of buffer view i (checked to lie in the binary chunk).
    std::string view(std::size_t i) const {
        const json& v = doc.at("bufferViews").at(i);
        const std::size_t offset = v.at("byteOffset"), length = v.at("byteLength");
        REQUIRE(v.at("buffer") == 0);
        REQUIRE(offset + length <= bin.size());
        CHECK(offset % 8 == 0);
        return bin.substr(offset, length);
    }
    // Bit `index` of an availability object (a constant or a bitstream).
    bool available(const json& a, std::size_t index) const {
        if (a.contains("constant")) {
            return a.at("constant") == 1;
        }
        const std::string bits = view(a.at("bitstream"));
        REQUIRE(index / 8 < bits.size());
        return (static_cast<unsigned char>(bits[index / 8]) >> (index % 8)) & 1u;
    }
    // Column `name` of the tile metadata table, as doubles (FLOAT64, `components` per row).
    std::vector<double> column(const std::string& name, std::size_t components) const {
        const json& table = doc.at("propertyTables").at(doc.at("tileMetadata").get<std::size_t>());
        const std::size_t count = table.at("count");
        const std::string bytes = view(table.at("properties").at(name).at("values"));
        REQUIRE(bytes.size() == count * components * 8);
        std::vector<double> out(count * components);
        std::memcpy(out.data(), bytes.data(), bytes.size());
        return out;
    }
};

inline Subtree read_subtree(const std::string& b) {
    REQUIRE(b.size() >= 24);
    REQUIRE(b.substr(0, 4) == "subt");
    REQUIRE(u32(b, 4) == 1);
    const std::uint64_t json_len = u64(b, 8), bin_len = u64(b, 16);
    REQUIRE(24 + json_len + bin_len == b.size());
    CHECK(json_len % 8 == 0);
    CHECK(bin_len % 8 == 0);
    Subtree s;
    s.doc = json::parse(b.substr(24, json_len));
    s.bin = b.substr(24 + json_len);
    REQUIRE(s.doc.at("buffers").at(0).at("byteLength") == bin_len);
    return s;
}

// 3D Tiles implicit tiling's tile index: x bits at even positions, y at odd.
inline std::uint64_t morton(std::uint64_t x, std::uint64_t y) {
    std::uint64_t m = 0;
    for (int b = 0; b < 32; ++b) {
        m |= ((x >> b) & 1u) << (2 * b) | ((y >> b) & 1u) << (2 * b + 1);
    }
    return m;
}

struct Glb {
    json doc;
    Drawn drawn;                                     // ECEF vertices, triangle indices
    std::vector<V3> normals;                         // ECEF unit normals as CesiumJS derives them
    std::array<std::vector<std::uint32_t>, 4> edges; // left (west), bottom, right, top
    double published = 0;                            // asset.extras.geometricError
};

inline Glb read_glb(const std::string& b) {
    REQUIRE(u32(b, 0) == 0x46546C67);
    REQUIRE(u32(b, 4) == 2);
    REQUIRE(u32(b, 8) == b.size());
    const std::uint32_t json_len = u32(b, 12);
    REQUIRE(u32(b, 16) == 0x4E4F534A);
    Glb g;
    g.doc = json::parse(b.substr(20, json_len));
    const std::size_t bin_at = 20 + json_len;
    REQUIRE(u32(b, bin_at + 4) == 0x004E4942);
    const std::string bin = b.substr(bin_at + 8, u32(b, bin_at));
    const json& d = g.doc;
    g.published = d.at("asset").at("extras").at("geometricError");
    // The view's bytes as a client gets them: decoded from the meshopt stream when compressed.
    const auto view_bytes = [&](std::size_t accessor_index, std::size_t& stride) {
        const json& acc = d.at("accessors").at(accessor_index);
        const json& v = d.at("bufferViews").at(acc.at("bufferView").get<std::size_t>());
        const std::size_t count = acc.at("count");
        if (!v.contains("extensions")) {
            REQUIRE(v.at("buffer") == 0);
            const std::size_t offset = v.value("byteOffset", 0), length = v.at("byteLength");
            REQUIRE(offset + length <= bin.size());
            stride = 0;
            return bin.substr(offset, length);
        }
        const json& e = v.at("extensions").at("EXT_meshopt_compression");
        const std::size_t offset = e.value("byteOffset", 0), length = e.at("byteLength");
        stride = e.at("byteStride");
        REQUIRE(e.at("buffer") == 0);
        REQUIRE(offset + length <= bin.size());
        REQUIRE(e.at("count") == count);
        std::string out(count * stride, '\0');
        const auto* src = reinterpret_cast<const unsigned char*>(bin.data() + offset);
        const std::string mode = e.at("mode");
        int rc = -1;
        if (mode == "ATTRIBUTES") {
            rc = meshopt_decodeVertexBuffer(out.data(), count, stride, src, length);
        } else if (mode == "TRIANGLES") {
            rc = meshopt_decodeIndexBuffer(out.data(), count, stride, src, length);
        } else if (mode == "INDICES") {
            rc = meshopt_decodeIndexSequence(out.data(), count, stride, src, length);
        }
        REQUIRE_MESSAGE(rc == 0, "meshopt could not decode a " << mode << " stream");
        return out;
    };
    const auto indices = [&](std::size_t accessor_index) {
        const json& acc = d.at("accessors").at(accessor_index);
        std::size_t stride = 0;
        const std::string bytes = view_bytes(accessor_index, stride);
        const std::size_t size = acc.at("componentType") == 5123 ? 2 : 4;
        REQUIRE((stride == 0 || stride == size));
        std::vector<std::uint32_t> out(acc.at("count").get<std::size_t>());
        for (std::size_t k = 0; k < out.size(); ++k) {
            std::uint32_t v = 0;
            std::memcpy(&v, bytes.data() + k * size, size);
            out[k] = v;
        }
        return out;
    };
    REQUIRE(d.at("meshes").size() == 1);
    const json& prim = d.at("meshes").at(0).at("primitives").at(0);
    const std::array<double, 16> m = d.at("nodes").at(0).at("matrix");
    const auto apply = [&m](const std::array<double, 3>& p, double w) {
        // Column-major matrix, then Y_UP_TO_Z_UP: (x, y, z) -> (x, -z, y).
        std::array<double, 3> y{};
        for (int r = 0; r < 3; ++r) {
            y[r] = m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + w * m[12 + r];
        }
        return V3{y[0], -y[2], y[1]};
    };
    const std::size_t pos_acc = prim.at("attributes").at("POSITION");
    const json& pa = d.at("accessors").at(pos_acc);
    std::size_t stride = 0;
    const std::string pos = view_bytes(pos_acc, stride);
    const std::size_t n = pa.at("count");
    for (std::size_t k = 0; k < n; ++k) {
        std::array<double, 3> p{};
        for (int c = 0; c < 3; ++c) {
            if (pa.at("componentType") == 5123) {
                REQUIRE(stride == 8);
                std::uint16_t q = 0;
                std::memcpy(&q, pos.data() + k * 8 + c * 2, 2);
                p[c] = static_cast<float>(q / 65535.0);
            } else {
                REQUIRE(pa.at("componentType") == 5126);
                float f = 0;
                std::memcpy(&f, pos.data() + k * 12 + c * 4, 4);
                p[c] = f;
            }
        }
        g.drawn.ecef.push_back(apply(p, 1));
    }
    if (prim.at("attributes").contains("NORMAL")) {
        const std::size_t acc = prim.at("attributes").at("NORMAL");
        const std::string bytes = view_bytes(acc, stride);
        REQUIRE(bytes.size() == 12 * n);
        for (std::size_t k = 0; k < n; ++k) {
            float f[3];
            std::memcpy(f, bytes.data() + 12 * k, 12);
            V3 e = apply({f[0], f[1], f[2]}, 0);
            const double len = std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
            g.normals.push_back({e[0] / len, e[1] / len, e[2] / len});
        }
    }
    g.drawn.indices = indices(prim.at("indices"));
    const json& edges = prim.at("extensions").at("CESIUM_tile_edges");
    const char* names[4] = {"left", "bottom", "right", "top"};
    for (int s = 0; s < 4; ++s) {
        g.edges[static_cast<std::size_t>(s)] = indices(edges.at(names[s]));
    }
    return g;
}

} // namespace tb_terrain3d
