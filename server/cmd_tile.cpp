// terrabound tile: one tile of a DEM, as the tile raster (.tif), its mesh (.obj) or encoded
// (.glb / .drc), exactly as the layer makes it for `build` and `serve`.
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "server/commands.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"
#include "tiler/sources/gdal_source.hpp"

#include <algorithm>
#include <cstdio>
#include <limits>
#include <sstream>

namespace tb::cli {
namespace {

int run(const Args& args) {
    if (args.positional.size() < 4) {
        throw InputError("tile: expected INPUT... Z X Y; see 'terrabound tile --help'");
    }
    const auto out = args.get("o");
    if (!out) {
        throw InputError("tile: name the output with -o OUT.{glb,drc,obj,tif}");
    }
    const std::string ext = extension_of(*out);
    if (ext != "glb" && ext != "drc" && ext != "obj" && ext != "tif") {
        throw InputError("tile: -o " + *out +
                         ": unknown output type; use .glb, .drc, .obj or .tif");
    }
    const std::size_t n = args.positional.size();
    const long long z = to_int(args.positional[n - 3], "tile: Z");
    // Z clamped to what an int holds (any zoom past it is as far outside the scheme); the
    // scheme's ranges are ValidTile::parse's to check.
    constexpr long long kIntMin = std::numeric_limits<int>::min();
    constexpr long long kIntMax = std::numeric_limits<int>::max();
    const tiler::TileId id{static_cast<int>(std::clamp(z, kIntMin, kIntMax)),
                           to_int(args.positional[n - 2], "tile: X"),
                           to_int(args.positional[n - 1], "tile: Y")};

    tiler::LayerOptions options;
    options.sources.assign(args.positional.begin(), args.positional.end() - 3);
    options.scheme = tiler::parse_scheme(args.get("scheme").value_or("geodetic"));
    const tiler::ValidTile tile = tiler::ValidTile::parse(options.scheme, id);
    const long long size = args.get_int("size", 256);
    if (size < 2 || size > 4096) {
        throw InputError("tile: --size " + std::to_string(size) + " is outside 2..4096");
    }
    options.tile_size = static_cast<int>(size);
    options.datum = tiler::parse_datum(args.get("datum").value_or("auto"));
    if (auto v = args.get("effort")) {
        options.effort = core::parse_effort(*v);
    }
    if (args.has("nodata")) {
        options.nodata = args.get_double("nodata", 0);
    }
    options.summary_dir = args.get("summary-dir").value_or("");
    if (auto v = args.get("valid-range")) {
        options.valid_range = tiler::parse_valid_range(*v, "tile: --valid-range");
    }
    if (auto v = args.get("priority")) {
        options.priority = tiler::parse_source_priority(*v, "tile: --priority");
    }
    const auto layer = tiler::Layer::open(options);
    const double eps = args.has("eps") ? args.get_double("eps", 0) : layer->eps_for_zoom(tile.z());
    tiler::check_eps(eps, "tile: --eps");

    std::ostringstream summary;
    summary << "tile " << tiler::tile_name(tile.id()) << " (" << to_string(options.scheme) << "): ";
    if (ext == "tif") {
        const tiler::TileRaster raster = layer->mesh_tile_at(tile, eps).raster;
        tiler::write_tile_raster_tiff(raster, *out);
        const auto voids = std::count(raster.grid.valid.begin(), raster.grid.valid.end(), 0);
        summary << raster.grid.width << " x " << raster.grid.height << " samples, " << voids
                << " void";
    } else if (ext == "obj") {
        const tiler::MeshedTile t = layer->mesh_tile_at(tile, eps);
        std::string text;
        char line[128];
        for (std::size_t v = 0; v < t.mesh.vertex_count(); ++v) {
            double column = 0, row = 0;
            tiler::vertex_grid_position(t.raster, t.mesh, v, column, row);
            std::snprintf(line,
                          sizeof line,
                          "v %.17g %.17g %.9g\n",
                          column,
                          row,
                          static_cast<double>(t.mesh.z[v]));
            text += line;
        }
        for (std::size_t e = 0; e + 2 < t.mesh.triangles.size(); e += 3) {
            std::snprintf(line,
                          sizeof line,
                          "f %u %u %u\n",
                          t.mesh.triangles[e] + 1,
                          t.mesh.triangles[e + 1] + 1,
                          t.mesh.triangles[e + 2] + 1);
            text += line;
        }
        tiler::write_file_atomically(*out, text);
        summary << t.mesh.vertex_count() << " vertices, " << t.mesh.triangle_count()
                << " triangles, eps " << eps << " m (mesh " << t.budget.mesh_eps << " m)";
    } else {
        const auto format = *tiler::parse_format(ext);
        const std::string bytes = layer->make_tile_at(tile, format, eps);
        tiler::write_file_atomically(*out, bytes);
        summary << bytes.size() << " bytes, eps " << eps << " m";
    }
    summary << " -> " << *out;
    log::info(summary.str());
    return 0;
}

} // namespace

const Command& tile_command() {
    static const Command command{
        {"tile",
         "INPUT... Z X Y -o OUT.{glb,drc,obj,tif}",
         "Make one tile (tile raster, mesh, or encoded tile) to a file.",
         {
             {"o", "OUT", "output file; its extension picks the type (overwritten)"},
             {"scheme", "NAME", "geodetic (EPSG:4326, TMS, default) or mercator (EPSG:3857, XYZ)"},
             {"eps", "E", "vertical error bound in metres (default: the zoom's ladder eps)"},
             {"size", "N", "tile raster of (N+1) x (N+1) samples (default 256)"},
             {"datum", "NAME", "source heights: auto (default), egm96 or ellipsoid"},
             {"nodata", "V", "raw sample value to treat as nodata, replacing the file's own"},
             {"effort",
              "LEVEL",
              "mesher effort: fast, balanced (default) or best; the same bound at each, best the "
              "fewest triangles"},
             {"summary-dir", "DIR", kSummaryDirHelp},
             {"valid-range", "MIN,MAX", kValidRangeHelp},
             {"priority", "finest|listed", kPriorityHelp},
         },
         "Outputs: .glb (glTF + Draco, ECEF), .drc (Draco, local ENU), .obj (the mesh in the\n"
         "grid coordinates of the samples it was meshed on: v column row height, heights above\n"
         "the WGS84 ellipsoid; border vertices sit between samples) and .tif (those samples\n"
         "exactly as meshed: the source's own pixels, or the zoom's lattice; Float32, voids in\n"
         "the mask band). Several INPUTs\n"
         "are mosaicked. Z X Y outside the scheme is an error (exit 2); a tile without data\n"
         "is reported as not found (exit 2)."},
        run};
    return command;
}

} // namespace tb::cli
