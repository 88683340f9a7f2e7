#pragma once
// What a static web host needs beside a built directory, so that clients read it with no code of
// their own: the headers of every file kind (media type, Content-Encoding of the gzip-stored
// .terrain tiles, CORS, caching) as an nginx snippet and as a _headers file (Netlify, Cloudflare
// Pages), and the raster DEM tiles' TileJSON documents.
#include "tiler/formats/format.hpp"
#include "tiler/layer.hpp"
#include "tiler/stores/store.hpp"

#include <string>
#include <vector>

namespace tb::tiler {

// How a host sends the files of one extension.
struct HostRule {
    std::string extension;     // "terrain", "glb", ... (no dot)
    std::string media_type;    // Content-Type
    std::string encoding;      // Content-Encoding, empty for none
    std::string cache_control; // Cache-Control
};

// One rule per kind of file a directory store holds (tiles, subtrees, documents).
const std::vector<HostRule>& host_rules();

struct HostFile {
    std::string name; // at the output's root
    std::string text;
};

// "terrabound-nginx.conf" (to include in the server block whose root is the output) and
// "_headers" (Netlify and Cloudflare Pages, publishing the output as the site's root).
std::vector<HostFile> host_files();

// Writes host_files() into the output directory `dir`, each atomically. IoError naming the file.
void write_host_files(const std::string& dir);

// TileJSON 3.0.0 of the layer's raster DEM tiles in `encoding` (terrarium or mapbox), as
// MapLibre's raster-dem source reads it (encoding, tileSize, zooms, the data's bounds), listing
// `tiles_url` (a template with {z}, {x} and {y}).
std::string dem_tilejson(const Layer& layer, Format encoding, const std::string& tiles_url);

// Where a static build keeps the TileJSON of `encoding`, beside its tiles:
// "dem/tilejson.json" (terrarium) or "dem/mapbox/tilejson.json".
std::string dem_tilejson_name(Format encoding);

// The TileJSON a static build writes for `encoding`: its tiles at
// "{base_url}/{layer}/dem[/mapbox]/{z}/{x}/{y}.png", or, without a base URL, relative to the
// TileJSON itself ("{z}/{x}/{y}.png"; MapLibre resolves tile URLs against the page, not the
// TileJSON, so it needs the base URL).
std::string static_dem_tilejson(const Layer& layer, Format encoding, const std::string& base_url);

} // namespace tb::tiler
