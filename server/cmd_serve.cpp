// terrabound serve: terrain tiles over HTTP, from a config file or from DEMs given directly.
#include "config/config.hpp"
#include "core/error.hpp"
#include "server/commands.hpp"
#include "server/http_server.hpp"
#include "server/layer_reload.hpp"
#include "server/metrics.hpp"
#include "server/tile_service.hpp"
#include "tiler/cpus.hpp"
#include "tiler/log.hpp"
#include "tiler/pyramid/tile_settings.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/source_list.hpp"
#include "tiler/stores/store.hpp"

#include <malloc.h>
#include <pthread.h>
#include <signal.h>
#include <time.h>

#include <cstdlib>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <filesystem>
#include <map>
#include <set>
#include <thread>

namespace tb::cli {
namespace {

// The viewer's directory: --web, else web/ beside the build directory (a source checkout), else
// the installed copy. Empty when none holds index.html and CesiumJS (setup installs it).
std::string find_web_root(const Args& args) {
    namespace fs = std::filesystem;
    if (auto dir = args.get("web")) {
        if (*dir == "none") {
            return "";
        }
        if (!fs::exists(fs::path(*dir) / "index.html")) {
            throw InputError("--web " + *dir +
                             ": no index.html there; name the viewer directory "
                             "(the repository's web/) or 'none'");
        }
        return fs::absolute(*dir).lexically_normal().string();
    }
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    std::vector<fs::path> candidates;
    if (!ec) {
        candidates.push_back(exe.parent_path().parent_path() / "web");
        candidates.push_back(exe.parent_path().parent_path() / "share" / "terrabound" / "web");
    }
    candidates.push_back(fs::current_path(ec) / "web");
    for (const auto& dir : candidates) {
        if (fs::exists(dir / "index.html", ec) &&
            fs::exists(dir / "node_modules" / "cesium" / "Build" / "Cesium" / "Cesium.js", ec)) {
            return fs::weakly_canonical(dir, ec).string();
        }
    }
    log::warn("viewer not found (web/index.html with web/node_modules/cesium); / shows a plain "
              "page. Run scripts/setup.sh, or pass --web DIR");
    return "";
}

bool ends_with(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// One layer per DEM with the defaults; names from the file names, made unique.
config::Config config_from_dems(const std::vector<std::string>& dems) {
    config::Config cfg;
    std::set<std::string> names;
    for (const auto& dem : dems) {
        config::LayerConfig layer;
        std::string name = config::layer_name_from_path(dem);
        for (int n = 2; names.count(name); ++n) {
            name = config::layer_name_from_path(dem) + "_" + std::to_string(n);
        }
        names.insert(name);
        layer.options.name = name;
        layer.options.sources = {dem};
        cfg.layers.push_back(std::move(layer));
    }
    return cfg;
}

// With a budget, malloc keeps at most this many arenas per generation thread (at least 2)
// unless MALLOC_ARENA_MAX says otherwise. glibc's default, 8 per core, gives each of the many
// HTTP and generation threads an arena of its own, and the freed pages of a tile's transient
// buffers stay in them: the load benchmark peaked at 1.22-1.28x memory_mb 512 so, and at 1.10x
// with 2 arenas (bench/README.md, "Load").
constexpr int kArenasPerThread = 1;

// Bounds malloc's arenas for a budget (see kArenasPerThread); returns the bound, 0 when left
// to glibc (no budget, or MALLOC_ARENA_MAX set).
int limit_malloc_arenas(const config::ServerConfig& server, int threads) {
    if (server.memory_mb == 0 || std::getenv("MALLOC_ARENA_MAX") != nullptr) {
        return 0;
    }
    const int arenas = std::max(2, kArenasPerThread * threads);
    if (mallopt(M_ARENA_MAX, arenas) != 1) {
        log::debug("mallopt(M_ARENA_MAX) failed; malloc keeps its default arenas");
        return 0;
    }
    return arenas;
}

// Splits the process's memory: GDAL's block cache gets a quarter of the budget (without one,
// it stays as init_gdal left it: 64 MiB, or GDAL_CACHEMAX), the tile cache cache_mb capped to
// half of it, the rest is left to tile generation, queues and connections, and malloc's arenas
// are bounded. Sets GDAL's cache, logs the split in one line, and returns the tile cache's
// bytes. Call before any DEM is read and before the server's threads start.
std::size_t split_memory(const config::ServerConfig& server, int threads) {
    const std::size_t budget = server.memory_mb;
    const std::size_t gdal_mb = budget / 4;
    const std::size_t cache_mb = budget ? std::min(server.cache_mb, budget / 2) : server.cache_mb;
    if (budget) {
        tiler::set_block_cache_mb(gdal_mb);
    }
    const int arenas = limit_malloc_arenas(server, threads);
    std::string line = budget ? "memory: " + std::to_string(budget) + " MiB budget: tile cache "
                              : "memory: no budget (memory_mb): tile cache ";
    line += std::to_string(cache_mb) + " MiB";
    if (cache_mb < server.cache_mb) {
        line += " (cache_mb " + std::to_string(server.cache_mb) + " capped to half the budget)";
    }
    // As GDAL has it now, so that the line shows what GDAL really uses.
    line += ", GDAL block cache " + std::to_string(tiler::block_cache_mb()) + " MiB";
    if (budget) {
        line += ", " + std::to_string(budget - cache_mb - gdal_mb) +
                " MiB left for tile generation and connections";
    }
    if (arenas > 0) {
        line += ", malloc arenas at most " + std::to_string(arenas);
    }
    log::info(line);
    return cache_mb << 20;
}

// No layer opened: `first` (the first layer's failure) alone for a single layer, as before;
// for several, one message saying so, of the same kind (exit 2 or 3), with the first reason.
[[noreturn]] void throw_none_served(std::exception_ptr first, std::size_t layers) {
    TB_ASSERT(first);
    if (layers == 1) {
        std::rethrow_exception(first);
    }
    const std::string prefix = "none of the " + std::to_string(layers) +
                               " layers can be served (each is logged above); the first: ";
    try {
        std::rethrow_exception(first);
    } catch (const IoError& e) {
        throw IoError(prefix + e.what());
    } catch (const Error& e) {
        throw InputError(prefix + e.what());
    }
}

// Owns SIGINT, SIGTERM and SIGHUP for the whole command: they are blocked in this thread and in
// every thread started afterwards (HTTP, generation), and one waiter thread takes them with
// sigtimedwait. While the server starts (opening DEMs can take a while), SIGINT and SIGTERM exit
// at once; once serving() is called, they stop the server gracefully instead. SIGHUP asks the
// layer watcher to check the sources now (ignored, with a log line, before it runs).
class StopSignals {
public:
    StopSignals() {
        sigemptyset(&set_);
        sigaddset(&set_, SIGINT);
        sigaddset(&set_, SIGTERM);
        sigaddset(&set_, SIGHUP);
        pthread_sigmask(SIG_BLOCK, &set_, nullptr);
        waiter_ = std::thread([this] { wait(); });
    }
    ~StopSignals() { finish(); }
    StopSignals(const StopSignals&) = delete;
    StopSignals& operator=(const StopSignals&) = delete;

    void serving(server::HttpServer& http) { http_ = &http; }
    // Where SIGHUP goes from now on (nullptr: nowhere); call with nullptr before it goes away.
    void reloading(server::LayerWatcher* watcher) { watcher_ = watcher; }
    // Ends the waiter; call before the server it stops goes away.
    void finish() {
        done_ = true;
        if (waiter_.joinable()) {
            waiter_.join();
        }
    }

private:
    void wait() {
        const timespec tick{0, 200 * 1000 * 1000};
        while (!done_) {
            const int signal_number = sigtimedwait(&set_, nullptr, &tick);
            if (signal_number == SIGHUP) {
                if (server::LayerWatcher* watcher = watcher_) {
                    watcher->check_now();
                } else {
                    log::info("received SIGHUP while starting; ignored");
                }
                continue;
            }
            if (signal_number != SIGINT && signal_number != SIGTERM) {
                continue;
            }
            const char* name = signal_number == SIGINT ? "SIGINT" : "SIGTERM";
            server::HttpServer* http = http_;
            if (!http) {
                log::info(std::string("received ") + name + " while starting; exiting");
                std::_Exit(128 + signal_number);
            }
            log::info(std::string("received ") + name + "; finishing requests in flight");
            http->stop();
            return;
        }
    }

    sigset_t set_;
    std::atomic<bool> done_{false};
    std::atomic<server::HttpServer*> http_{nullptr};
    std::atomic<server::LayerWatcher*> watcher_{nullptr};
    std::thread waiter_;
};

// The config: the file, or one layer per DEM; then the command line's overrides.
config::Config load_serve_config(const Args& args) {
    config::Config cfg;
    if (args.positional.size() == 1 && ends_with(args.positional[0], ".json")) {
        cfg = config::load_config(args.positional[0]);
    } else if (args.positional.empty()) {
        throw InputError("serve: name a config file (.json) or one or more DEM files; see "
                         "'terrabound serve --help'");
    } else {
        for (const auto& p : args.positional) {
            if (ends_with(p, ".json")) {
                throw InputError("serve: " + p +
                                 ": give a config file alone, not together with DEMs");
            }
        }
        cfg = config_from_dems(args.positional);
    }
    if (auto host = args.get("host")) {
        if (const auto problem = config::host_problem(*host)) {
            throw InputError("--host: " + *problem);
        }
        cfg.server.host = *host;
    }
    if (args.has("port")) {
        const long long port = args.get_int("port", cfg.server.port);
        if (port < 0 || port > 65535) {
            throw InputError("--port: expected 0..65535 (0: any free port), got " +
                             std::to_string(port));
        }
        cfg.server.port = static_cast<int>(port);
    }
    if (args.has("threads")) {
        const long long threads = args.get_int("threads", cfg.server.threads);
        if (threads < 0 || threads > 256) {
            throw InputError("--threads: expected 0..256 (0: one per usable core), got " +
                             std::to_string(threads));
        }
        cfg.server.threads = static_cast<int>(threads);
    }
    if (args.has("memory-mb")) {
        const long long mb = args.get_int("memory-mb", 0);
        if (mb != 0 && (mb < static_cast<long long>(config::kMinMemoryMb) ||
                        mb > static_cast<long long>(config::kMaxMemoryMb))) {
            throw InputError(
                "--memory-mb: expected 0 (no budget) or " + std::to_string(config::kMinMemoryMb) +
                ".." + std::to_string(config::kMaxMemoryMb) + " MiB, got " + std::to_string(mb));
        }
        cfg.server.memory_mb = static_cast<std::size_t>(mb);
    }
    if (args.has("deadline-ms")) {
        const long long ms = args.get_int("deadline-ms", cfg.server.deadline_ms);
        if (ms < 1 || ms > 600000) {
            throw InputError("--deadline-ms: expected 1..600000 (milliseconds a tile request may "
                             "take before it gets 503), got " +
                             std::to_string(ms));
        }
        cfg.server.deadline_ms = static_cast<int>(ms);
        // The wait for a generation to start counts within the deadline.
        cfg.server.start_wait_ms = std::min(cfg.server.start_wait_ms, cfg.server.deadline_ms);
    }
    if (auto metrics = args.get("metrics")) {
        server::parse_metrics_access(*metrics, "--metrics"); // checked here, before the layers
        cfg.server.metrics = *metrics;
    }
    if (auto store = args.get("store")) {
        for (auto& layer : cfg.layers) {
            layer.store = *store;
        }
    }
    if (args.has("nodata")) {
        const double nodata = args.get_double("nodata", 0);
        for (auto& layer : cfg.layers) {
            layer.options.nodata = nodata;
        }
    }
    if (auto v = args.get("effort")) {
        const core::Effort effort = core::parse_effort(*v);
        for (auto& layer : cfg.layers) {
            layer.options.effort = effort;
        }
    }
    if (auto v = args.get("summary-dir")) {
        for (auto& layer : cfg.layers) {
            layer.options.summary_dir = *v;
        }
    }
    if (auto v = args.get("valid-range")) {
        const auto range = tiler::parse_valid_range(*v, "serve: --valid-range");
        for (auto& layer : cfg.layers) {
            layer.options.valid_range = range;
        }
    }
    if (auto v = args.get("priority")) {
        const auto priority = tiler::parse_source_priority(*v, "serve: --priority");
        for (auto& layer : cfg.layers) {
            layer.options.priority = priority;
        }
    }
    log::Level level = log::Level::Info;
    if (log::parse_level(cfg.server.log_level, level)) {
        log::set_level(level);
    }

    return cfg;
}

struct OpenedLayers {
    std::vector<server::ServedLayer> served;
    std::vector<server::UnavailableLayer> unavailable;
    server::Stores stores;
    std::vector<std::vector<std::string>> stamps; // per config layer, taken before opening it
};

// The config's layers and their stores. A layer whose sources or store fail to open (a store
// built with other settings, or one whose build --update has not finished) is logged and
// answers 503 with the reason; every layer failing stops before listening.
OpenedLayers open_layers(const config::Config& cfg) {
    OpenedLayers opened;
    std::vector<std::string> failures; // logged once the others are known to open
    std::exception_ptr first_failure;
    for (const auto& layer : cfg.layers) {
        opened.stamps.push_back(server::source_stamps(layer.options.sources));
        server::ServedLayer s;
        try {
            s = server::open_served_layer(layer);
            server::attach_store(s, layer, opened.stores);
        } catch (const Error& e) {
            failures.push_back("layer " + layer.options.name + " (" +
                               tiler::inputs_text(layer.options.sources) + "): " + e.what());
            opened.unavailable.push_back({layer.options.name, e.what()});
            if (!first_failure) {
                first_failure = std::current_exception();
            }
            continue;
        }
        log::info("layer " + layer.options.name + ": zooms " + std::to_string(s.layer->min_zoom()) +
                  ".." + std::to_string(s.layer->max_zoom()));
        opened.served.push_back(std::move(s));
    }
    if (opened.served.empty()) {
        for (const auto& failure : failures) {
            if (cfg.layers.size() > 1) {
                log::error(failure);
            }
        }
        throw_none_served(first_failure, cfg.layers.size());
    }
    for (const auto& failure : failures) {
        log::error(failure + "; its routes answer 503, the other layers serve");
    }
    return opened;
}

int run(const Args& args) {
    StopSignals signals;
    const config::Config cfg = load_serve_config(args);
    server::Metrics metrics;
    const int threads = cfg.server.threads > 0 ? cfg.server.threads : tiler::usable_cpus();
    const std::size_t cache_bytes = split_memory(cfg.server, threads); // before any DEM is read
    OpenedLayers opened = open_layers(cfg);

    server::TileServiceOptions tile_options;
    tile_options.cache_bytes = cache_bytes;
    tile_options.threads = threads;
    tile_options.queue_limit = cfg.server.queue_limit;
    tile_options.start_wait = std::chrono::milliseconds(cfg.server.start_wait_ms);
    tile_options.deadline = std::chrono::milliseconds(cfg.server.deadline_ms);
    server::TileService tiles(
        std::move(opened.served), tile_options, metrics, std::move(opened.unavailable));

    server::HttpOptions http_options;
    http_options.host = cfg.server.host;
    http_options.port = cfg.server.port;
    http_options.cors_origins = cfg.server.cors_origins;
    http_options.http_threads = std::max(16, 4 * threads);
    http_options.metrics = server::parse_metrics_access(cfg.server.metrics, "metrics");
    http_options.web_root = find_web_root(args);
    if (!http_options.web_root.empty()) {
        if (tiles.find("web")) {
            throw InputError("layer name 'web' is taken by the viewer's files; rename the layer "
                             "or pass --web none");
        }
        log::info("viewer: " + http_options.web_root);
    }
    server::HttpServer http(tiles, metrics, http_options);
    const int port = http.bind();

    server::LayerWatcher watcher(tiles,
                                 cfg.layers,
                                 std::move(opened.stamps),
                                 opened.stores,
                                 std::chrono::seconds(cfg.server.watch_interval_s));
    signals.reloading(&watcher);
    signals.serving(http);

    const std::string shown_host = cfg.server.host == "0.0.0.0" ? "localhost" : cfg.server.host;
    log::info("serving http://" + shown_host + ":" + std::to_string(port) + "/ (" +
              std::to_string(tiles.layers()->served.size()) + " layer(s)" +
              (tiles.layers()->unavailable.empty()
                   ? std::string()
                   : ", " + std::to_string(tiles.layers()->unavailable.size()) + " unavailable") +
              ", " + std::to_string(threads) +
              " generation thread(s)); open it in a browser, stop with Ctrl-C");
    http.run();

    signals.reloading(nullptr);
    signals.finish();
    log::info("stopped");
    return 0;
}

} // namespace

const Command& serve_command() {
    static const Command command{
        {"serve",
         "[CONFIG.json | DEM...] [--host H] [--port P] [--threads N] [--store PATH] "
         "[--metrics loopback|on|off] [--memory-mb MB] [--deadline-ms MS]",
         "Serve terrain tiles over HTTP.",
         {{"host", "HOST", "address to listen on (default 127.0.0.1, or the config's)"},
          {"port", "PORT", "port to listen on (default 8080; 0 picks a free port)"},
          {"threads", "N", "tile generation threads (default: one per usable core)"},
          {"web", "DIR", "the viewer's directory (default: web/ of this checkout; 'none': off)"},
          {"memory-mb",
           "MB",
           "memory budget: GDAL's block cache gets a quarter, the tile cache at most half "
           "(default: none; GDAL 64 MiB, tile cache cache_mb)"},
          {"deadline-ms",
           "MS",
           "how long a tile request may take: past it, 503 with Retry-After, and a tile nobody "
           "waits for any more stops (default 10000, or the config's deadline_ms; a longer "
           "start_wait_ms is shortened to it)"},
          {"metrics",
           "WHO",
           "who may read /metrics: loopback (default: this machine only), on (anyone), off"},
          {"nodata", "V", "raw sample value every layer treats as nodata (the config's nodata)"},
          {"effort",
           "LEVEL",
           "mesher effort of every layer (the config's effort): fast, balanced (default) or best"},
          {"summary-dir", "DIR", kSummaryDirHelp},
          {"valid-range", "MIN,MAX", kValidRangeHelp},
          {"priority", "finest|listed", kPriorityHelp},
          {"store",
           "PATH",
           "keep generated tiles in this store for every layer: a directory, or a file "
           "ending in .sqlite or .db; or serve the raster DEM tiles a build wrote to an "
           ".mbtiles or .pmtiles file (other tiles are kept in memory)"}},
         "With DEM files, each becomes a layer named after its file, with default settings.\n"
         "With a config file (JSON), every setting is explicit; see docs/serving.md, "
         "\"Configuration\".\n"
         "Routes (every layer, {layer} = its name):\n"
         "  /{layer}/tileset.json               3D Tiles (CesiumJS, three.js, deck.gl)\n"
         "  /{layer}/{z}/{x}/{y}.glb, .drc      its mesh tiles; ?eps=K: eps_levels[K]\n"
         "  /{layer}/layer.json                 quantized-mesh terrain (CesiumTerrainProvider)\n"
         "  /{layer}/{z}/{x}/{y}.terrain        its tiles, extensions as Accept asks\n"
         "  /{layer}/terrain/tileset.json       3D Tiles terrain (Cesium3DTilesTerrainProvider)\n"
         "  /{layer}/dem/tilejson.json          raster DEM for MapLibre / deck.gl (terrarium;\n"
         "                                      ?encoding=mapbox for Terrain-RGB)\n"
         "  /{layer}/dem/{z}/{x}/{y}.png        its tiles (same ?encoding)\n"
         "  /layers, /health, /metrics, / (the viewer)\n"
         "SIGINT/SIGTERM finish requests in flight, then exit.\n"},
        run};
    return command;
}

} // namespace tb::cli
