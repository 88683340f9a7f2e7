#include "tiler/formats/format.hpp"

namespace tb::tiler {

std::optional<Format> parse_format(std::string_view ext) {
    if (ext == "glb") {
        return Format::Glb;
    }
    if (ext == "drc") {
        return Format::Drc;
    }
    return std::nullopt;
}

const char* extension(Format format) {
    return format == Format::Glb ? "glb" : "drc";
}

const char* media_type(Format format) {
    return format == Format::Glb ? "model/gltf-binary" : "application/octet-stream";
}

} // namespace tb::tiler
