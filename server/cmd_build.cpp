// terrabound build: pre-generate a layer's tile pyramid into a directory or an SQLite file.
// The work is tiler/pyramid/build.cpp; this file parses options, handles SIGINT/SIGTERM and
// reports.
#include "config/config.hpp"
#include "core/error.hpp"
#include "server/commands.hpp"
#include "tiler/dem_tiles.hpp"
#include "tiler/log.hpp"
#include "tiler/pyramid/build.hpp"
#include "tiler/pyramid/convert.hpp"
#include "tiler/stores/store.hpp"

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <string>
#include <vector>

namespace tb::cli {
namespace {

std::atomic<bool> g_stop{false};
std::atomic<int> g_signal{0};

extern "C" void on_signal(int sig) {
    g_signal.store(sig);
    g_stop.store(true);
}

std::vector<std::string> split(const std::string& text, char sep) {
    std::vector<std::string> parts;
    std::string part;
    for (char c : text) {
        if (c == sep) {
            parts.push_back(part);
            part.clear();
        } else {
            part += c;
        }
    }
    parts.push_back(part);
    return parts;
}

tiler::LonLatBox parse_bbox(const std::string& text) {
    const auto parts = split(text, ',');
    if (parts.size() != 4) {
        throw InputError("build: --bbox '" + text + "': expected W,S,E,N (four numbers, degrees)");
    }
    tiler::LonLatBox b;
    b.west = to_double(parts[0], "--bbox west");
    b.south = to_double(parts[1], "--bbox south");
    b.east = to_double(parts[2], "--bbox east");
    b.north = to_double(parts[3], "--bbox north");
    return b;
}

std::vector<tiler::Format> parse_formats(const std::string& text) {
    std::vector<tiler::Format> formats;
    for (const auto& name : split(text, ',')) {
        const auto f = tiler::parse_format(name);
        if (!f) {
            throw InputError(
                "build: --formats: unknown format '" + name +
                "'; expected a comma-separated list of glb, drc, terrarium, mapbox, terrain, "
                "terrain3d");
        }
        formats.push_back(*f);
    }
    return formats;
}

int to_zoom(const Args& args, const std::string& name) {
    const long long z = args.get_int(name, 0);
    if (z < 0 || z > tiler::kMaxZoom) {
        throw InputError("build: --" + name + " " + std::to_string(z) + ": expected 0.." +
                         std::to_string(tiler::kMaxZoom));
    }
    return static_cast<int>(z);
}

std::string human_bytes(std::int64_t bytes) {
    char buf[32];
    const double b = static_cast<double>(bytes);
    if (b >= 1e9) {
        std::snprintf(buf, sizeof buf, "%.2f GB", b / 1e9);
    } else if (b >= 1e6) {
        std::snprintf(buf, sizeof buf, "%.1f MB", b / 1e6);
    } else {
        std::snprintf(buf, sizeof buf, "%.1f kB", b / 1e3);
    }
    return buf;
}

// What a build makes without --formats: what serve serves its clients (3D Tiles, globe terrain
// in both providers' formats, raster DEM), leaving out drc and mapbox, which only some clients
// want instead of glb and terrarium; a single-file DEM container holds terrarium.
std::vector<tiler::Format> default_formats(const std::string& output) {
    const bool container = output.ends_with(".mbtiles") || output.ends_with(".pmtiles");
    if (container) {
        return {tiler::Format::Terrarium};
    }
    return {tiler::Format::Glb,
            tiler::Format::Terrain,
            tiler::Format::Terrain3d,
            tiler::Format::Terrarium};
}

// First SIGINT/SIGTERM: finish the tiles in flight and stop cleanly. The handler resets
// itself, so a second one stops at once (atomic writes keep the store valid even then).
void catch_stop_signals() {
    struct sigaction action {};
    action.sa_handler = on_signal;
    action.sa_flags = SA_RESETHAND;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGTERM, &action, nullptr);
}

// `build STORE.sqlite -o OUT.pmtiles`: copies one layer's DEM tiles into the container
// (tiler/pyramid/convert.hpp). Options that decide how tiles are made do not apply.
int run_convert(const Args& args, const std::string& output) {
    for (const auto& given : args.values) {
        if (given.first != "o" && given.first != "layer" && given.first != "formats") {
            throw InputError("build: --" + given.first + " does not apply when converting " +
                             args.positional[0] +
                             " (its tiles are copied as they are); drop it, or build from the "
                             "DEM instead");
        }
    }
    for (const auto& flag : args.flags) {
        if (flag != "force" && flag != "json") {
            throw InputError("build: --" + flag + " does not apply when converting " +
                             args.positional[0] + " (a conversion is not resumed or sharded: " +
                             "run it again, with --force to replace OUT)");
        }
    }
    tiler::ConvertOptions o;
    o.input = args.positional[0];
    o.output = output;
    o.layer = args.get("layer").value_or("");
    o.force = args.has("force");
    if (auto v = args.get("formats")) {
        const auto formats = parse_formats(*v);
        if (formats.size() != 1) {
            throw InputError("build: --formats " + *v +
                             ": a container holds one DEM encoding; convert --formats terrarium "
                             "or --formats mapbox, one file each");
        }
        o.format = formats[0];
    }
    catch_stop_signals();
    const tiler::ConvertSummary c = tiler::convert_store(o, g_stop);
    if (c.interrupted) {
        std::fprintf(stderr,
                     "terrabound: conversion interrupted; %s was not written; run it again\n",
                     o.output.c_str());
        return 128 + (g_signal.load() ? g_signal.load() : SIGINT);
    }
    char seconds[32];
    std::snprintf(seconds, sizeof seconds, "%.1f", c.seconds);
    log::info("build: converted " + std::to_string(c.tiles) + " " + format_name(c.format) +
              " DEM tiles of layer " + c.layer + ", " + human_bytes(c.bytes) + ", into " +
              o.output + ", " + seconds + " s");
    if (args.has("json")) {
        tiler::BuildSummary s;
        s.planned = s.written = s.dem_written = c.tiles;
        s.bytes = c.bytes;
        s.seconds = c.seconds;
        std::printf("%s\n", tiler::to_json(s).c_str());
        std::fflush(stdout);
    }
    return 0;
}

int run(const Args& args) {
    tiler::BuildOptions o;
    o.layer.sources = args.positional;
    if (o.layer.sources.empty()) {
        throw InputError("build: name at least one DEM; see 'terrabound build --help'");
    }
    const auto out = args.get("o");
    if (!out) {
        throw InputError("build: name the output with -o OUT (a directory, or a file ending in "
                         ".sqlite)");
    }
    const auto& inputs = o.layer.sources;
    if (std::any_of(inputs.begin(), inputs.end(), tiler::is_store_input)) {
        if (inputs.size() != 1) {
            throw InputError("build: a .sqlite or .db input is a Terrabound store to convert, and "
                             "is converted alone; name it as the only input");
        }
        return run_convert(args, *out);
    }
    o.output = *out;
    // Named as `serve DEM` names it, so the URLs of a static copy are the server's.
    o.layer.name = config::layer_name_from_path(o.layer.sources[0]);
    if (o.layer.name.empty()) {
        o.layer.name = "terrain";
    }
    if (auto v = args.get("layer")) {
        o.layer.name = *v;
    }
    if (auto v = args.get("scheme")) {
        o.layer.scheme = tiler::parse_scheme(*v);
    }
    if (args.has("size")) {
        const long long n = args.get_int("size", 0);
        if (n < 2 || n > 4096) {
            throw InputError("build: --size " + std::to_string(n) + ": expected 2..4096");
        }
        o.layer.tile_size = static_cast<int>(n);
    }
    if (args.has("min-zoom")) {
        o.layer.min_zoom = to_zoom(args, "min-zoom");
    }
    if (args.has("max-zoom")) {
        o.layer.max_zoom = to_zoom(args, "max-zoom");
    }
    if (o.layer.min_zoom && o.layer.max_zoom && *o.layer.min_zoom > *o.layer.max_zoom) {
        throw InputError("build: --min-zoom " + std::to_string(*o.layer.min_zoom) +
                         " is above --max-zoom " + std::to_string(*o.layer.max_zoom));
    }
    if (args.has("eps-finest")) {
        o.layer.finest_eps = args.get_double("eps-finest", 0);
    }
    if (args.has("nodata")) {
        o.layer.nodata = args.get_double("nodata", 0);
    }
    if (auto v = args.get("effort")) {
        o.layer.effort = core::parse_effort(*v);
    }
    o.layer.summary_dir = args.get("summary-dir").value_or("");
    if (auto v = args.get("valid-range")) {
        o.layer.valid_range = tiler::parse_valid_range(*v, "build: --valid-range");
    }
    if (auto v = args.get("priority")) {
        o.layer.priority = tiler::parse_source_priority(*v, "build: --priority");
    }
    if (auto v = args.get("bbox")) {
        o.bbox = parse_bbox(*v);
    }
    o.formats = default_formats(o.output);
    if (auto v = args.get("formats")) {
        o.formats = parse_formats(*v);
    }
    if (auto v = args.get("base-url")) {
        if (!(v->starts_with("http://") || v->starts_with("https://") || v->starts_with("/"))) {
            throw InputError("build: --base-url '" + *v +
                             "': expected where OUT will be hosted, starting with http://, "
                             "https:// or / (e.g. https://example.com/tiles)");
        }
        o.base_url = *v;
    }
    if (auto v = args.get("terrain-extensions")) {
        o.terrain_extensions = tiler::parse_terrain_extensions(*v);
    }
    if (args.has("dem-size")) {
        const long long n = args.get_int("dem-size", 0);
        if (n != 256 && n != 512) {
            throw InputError("build: --dem-size " + std::to_string(n) + ": expected 256 or 512");
        }
        o.layer.dem_tile_size = static_cast<int>(n);
    }
    if (auto v = args.get("dem-heights")) {
        o.layer.dem_heights = tiler::parse_dem_heights(*v);
    }
    if (args.has("threads")) {
        const long long n = args.get_int("threads", 0);
        if (n < 1 || n > 1024) {
            throw InputError("build: --threads " + std::to_string(n) + ": expected 1..1024");
        }
        o.threads = static_cast<int>(n);
    }
    if (auto v = args.get("shard")) {
        o.shard = tiler::parse_shard(*v);
    }
    o.resume = args.has("resume");
    o.force = args.has("force");
    o.finalize = args.has("finalize");
    o.update = args.has("update");

    tiler::check_store_formats(o.output, o.formats); // a container holds one DEM encoding

    catch_stop_signals();
    const tiler::BuildSummary s = tiler::build_pyramid(o, g_stop);
    char seconds[32];
    std::snprintf(seconds, sizeof seconds, "%.1f", s.seconds);

    log::info(
        "build: " + std::to_string(s.written) + " tiles written" +
        (s.dem_written ? " (" + std::to_string(s.dem_written) + " of them DEM tiles), " : ", ") +
        std::to_string(s.skipped) + " skipped (already there), " + std::to_string(s.empty) +
        " empty, " + std::to_string(s.failed) + " failed, " +
        (o.update ? std::to_string(s.removed) + " removed, " : "") + human_bytes(s.bytes) + ", " +
        seconds + " s" + (s.tileset_written ? "; tileset written" : ""));
    if (args.has("json")) {
        std::printf("%s\n", tiler::to_json(s).c_str());
        std::fflush(stdout);
    }
    if (s.interrupted) {
        std::fprintf(stderr, "terrabound: build interrupted; run again with --resume\n");
        return 128 + (g_signal.load() ? g_signal.load() : SIGINT);
    }
    if (s.failed > 0) {
        std::fprintf(stderr,
                     "terrabound: build: %lld tile(s) failed (see the errors above); fix the "
                     "cause and run again with --resume\n",
                     static_cast<long long>(s.failed));
        return 1;
    }
    return 0;
}

} // namespace

const Command& build_command() {
    static const Command command{
        {"build",
         "INPUT... -o OUT [options]\n       terrabound build STORE.sqlite -o "
         "OUT.pmtiles|OUT.mbtiles "
         "[--layer NAME] [--formats terrarium|mapbox] [--force]",
         "Pre-generate a tile pyramid into a directory or a single file, or convert a store's "
         "DEM tiles into a container.",
         {
             {"o",
              "OUT",
              "output: a directory, a file ending in .sqlite (or .db), or OUT.mbtiles "
              "(MBTiles 1.3) "
              "or OUT.pmtiles (PMTiles v3) of one DEM encoding: --formats terrarium or mapbox"},
             {"layer",
              "NAME",
              "layer name, [A-Za-z0-9_-]+ (default: the first INPUT's file name, as serve names "
              "it: N44W072.hgt -> N44W072)"},
             {"scheme", "S", "geodetic (default) or mercator"},
             {"size", "N", "tile raster is (N+1) x (N+1) samples (default 256)"},
             {"min-zoom", "Z", "coarsest zoom (default: from the sources)"},
             {"max-zoom", "Z", "finest zoom (default: from the sources' resolution)"},
             {"eps-finest", "E", "vertical error bound at max zoom, metres; doubles per level up"},
             {"bbox", "W,S,E,N", "only tiles meeting this box, degrees (no tileset is written)"},
             {"formats",
              "LIST",
              "comma-separated: glb, drc, terrarium, mapbox, terrain, terrain3d (default "
              "glb,terrain,terrain3d,terrarium: what CesiumJS, three.js, deck.gl and MapLibre "
              "read; terrarium alone for .mbtiles and .pmtiles); "
              "terrarium and mapbox are PNG DEM tiles (EPSG:3857 XYZ) under OUT/{layer}/dem/; "
              "terrain is quantized-mesh with OUT/{layer}/layer.json, terrain3d 3D Tiles "
              "terrain with OUT/{layer}/terrain/tileset.json (both geodetic, from zoom 0)"},
             {"base-url",
              "URL",
              "where OUT will be hosted (https://example.com/tiles): the DEM TileJSON lists "
              "absolute tile URLs, which MapLibre needs (default: relative to the TileJSON)"},
             {"terrain-extensions",
              "LIST",
              "quantized-mesh extensions each .terrain tile holds and layer.json lists: "
              "metadata (default), octvertexnormals, watermask, comma-separated, or all or none; "
              ".terrain files are stored gzip-compressed (send them with Content-Encoding: "
              "gzip)"},
             {"dem-size", "P", "DEM tiles are P x P pixels, 256 or 512 (default 512)"},
             {"dem-heights", "H", "DEM tile heights: sea_level (default) or ellipsoid"},
             {"nodata", "V", "raw sample value to treat as nodata, replacing the file's own"},
             {"effort",
              "LEVEL",
              "mesher effort: fast, balanced (default) or best; the same bound at each, best the "
              "fewest triangles"},
             {"summary-dir", "DIR", kSummaryDirHelp},
             {"valid-range", "MIN,MAX", kValidRangeHelp},
             {"priority", "finest|listed", kPriorityHelp},
             {"threads", "N", "worker threads (default: one per usable core)"},
             {"resume", "", "continue a build: same parameters, tiles already there are kept"},
             {"update",
              "",
              "after DEMs were added, replaced or removed: remake only the tiles they touch "
              "(and their ancestors), remove those left without data; the result is what a "
              "full build makes"},
             {"force", "", "delete the layer's existing tiles and documents first"},
             {"shard",
              "I/N",
              "build shard I of N (0-based; auto/N reads JOB_COMPLETION_INDEX "
              "or SLURM_ARRAY_TASK_ID); implies --resume"},
             {"finalize", "", "after all shards: check they finished, then write the tileset"},
             {"json", "", "also print the summary as one JSON line on stdout"},
         },
         "Tiles are written atomically and the tileset last, so a build can be killed at any\n"
         "time and continued with --resume. Ctrl-C (SIGINT) or SIGTERM finishes the tiles in\n"
         "flight and exits with 130/143; a second one stops at once. Without --resume or\n"
         "--force an existing layer in OUT is an error. Sharded builds: run every shard I/N\n"
         "against the same OUT (a shared directory, or one SQLite file on one machine), then\n"
         "once 'terrabound build ... --finalize' with the same parameters. --update follows\n"
         "changed DEMs (it works with --shard too: run every shard with --update, then\n"
         "--finalize); an interrupted update is finished by running it again. One build writes "
         "OUT\n"
         "at a time (the shards of one build together): another is refused at once, naming the\n"
         "holder's pid and host. The lock is OUT/.build.lock (OUT.sqlite.build.lock beside an\n"
         "SQLite file), gone once the build ends; a killed build's lock is taken over.\n"
         "Outputs, under OUT/{layer}/ (the server's URLs): tileset.json and {z}/{x}/{y}.glb\n"
         "(or .drc); layer.json and {z}/{x}/{y}.terrain (gzip-compressed); terrain/tileset.json\n"
         "with its subtrees and glbs; dem/tilejson.json and dem/{z}/{x}/{y}.png (terrarium),\n"
         "dem/mapbox/... (mapbox); build-manifest.json. In a directory also OUT/_headers and\n"
         "OUT/terrabound-nginx.conf: how a static host must send the files.\n"
         "Converting: an INPUT ending in .sqlite or .db is a Terrabound SQLite store, whose\n"
         "raster DEM tiles of one layer in one encoding are copied as they are (each checked\n"
         "against its checksum) into OUT.mbtiles or OUT.pmtiles, with the metadata a build\n"
         "straight into it writes. --layer and --formats choose when the store holds several\n"
         "(an error lists what it holds); only a finished build is converted. OUT appears\n"
         "whole or not at all (an interrupted conversion leaves nothing); --force replaces it."},
        run};
    return command;
}

} // namespace tb::cli
