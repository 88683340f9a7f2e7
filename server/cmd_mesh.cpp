// terrabound mesh: mesh one whole raster in grid coordinates with a guaranteed vertical error.
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "server/commands.hpp"
#include "tiler/json_number.hpp"
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>

namespace tb::cli {
namespace {

int run(const Args& args) {
    if (args.positional.size() != 1) {
        throw InputError("mesh: name exactly one raster; see 'terrabound mesh --help'");
    }
    const std::string& input = args.positional[0];
    if (!args.has("eps")) {
        throw InputError("mesh: give the vertical error bound with --eps E");
    }
    const double eps = args.get_double("eps", 0);
    const auto out = args.get("o");
    if (!out) {
        throw InputError("mesh: name the output with -o OUT.obj or -o OUT.json");
    }
    const std::string ext = extension_of(*out);
    if (ext != "obj" && ext != "json") {
        throw InputError("mesh: -o " + *out + ": unknown output type; use .obj or .json");
    }
    const auto start = std::chrono::steady_clock::now();
    std::optional<double> nodata;
    if (args.has("nodata")) {
        nodata = args.get_double("nodata", 0);
    }
    const core::HeightGrid grid = tiler::DemSource::open({input}, nodata)->read_all();
    if (grid.width < 2 || grid.height < 2) {
        throw InputError(input + ": " + std::to_string(grid.width) + " x " +
                         std::to_string(grid.height) + " samples; meshing needs at least 2 x 2");
    }
    // float32 heights cannot resolve an eps far below their own precision.
    float top = 0;
    for (float h : grid.heights) {
        top = std::max(top, std::abs(h));
    }
    if (!(eps > 0) || eps < std::ldexp(static_cast<double>(top), -20)) {
        throw InputError("mesh: --eps " + std::to_string(eps) +
                         " is not usable; give eps > 0 and at least 1e-6 of the largest height (" +
                         std::to_string(top) + ")");
    }
    core::TriangulateOptions options;
    options.eps = eps;
    options.lock_border = !args.has("no-lock-border");
    options.effort = core::parse_effort(args.get("effort").value_or("balanced"));
    const core::Mesh mesh = core::triangulate(grid, options);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    tiler::write_file_atomically(
        *out, ext == "obj" ? tiler::mesh_to_obj(mesh) : tiler::mesh_to_json(mesh));
    if (args.has("stats")) {
        std::printf("{\"width\":%d,\"height\":%d,\"eps\":%s,\"vertices\":%zu,\"triangles\":%zu,"
                    "\"max_error\":%s,\"seconds\":%s}\n",
                    grid.width,
                    grid.height,
                    tiler::json_number(eps, "eps").c_str(),
                    mesh.points.size(),
                    mesh.triangle_count(),
                    tiler::json_number(core::max_error(mesh, grid), "max_error").c_str(),
                    tiler::json_number(seconds, "seconds").c_str());
    }
    return 0;
}

} // namespace

const Command& mesh_command() {
    static const Command command{
        {"mesh",
         "INPUT --eps E -o OUT.{obj,json}",
         "Mesh one raster with a guaranteed vertical error.",
         {
             {"eps", "E", "vertical error bound, in the raster's height unit (> 0)"},
             {"o", "OUT", "output: .obj (v column row height, 1-based faces) or .json"},
             {"stats",
              "",
              "print one JSON line: width, height, eps, vertices, triangles, "
              "max_error, seconds"},
             {"no-lock-border", "", "let the border be simplified like the interior"},
             {"nodata", "V", "raw sample value to treat as nodata, replacing the file's own"},
             {"effort",
              "LEVEL",
              "mesher effort: fast, balanced (default) or best; the same bound at each, best the "
              "fewest triangles"},
         },
         "Band 1 is meshed in grid coordinates (x = column, y = row, row 0 first); nodata\n"
         "samples constrain nothing and are filled from their surroundings. No georeferencing\n"
         "is needed. JSON output: {\"vertices\":[x,y,z,...],\"triangles\":[i,j,k,...]} (0-based),\n"
         "the format shared/bench's linf_check reads."},
        run};
    return command;
}

} // namespace tb::cli
