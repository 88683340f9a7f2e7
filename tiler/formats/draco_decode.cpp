// Decoding encode_tile's output with Draco's own decoder (what clients run), for tests and
// self-checks. Draco's Status becomes InputError here: the bytes are what is wrong.
#include "tiler/formats/draco_decode.hpp"

#include "core/error.hpp"

#include <draco/compression/decode.h>
#include <draco/mesh/mesh.h>
#include <draco/metadata/geometry_metadata.h>

#include <charconv>
#include <cstring>

namespace tb::tiler {
namespace {

std::uint32_t read_u32(std::string_view bytes, std::size_t at) {
    std::uint32_t v = 0;
    for (int k = 3; k >= 0; --k) {
        v = (v << 8) | static_cast<unsigned char>(bytes[at + static_cast<std::size_t>(k)]);
    }
    return v;
}

// The number following `"key":` after position `from` in the JSON text.
double json_number_after(std::string_view json, std::string_view key, std::size_t from = 0) {
    std::string pattern(1, '"'); // built up, not "a" + b: GCC 12 -O3 warns (-Wrestrict) on that
    pattern += key;
    pattern += "\":";
    const std::size_t at = json.find(pattern, from);
    if (at == std::string_view::npos) {
        throw InputError("glb: JSON has no \"" + std::string(key) +
                         "\"; expected a tile written by Terrabound");
    }
    const char* begin = json.data() + at + pattern.size();
    double v = 0;
    const auto r = std::from_chars(begin, json.data() + json.size(), v);
    if (r.ec != std::errc()) {
        throw InputError("glb: JSON \"" + std::string(key) + "\" is not a number");
    }
    return v;
}

} // namespace

DecodedTile decode_drc(std::string_view bytes) {
    draco::DecoderBuffer buffer;
    buffer.Init(bytes.data(), bytes.size());
    draco::Decoder decoder;
    auto result = decoder.DecodeMeshFromBuffer(&buffer);
    if (!result.ok()) {
        throw InputError("drc: Draco cannot decode the mesh: " +
                         result.status().error_msg_string());
    }
    const std::unique_ptr<draco::Mesh> mesh = std::move(result).value();
    const draco::PointAttribute* pos = mesh->GetNamedAttribute(draco::GeometryAttribute::POSITION);
    if (pos == nullptr || pos->num_components() != 3) {
        throw InputError("drc: the mesh has no 3-component POSITION attribute");
    }
    DecodedTile out;
    out.positions.resize(mesh->num_points());
    for (draco::PointIndex i(0); i < mesh->num_points(); ++i) {
        float p[3];
        if (!pos->ConvertValue<float, 3>(pos->mapped_index(i), p)) {
            throw InputError("drc: POSITION values are not convertible to float");
        }
        out.positions[i.value()] = {double(p[0]), double(p[1]), double(p[2])};
    }
    if (const draco::PointAttribute* nrm =
            mesh->GetNamedAttribute(draco::GeometryAttribute::NORMAL)) {
        if (nrm->num_components() != 3) {
            throw InputError("drc: the NORMAL attribute has " +
                             std::to_string(nrm->num_components()) + " components, expected 3");
        }
        out.normals.resize(mesh->num_points());
        for (draco::PointIndex i(0); i < mesh->num_points(); ++i) {
            float n[3];
            if (!nrm->ConvertValue<float, 3>(nrm->mapped_index(i), n)) {
                throw InputError("drc: NORMAL values are not convertible to float");
            }
            out.normals[i.value()] = {double(n[0]), double(n[1]), double(n[2])};
        }
    }
    out.indices.reserve(std::size_t{mesh->num_faces()} * 3);
    for (draco::FaceIndex f(0); f < mesh->num_faces(); ++f) {
        for (int k = 0; k < 3; ++k) {
            out.indices.push_back(mesh->face(f)[k].value());
        }
    }
    if (const draco::GeometryMetadata* md = mesh->GetMetadata()) {
        for (const char* key : kDrcStringKeys) {
            std::string v;
            if (md->GetEntryString(key, &v)) {
                out.metadata.strings[key] = v;
            }
        }
        for (const char* key : kDrcDoubleKeys) {
            double v = 0;
            if (md->GetEntryDouble(key, &v)) {
                out.metadata.doubles[key] = v;
            }
        }
        for (const char* key : kDrcIntKeys) {
            std::int32_t v = 0;
            if (md->GetEntryInt(key, &v)) {
                out.metadata.ints[key] = v;
            }
        }
    }
    return out;
}

DecodedTile decode_glb(std::string_view bytes) {
    if (bytes.size() < 20 || read_u32(bytes, 0) != 0x46546C67 || read_u32(bytes, 4) != 2) {
        throw InputError("glb: not a glTF 2.0 binary (bad magic or version)");
    }
    if (read_u32(bytes, 8) != bytes.size()) {
        throw InputError("glb: header length " + std::to_string(read_u32(bytes, 8)) +
                         " differs from the " + std::to_string(bytes.size()) + " bytes given");
    }
    const std::uint32_t json_len = read_u32(bytes, 12);
    if (read_u32(bytes, 16) != 0x4E4F534A || 20 + std::size_t{json_len} > bytes.size()) {
        throw InputError("glb: first chunk is not a complete JSON chunk");
    }
    const std::string_view json = bytes.substr(20, json_len);
    if (20 + std::size_t{json_len} == bytes.size()) {
        // No BIN chunk: an empty tile (all voids) has a scene without nodes and no buffer.
        if (json.find("\"meshes\"") != std::string_view::npos ||
            json.find("\"buffers\"") != std::string_view::npos) {
            throw InputError("glb: has meshes or buffers but no BIN chunk");
        }
        DecodedTile empty;
        empty.json = std::string(json);
        return empty;
    }
    if (20 + std::size_t{json_len} + 8 > bytes.size()) {
        throw InputError("glb: first chunk is not a complete JSON chunk");
    }
    const std::size_t bin_at = 20 + std::size_t{json_len};
    const std::uint32_t bin_len = read_u32(bytes, bin_at);
    if (read_u32(bytes, bin_at + 4) != 0x004E4942 || bin_at + 8 + bin_len != bytes.size()) {
        throw InputError("glb: second chunk is not a BIN chunk ending the file");
    }
    const std::string_view bin = bytes.substr(bin_at + 8, bin_len);

    const std::size_t draco_at = json.find("\"KHR_draco_mesh_compression\":{\"bufferView\":0");
    const std::size_t views_at = json.find("\"bufferViews\":[{");
    if (draco_at == std::string_view::npos || views_at == std::string_view::npos) {
        throw InputError("glb: no KHR_draco_mesh_compression primitive on buffer view 0");
    }
    const double offset = json_number_after(json, "byteOffset", views_at);
    const double length = json_number_after(json, "byteLength", views_at);
    if (offset < 0 || length <= 0 || offset + length > double(bin.size())) {
        throw InputError("glb: buffer view 0 lies outside the BIN chunk");
    }
    DecodedTile out =
        decode_drc(bin.substr(static_cast<std::size_t>(offset), static_cast<std::size_t>(length)));
    const std::size_t tr = json.find("\"translation\":[");
    if (tr != std::string_view::npos) {
        const char* p = json.data() + tr + std::strlen("\"translation\":[");
        const char* end = json.data() + json.size();
        for (int k = 0; k < 3; ++k) {
            const auto r = std::from_chars(p, end, out.translation[static_cast<std::size_t>(k)]);
            if (r.ec != std::errc() || r.ptr == end) {
                throw InputError("glb: node translation is not three numbers");
            }
            p = r.ptr + 1; // skip ',' or ']'
        }
    }
    out.json = std::string(json);
    return out;
}

} // namespace tb::tiler
