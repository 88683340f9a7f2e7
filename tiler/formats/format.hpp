#pragma once
// Encoded tile formats, with their file extensions and media types.
#include <optional>
#include <string_view>

namespace tb::tiler {

enum class Format {
    Glb, // glTF 2.0 binary, KHR_draco_mesh_compression, ECEF relative to the tile centre
    Drc, // raw Draco, local ENU metres z-up, with geometry metadata
};

std::optional<Format> parse_format(std::string_view extension); // "glb" | "drc"
const char* extension(Format format);                           // "glb" | "drc"
const char* media_type(Format format); // model/gltf-binary | application/octet-stream

} // namespace tb::tiler
