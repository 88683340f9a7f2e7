#pragma once
// The server configuration: a JSON file (schema in docs/serving.md, "Configuration") read into plain
// structs. Only config/config.cpp sees nlohmann-json.
//
// Every problem in a file is collected and reported together, one line each, with the JSON
// pointer of the offending value:
//   config.json: /layers/0/finest_eps: expected a number > 0, got -1
#include "tiler/formats/format.hpp"
#include "tiler/layer.hpp"

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

namespace tb::config {

// The smallest memory budget (ServerConfig::memory_mb) but none: a quarter of it, GDAL's block
// cache, still holds a few hundred blocks.
inline constexpr std::size_t kMinMemoryMb = 64;
inline constexpr int kMaxWatchIntervalS = 86400;
inline constexpr std::size_t kMaxMemoryMb = std::size_t{1} << 20; // 1 TiB, as cache_mb

struct ServerConfig {
    std::string host = "127.0.0.1";
    int port = 8080;
    int threads = 0;                               // tile generation threads; 0 = one per core
    std::size_t cache_mb = 256;                    // in-memory tile cache, MiB (0 disables it)
    std::vector<std::string> cors_origins = {"*"}; // Access-Control-Allow-Origin values
    std::string log_level = "info";                // debug | info | warn | error | off
    int queue_limit = 64;             // generations allowed to wait for a thread; past it: 503
    std::string metrics = "loopback"; // who may read /metrics: loopback | on | off
    // The process's memory budget, MiB; 0: none. GDAL's block cache gets a quarter, and the tile
    // cache at most half (cache_mb is capped to it).
    std::size_t memory_mb = 0;
    // How long a tile request waits for its generation to start; past it: 503 with Retry-After
    // (TileServiceOptions::start_wait says why 10 s).
    int start_wait_ms = 10000;
    // How long a tile request may take in all; past it: 503 with Retry-After, and a generation
    // no request waits for any more stops (TileServiceOptions::deadline). At least start_wait_ms.
    int deadline_ms = 10000;
    // How often serve checks its layers' source files (size and modification time) and reloads
    // a layer whose sources changed, in seconds; 0: only on SIGHUP.
    int watch_interval_s = 5;
};

struct LayerConfig {
    tiler::LayerOptions options; // sources already resolved against the config's dir
    std::vector<tiler::Format> formats = {tiler::Format::Glb,
                                          tiler::Format::Drc,
                                          tiler::Format::Terrarium,
                                          tiler::Format::Mapbox,
                                          tiler::Format::Terrain,
                                          tiler::Format::Terrain3d};
    std::optional<std::string> store; // directory or *.sqlite / *.db; none: memory only
};

struct Config {
    ServerConfig server;
    std::vector<LayerConfig> layers;
};

// Parses and validates `text`, the contents of the file `path` (used in messages and to
// resolve relative source and store paths against its directory). Checks unknown keys, types,
// ranges, duplicate layer names and that every local source file exists. Throws InputError
// whose message lists every problem, one per line.
Config parse_config(const std::string& text, const std::string& path);

// Reads `path` and parses it. Throws InputError when it cannot be read or is invalid.
Config load_config(const std::string& path);

// A URL-safe layer name ([A-Za-z0-9_-]+) derived from a DEM path: "data/N57E011.hgt" ->
// "N57E011", "my dem (v2).tif" -> "my_dem_v2". Never empty.
std::string layer_name_from_path(const std::string& path);

// What is wrong with a host to listen on, or nullopt when it is usable: an IPv4 address (four
// numbers 0..255), an IPv6 address, or a host name (letters, digits and '-' in '.'-separated
// parts of 1..63 characters). The text reads after "host: ".
std::optional<std::string> host_problem(const std::string& host);

// True when `name` is a valid layer name: 1..64 characters of [A-Za-z0-9_-].
bool is_valid_layer_name(const std::string& name);

} // namespace tb::config
