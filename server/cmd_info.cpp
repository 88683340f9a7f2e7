// terrabound info: what a DEM is.
#include "core/error.hpp"
#include "server/commands.hpp"
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/source_list.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>

namespace tb::cli {
namespace {

// Collections of more files than this are described as a whole unless --each is given.
constexpr std::size_t kDescribedFiles = 8;

std::string describe(const tiler::DemInfo& d) {
    std::ostringstream out;
    out.precision(10);
    out << d.path << "\n";
    out << "  format:      " << d.driver << "\n";
    out << "  size:        " << d.width << " x " << d.height << " samples, " << d.bands
        << " band(s); band 1 is used\n";
    out << "  data type:   " << d.data_type << "\n";
    out << "  crs:         ";
    if (d.crs_name.empty()) {
        out << "none (no georeferencing)\n";
    } else {
        out << d.crs_name << (d.crs_id.empty() ? " (not identified as an EPSG code)" : "")
            << (d.crs_id.empty() ? "" : " (" + d.crs_id + ")") << "\n";
    }
    out << "  nodata:      ";
    if (d.nodata) {
        out << *d.nodata << "\n";
    } else {
        out << "none\n";
    }
    if (d.scale != 1.0 || d.offset != 0.0) {
        out << "  scale:       " << d.scale << ", offset " << d.offset
            << (d.metres_per_unit != 1.0 ? " (to metres)\n" : "\n");
    }
    out << "  heights:     ";
    if (d.has_data) {
        out << d.min_height << " .. " << d.max_height << " m";
        if (d.metres_per_unit != 1.0) {
            out << " (the file's unit: " << d.height_unit << ", " << d.metres_per_unit
                << " m each)";
        }
        out << (d.range_exact ? "\n" : " (approximate: too large to read whole)\n");
    } else {
        out << "no valid sample (every sample is nodata)\n";
    }
    if (d.outliers > 0) {
        out << "  outliers:    " << (d.range_exact ? "" : "at least ") << d.outliers
            << " sample(s) outside " << d.valid_range.low << " .. " << d.valid_range.high
            << " m count as nodata (first: " << d.outlier_height << " m at pixel "
            << d.outlier_column << ", " << d.outlier_row << ")\n";
    }
    if (d.likely_nodata && !d.nodata_given) {
        out << "  warning:     " << 100 * d.likely_nodata_share << "% of the samples are "
            << *d.likely_nodata << ", far from all the others (" << d.others_min << " .. "
            << d.others_max << "): likely voids not declared as nodata; pass --nodata "
            << *d.likely_nodata << "\n";
    }
    if (d.has_geotransform) {
        const auto& g = d.geotransform;
        out << "  pixel size:  " << std::abs(g[1]) << " x " << std::abs(g[5])
            << (d.geographic ? " degrees" : " CRS units");
        if (d.resolution_m > 0) {
            out << " (about " << std::round(d.resolution_m * 10) / 10 << " m)";
        }
        out << "\n";
        out << "  origin:      " << g[0] << ", " << g[3] << "\n";
    } else {
        out << "  pixel size:  unknown (no geotransform)\n";
    }
    if (d.lonlat_bounds) {
        const auto& b = *d.lonlat_bounds;
        out << "  lon/lat:     west " << b[0] << ", south " << b[1] << ", east " << b[2]
            << ", north " << b[3] << "\n";
    }
    return out.str();
}

// What a zoom's tiles read of the source: "full resolution", "every 4th pixel",
// "overview 2 (1/3.99)", "overview 4 (1/15.9), every 2nd pixel" (overviews numbered from 1).
std::string describe_read(const tiler::ReadLevel& level) {
    std::string text;
    if (level.overview < 0) {
        text = level.step == 1 ? "full resolution" : "";
    } else {
        char factor[32];
        std::snprintf(factor, sizeof factor, "%.3g", level.factor);
        text = "overview " + std::to_string(level.overview + 1) + " (1/" + factor + ")";
    }
    if (level.step > 1) {
        const char* suffix = level.step % 10 == 2 && level.step % 100 != 12 ? "nd" : "th";
        text +=
            (text.empty() ? "every " : ", every ") + std::to_string(level.step) + suffix + " pixel";
    }
    return text;
}

// What zoom z's tiles read, for the plan's last column.
std::string describe_zoom(const tiler::Layer& layer, int z) {
    const auto& o = layer.options();
    switch (layer.zoom_source(z)) {
    case tiler::ZoomSource::Pixels:
        return "full resolution (the DEM's pixels)";
    case tiler::ZoomSource::Summary:
        return "the summary's planes, judged by its blocks";
    case tiler::ZoomSource::Summaries:
        return "each DEM's summary where it serves the zoom, judged by its blocks; the other "
               "DEMs at full resolution";
    case tiler::ZoomSource::Lattice:
        break;
    }
    if (layer.source().parts().size() > 1) {
        return "each DEM at its own level, checked at full resolution";
    }
    return describe_read(layer.source().read_level(o.scheme, z, o.tile_size)) +
           ", checked at full resolution";
}

// A collection's groups and how they rank: the first with a valid pixel wins at each point.
std::string describe_ranks(const tiler::DemSource& source, tiler::SourcePriority priority) {
    std::ostringstream out;
    out.precision(6);
    const auto parts = source.parts();
    std::size_t files = 0;
    for (const auto& part : parts) {
        files += std::max<std::size_t>(part->files.size(), 1);
    }
    out << "collection of " << files << (files == 1 ? " file" : " files") << " in " << parts.size()
        << (parts.size() == 1 ? " DEM group" : " DEM groups");
    if (parts.size() > 1) {
        out << ", ranked " << to_string(priority)
            << " (where they overlap the first with data wins; the others fill its voids)";
    }
    out << ":\n";
    for (std::size_t k = 0; k < parts.size(); ++k) {
        const tiler::DemInfo& d = *parts[k];
        out << "  " << k + 1 << ". " << d.path << ": ";
        if (d.files.size() > 1) {
            out << d.files.size() << " files, ";
        }
        out << d.resolution_m << " m pixels, " << (d.crs_id.empty() ? d.crs_name : d.crs_id);
        if (d.lonlat_bounds) {
            const auto& b = *d.lonlat_bounds;
            out << ", lon " << b[0] << " .. " << b[2] << ", lat " << b[1] << " .. " << b[3];
        }
        out << "\n";
    }
    return out.str();
}

// The pyramid a layer of these DEMs would have: zooms, tiles per zoom, eps per zoom, and what
// each zoom reads of the source.
std::string describe_pyramid(const tiler::LayerOptions& options) {
    std::ostringstream out;
    out.precision(6);
    std::shared_ptr<const tiler::Layer> layer;
    try {
        layer = tiler::Layer::open(options);
    } catch (const InputError& e) {
        out << "  pyramid:     none (" << e.what() << ")\n";
        return out.str();
    }
    if (options.sources.size() > 1) {
        out << describe_ranks(layer->source(), options.priority);
    }
    const auto& o = layer->options();
    const auto b = layer->data_bounds();
    out << "  pyramid:     " << to_string(o.scheme) << ", " << o.tile_size
        << "-sample tiles, zooms " << layer->min_zoom() << ".." << layer->max_zoom() << ", heights "
        << to_string(layer->source_datum()) << " -> WGS84 ellipsoid (" << layer->min_height()
        << " .. " << layer->max_height() << " m)\n";
    out << "  footprint:   west " << b.west << ", south " << b.south << ", east " << b.east
        << ", north " << b.north << " (pixel centres)\n";
    const bool pixels = layer->guarantee() == tiler::Guarantee::SourcePixels;
    out << "  guarantee:   "
        << (pixels ? "tiles of the DEM's own zoom are meshed on its pixel centres, so their eps "
                     "holds by construction; coarser tiles are meshed on the zoom's lattice and "
                     "judged against every valid pixel under them, one by one or as blocks of "
                     "the DEM's summary, and publish the larger of eps and what that measures"
                   : "measured: tiles are meshed on each zoom's lattice in the scheme's CRS and "
                     "checked at every valid source pixel centre (reprojected), or at coarse "
                     "zooms against the blocks of the DEM's summary carried through its CRS; a "
                     "tile whose measured error exceeds eps publishes the larger bound")
        << "\n";
    out << "    zoom  tiles       columns x rows      eps (m)     reads\n";
    for (int z = layer->min_zoom(); z <= layer->max_zoom(); ++z) {
        const tiler::TileRange r = layer->tiles_at(z);
        char line[192];
        std::snprintf(line,
                      sizeof line,
                      "    %4d  %-10lld  %8lld x %-8lld  %-10g  %s\n",
                      z,
                      static_cast<long long>(layer->tile_count_at(z)),
                      static_cast<long long>(r.x1 - r.x0 + 1),
                      static_cast<long long>(r.y1 - r.y0 + 1),
                      layer->eps_for_zoom(z),
                      describe_zoom(*layer, z).c_str());
        out << line;
    }
    return out.str();
}

int run(const Args& args) {
    if (args.positional.empty()) {
        throw InputError("info: name a DEM file; see 'terrabound info --help'");
    }
    const tiler::Scheme scheme = tiler::parse_scheme(args.get("scheme").value_or("geodetic"));
    std::optional<double> nodata;
    if (args.has("nodata")) {
        nodata = args.get_double("nodata", 0);
    }
    tiler::ValidRange range;
    if (auto v = args.get("valid-range")) {
        range = tiler::parse_valid_range(*v, "info: --valid-range");
    }
    tiler::LayerOptions options;
    options.scheme = scheme;
    options.nodata = nodata;
    options.summary_dir = args.get("summary-dir").value_or("");
    options.valid_range = range;
    if (auto v = args.get("priority")) {
        options.priority = tiler::parse_source_priority(*v, "info: --priority");
    }
    const std::vector<std::string> paths = tiler::expand_dem_inputs(args.positional);
    const bool each = paths.size() <= kDescribedFiles || args.has("each");
    if (!each) {
        std::printf("%zu DEM files, the first %s (each described with --each)\n",
                    paths.size(),
                    paths.front().c_str());
    }
    for (std::size_t k = 0; each && k < paths.size(); ++k) {
        std::fputs(describe(tiler::inspect_dem(paths[k], tiler::kExactRangeSamples, nodata, range))
                       .c_str(),
                   stdout);
    }
    options.sources = paths; // one DEM or one collection: one pyramid
    std::fputs(describe_pyramid(options).c_str(), stdout);
    return 0;
}

} // namespace

const Command& info_command() {
    static const Command command{
        {"info",
         "DEM...",
         "Describe a DEM: size, CRS, data type, nodata, height range, resolution, pyramid;\n"
         "several DEMs: each of them (up to 8, or --each), then their groups (files of one\n"
         "CRS and pixel size), how the groups rank, and the pyramid of them together.",
         {{"scheme", "NAME", "pyramid plan for geodetic (default) or mercator tiles"},
          {"nodata", "V", "raw sample value to treat as nodata, replacing the file's own"},
          {"summary-dir", "DIR", kSummaryDirHelp},
          {"valid-range", "MIN,MAX", kValidRangeHelp},
          {"priority", "finest|listed", kPriorityHelp},
          {"each", "", "describe every file of a collection of more than 8 (default: the whole)"}},
         "The pyramid plan is what 'terrabound build' and 'serve' make of the DEM alone with\n"
         "default options: zoom range, tiles per zoom, each zoom's eps (metres), how that eps\n"
         "is made true at the DEM's own pixels (the guarantee), and what its tiles read: the\n"
         "DEM's pixels at full resolution (the finest zoom of lon/lat DEMs, and of EPSG:3857\n"
         "ones for mercator), the DEM's multi-resolution summary (zooms whose lattice step\n"
         "spans 8 pixels or more), or every 2^k-th pixel or an overview, checked at full\n"
         "resolution (the zooms between, and every zoom of a DEM in another CRS). The eps of\n"
         "zooms read from the summary follows the data's roughness there, so info makes the\n"
         "summary (kept on disk for DEMs of 16 Mpixel and more, see --summary-dir)."},
        run};
    return command;
}

} // namespace tb::cli
