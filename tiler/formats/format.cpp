#include "tiler/formats/format.hpp"

namespace tb::tiler {

std::optional<Format> parse_format(std::string_view name) {
    for (Format f :
         {Format::Glb, Format::Drc, Format::Terrarium, Format::Mapbox, Format::Terrain,
          Format::Terrain3d}) {
        if (name == format_name(f)) {
            return f;
        }
    }
    return std::nullopt;
}

const char* format_name(Format format) {
    switch (format) {
    case Format::Glb:
        return "glb";
    case Format::Drc:
        return "drc";
    case Format::Terrarium:
        return "terrarium";
    case Format::Mapbox:
        return "mapbox";
    case Format::Terrain:
        return "terrain";
    case Format::Terrain3d:
        return "terrain3d";
    }
    return "?";
}

const char* extension(Format format) {
    if (format == Format::Terrain3d) {
        return "glb";
    }
    return is_dem_format(format) ? "png" : format_name(format);
}

const char* media_type(Format format) {
    if (is_dem_format(format)) {
        return "image/png";
    }
    if (format == Format::Terrain) {
        return "application/vnd.quantized-mesh";
    }
    return format == Format::Glb || format == Format::Terrain3d ? "model/gltf-binary"
                                                                : "application/octet-stream";
}

bool is_terrain_format(Format format) {
    return format == Format::Terrain || format == Format::Terrain3d;
}

bool is_dem_format(Format format) {
    return format == Format::Terrarium || format == Format::Mapbox;
}

} // namespace tb::tiler
