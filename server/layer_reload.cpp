#include "server/layer_reload.hpp"

#include "core/error.hpp"
#include "tiler/formats/quantized_mesh.hpp"
#include "tiler/log.hpp"
#include "tiler/pyramid/tile_settings.hpp"
#include "tiler/sources/source_list.hpp"

#include <filesystem>
#include <sys/stat.h>

namespace tb::server {

ServedLayer open_served_layer(const config::LayerConfig& layer) {
    ServedLayer served;
    served.layer = tiler::Layer::open(layer.options);
    served.layer->prepare(); // its summaries made or loaded now, not by its first tiles
    served.formats = layer.formats;
    return served;
}

void attach_store(ServedLayer& served, const config::LayerConfig& layer, Stores& stores) {
    if (!layer.store) {
        return;
    }
    auto& store = stores[*layer.store];
    if (!store && layer.store->ends_with(".pmtiles") && !std::filesystem::exists(*layer.store)) {
        // A PMTiles archive is written once, by a build; a server could only stage tiles that
        // never become an archive.
        throw InputError("layer " + layer.options.name + ": store " + *layer.store +
                         " does not exist; serve reads a .pmtiles archive that terrabound build "
                         "made (build DEM -o " +
                         *layer.store +
                         "), or give it a directory or a .sqlite file to keep tiles in");
    }
    if (!store) {
        store = tiler::TileStore::open(*layer.store);
        log::info("store: " + store->describe());
    }
    // Tiles made with other settings would publish bounds that are not this layer's.
    const tiler::StoreUse use = tiler::prepare_store_for_serving(*store, *served.layer);
    served.store_eps_levels = use.eps_levels;
    // A build that kept only some extensions cannot answer a client asking for more.
    served.store_terrain = use.terrain_extensions.empty() ||
                           use.terrain_extensions ==
                               tiler::terrain_extensions_json(tiler::kAllQuantizedMeshExtensions);
    if (!served.store_terrain) {
        log::info("store: layer " + layer.options.name + ": its .terrain tiles hold only " +
                  use.terrain_extensions +
                  " (build --terrain-extensions); serve makes them with every extension "
                  "instead, and keeps them in memory only");
    }
    served.store = store;
}

std::vector<std::string> source_stamps(const std::vector<std::string>& sources) {
    std::vector<std::string> stamps;
    std::vector<std::string> files;
    try {
        files = tiler::watched_files(sources); // a file added to a directory is a change
    } catch (const InputError&) {
        files = sources; // the reload that follows reports it
    }
    for (const auto& path : files) {
        struct stat st {};
        if (::stat(path.c_str(), &st) != 0) {
            stamps.emplace_back("-");
            continue;
        }
        const long long ns =
            static_cast<long long>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec;
        stamps.push_back(std::to_string(static_cast<long long>(st.st_size)) + " " +
                         std::to_string(ns));
    }
    return stamps;
}

LayerWatcher::LayerWatcher(TileService& tiles,
                           std::vector<config::LayerConfig> layers,
                           std::vector<std::vector<std::string>> stamps,
                           Stores& stores,
                           std::chrono::seconds interval)
    : tiles_(tiles), layers_(std::move(layers)), stamps_(std::move(stamps)), stores_(stores),
      interval_(interval) {
    TB_ASSERT(stamps_.size() == layers_.size());
    thread_ = std::thread([this] { run(); });
}

LayerWatcher::~LayerWatcher() {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        stop_ = true;
    }
    wake_.notify_all();
    thread_.join();
}

void LayerWatcher::check_now() {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        now_ = true;
    }
    wake_.notify_all();
}

void LayerWatcher::run() {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!stop_) {
        const auto woken = [this] { return stop_ || now_; };
        if (interval_.count() > 0) {
            wake_.wait_for(lock, interval_, woken);
        } else {
            wake_.wait(lock, woken);
        }
        if (stop_) {
            return;
        }
        const bool asked = now_;
        now_ = false;
        lock.unlock();
        if (asked) {
            log::info("reload: checking every layer's sources (SIGHUP)");
        }
        check();
        lock.lock();
    }
}

// Reloads every layer whose sources changed since it was last opened (or tried).
void LayerWatcher::check() {
    for (std::size_t i = 0; i < layers_.size(); ++i) {
        auto now = source_stamps(layers_[i].options.sources);
        if (now == stamps_[i]) {
            continue;
        }
        stamps_[i] = std::move(now); // a failed reload is retried when they change again
        reload(i);
    }
}

void LayerWatcher::reload(std::size_t i) {
    const config::LayerConfig& layer = layers_[i];
    const std::string& name = layer.options.name;
    log::info("reload: layer " + name + ": its sources changed; opening them again");
    try {
        ServedLayer served = open_served_layer(layer);
        const int min_zoom = served.layer->min_zoom(), max_zoom = served.layer->max_zoom();
        tiles_.replace_layer(std::move(served),
                             [&](ServedLayer& s) { attach_store(s, layer, stores_); });
        log::info("reload: layer " + name + " now serves its new sources (zooms " +
                  std::to_string(min_zoom) + ".." + std::to_string(max_zoom) +
                  "); its cached tiles were dropped");
    } catch (const std::exception& e) {
        tiles_.make_unavailable(name, e.what());
        log::error("reload: layer " + name + ": " + e.what() +
                   "; it answers 503 until its sources change again (replace them with a "
                   "rename, so they are never read half-written)");
    }
}

} // namespace tb::server
