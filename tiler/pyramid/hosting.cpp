#include "tiler/pyramid/hosting.hpp"

#include "tiler/dem_tiles.hpp"
#include "tiler/json_number.hpp"
#include "tiler/stores/atomic_file.hpp"

#include <filesystem>

namespace tb::tiler {
namespace {

// Tiles never change under one URL (another eps or source is another build), so clients may
// keep them a week, as `serve` says; documents name the tiles and may be rebuilt: a minute.
constexpr const char* kTileCache = "public, max-age=604800";
constexpr const char* kDocumentCache = "public, max-age=60";

std::string nginx_location(const HostRule& r) {
    std::string out = "location ~ \\." + r.extension + "$ {\n";
    out += "    types { }\n    default_type " + r.media_type + ";\n";
    if (!r.encoding.empty()) {
        // Stored compressed: nginx must neither compress it again nor guess otherwise.
        out += "    gzip off;\n    add_header Content-Encoding " + r.encoding + ";\n";
    }
    out += "    add_header Cache-Control \"" + r.cache_control + "\";\n";
    out += "    add_header Access-Control-Allow-Origin * always;\n";
    out += "    add_header Access-Control-Expose-Headers \"ETag, Content-Length, "
           "Content-Encoding\" always;\n";
    out += "    if ($request_method = OPTIONS) {\n"
           "        add_header Access-Control-Allow-Origin *;\n"
           "        add_header Access-Control-Allow-Methods \"GET, HEAD, OPTIONS\";\n"
           "        add_header Access-Control-Allow-Headers *;\n"
           "        add_header Access-Control-Max-Age 86400;\n"
           "        return 204;\n"
           "    }\n";
    return out + "}\n";
}

std::string nginx_snippet() {
    std::string out =
        "# Terrabound: how nginx sends a static copy of this build (written by terrabound build).\n"
        "# Include it in the server block whose root is this directory:\n"
        "#   server { listen 80; root /srv/tiles; include /srv/tiles/terrabound-nginx.conf; }\n"
        "# .terrain files are stored gzip-compressed and go out as they are, with\n"
        "# Content-Encoding: gzip (CesiumJS needs it); hidden files (checksums, locks) are not\n"
        "# served.\n"
        "location ~ /\\. {\n    return 404;\n}\n";
    for (const HostRule& r : host_rules()) {
        out += nginx_location(r);
    }
    return out;
}

std::string headers_file() {
    std::string out =
        "# Terrabound: the headers of a static copy of this build (written by terrabound build),\n"
        "# for Netlify and Cloudflare Pages: publish this directory as the site's root.\n"
        "# .terrain files are stored gzip-compressed: they must go out with Content-Encoding: "
        "gzip.\n"
        "/*\n  Access-Control-Allow-Origin: *\n";
    for (const HostRule& r : host_rules()) {
        out += "/*." + r.extension + "\n  Content-Type: " + r.media_type + "\n";
        if (!r.encoding.empty()) {
            out += "  Content-Encoding: " + r.encoding + "\n";
        }
        out += "  Cache-Control: " + r.cache_control + "\n";
    }
    return out;
}

} // namespace

const std::vector<HostRule>& host_rules() {
    static const std::vector<HostRule> rules = {
        {"terrain", media_type(Format::Terrain), "gzip", kTileCache},
        {"glb", media_type(Format::Glb), "", kTileCache},
        {"drc", media_type(Format::Drc), "", kTileCache},
        {"png", media_type(Format::Terrarium), "", kTileCache},
        {"subtree", "application/octet-stream", "", kTileCache},
        {"json", "application/json", "", kDocumentCache},
    };
    return rules;
}

std::vector<HostFile> host_files() {
    return {{"terrabound-nginx.conf", nginx_snippet()}, {"_headers", headers_file()}};
}

void write_host_files(const std::string& dir) {
    for (const HostFile& f : host_files()) {
        write_file_atomically((std::filesystem::path(dir) / f.name).string(), f.text);
    }
}

std::string dem_tilejson(const Layer& layer, Format encoding, const std::string& tiles_url) {
    const DemTilePlan plan = dem_tile_plan(layer);
    const LonLatBox& b = plan.bounds;
    return "{\"tilejson\":\"3.0.0\",\"name\":" + json_string(layer.options().name) +
           ",\"scheme\":\"xyz\",\"tiles\":[" + json_string(tiles_url) +
           "],\"minzoom\":" + std::to_string(plan.min_zoom) +
           ",\"maxzoom\":" + std::to_string(plan.max_zoom) + ",\"bounds\":[" + json_number(b.west) +
           "," + json_number(b.south) + "," + json_number(b.east) + "," + json_number(b.north) +
           "],\"center\":[" + json_number(0.5 * (b.west + b.east)) + "," +
           json_number(0.5 * (b.south + b.north)) + "," + std::to_string(plan.max_zoom) +
           "],\"encoding\":\"" + format_name(encoding) +
           "\",\"tileSize\":" + std::to_string(plan.tile_size) + "}\n";
}

std::string dem_tilejson_name(Format encoding) {
    return encoding == Format::Mapbox ? "dem/mapbox/tilejson.json" : "dem/tilejson.json";
}

std::string static_dem_tilejson(const Layer& layer, Format encoding, const std::string& base_url) {
    std::string url = "{z}/{x}/{y}.png";
    if (!base_url.empty()) {
        std::string base = base_url;
        while (!base.empty() && base.back() == '/') {
            base.pop_back();
        }
        const std::string name = dem_tilejson_name(encoding);
        url = base + "/" + layer.options().name + "/" +
              name.substr(0, name.size() - std::string("tilejson.json").size()) + url;
    }
    return dem_tilejson(layer, encoding, url);
}

} // namespace tb::tiler
