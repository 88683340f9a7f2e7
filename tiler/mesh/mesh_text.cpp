// A mesh in grid coordinates as OBJ or JSON text (mesh_text.hpp).
#include "tiler/mesh/mesh_text.hpp"

#include <cstdio>

namespace tb::tiler {

std::string mesh_to_obj(const core::Mesh& mesh) {
    std::string out;
    out.reserve(mesh.points.size() * 32 + mesh.triangles.size() * 8);
    char line[96];
    for (std::size_t v = 0; v < mesh.points.size(); ++v) {
        std::snprintf(line,
                      sizeof line,
                      "v %d %d %.17g\n",
                      mesh.points[v].x,
                      mesh.points[v].y,
                      static_cast<double>(mesh.z[v]));
        out += line;
    }
    for (std::size_t e = 0; e + 2 < mesh.triangles.size(); e += 3) {
        std::snprintf(line,
                      sizeof line,
                      "f %u %u %u\n",
                      mesh.triangles[e] + 1,
                      mesh.triangles[e + 1] + 1,
                      mesh.triangles[e + 2] + 1);
        out += line;
    }
    return out;
}

std::string mesh_to_json(const core::Mesh& mesh) {
    std::string out = "{\"vertices\":[";
    char number[64];
    for (std::size_t v = 0; v < mesh.points.size(); ++v) {
        std::snprintf(number,
                      sizeof number,
                      "%s%d,%d,%.17g",
                      v ? "," : "",
                      mesh.points[v].x,
                      mesh.points[v].y,
                      static_cast<double>(mesh.z[v]));
        out += number;
    }
    out += "],\"triangles\":[";
    for (std::size_t e = 0; e < mesh.triangles.size(); ++e) {
        std::snprintf(number, sizeof number, "%s%u", e ? "," : "", mesh.triangles[e]);
        out += number;
    }
    out += "]}\n";
    return out;
}

} // namespace tb::tiler
