#pragma once
// Layers that follow their sources while `serve` runs. A watcher thread compares every layer's
// source files (size and modification time) with what they were when the layer was opened,
// every watch interval and at once on SIGHUP. A layer whose sources changed is opened anew,
// which rebuilds its summary (the summary's key holds the sources' size and time), its store is
// readied for it (a store's tiles of the old sources are removed), and it is swapped in with
// TileService::replace_layer: from then on no answer comes from the old layer, and none mixes
// the two. A layer that cannot be opened answers 503 with the reason until its sources change
// again. Replace a source atomically (write a new file, then rename it over the old one), so a
// check never catches it half-written.
#include "config/config.hpp"
#include "server/tile_service.hpp"

#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace tb::server {

// The stores of a config's layers, opened once and shared by the layers that name one path.
using Stores = std::map<std::string, std::shared_ptr<tiler::TileStore>>;

// A config layer opened: its tiler::Layer and formats, no store yet. Throws what
// tiler::Layer::open throws.
ServedLayer open_served_layer(const config::LayerConfig& layer);

// Gives `served` the store its config names (opened into `stores` the first time) made ready
// for it (tiler::prepare_store_for_serving). Nothing without a store. Throws IoError or
// InputError as the store and its manifest do.
void attach_store(ServedLayer& served, const config::LayerConfig& layer, Stores& stores);

// What each source is on disk now: "size mtime-in-ns" of a local file, "-" for one that cannot
// be read (missing, or not a local file such as /vsicurl/).
std::vector<std::string> source_stamps(const std::vector<std::string>& sources);

class LayerWatcher {
public:
    // `stamps[i]`: layer i's source_stamps, taken before it was opened. `interval` 0: checks
    // only when check_now() is called.
    LayerWatcher(TileService& tiles,
                 std::vector<config::LayerConfig> layers,
                 std::vector<std::vector<std::string>> stamps,
                 Stores& stores,
                 std::chrono::seconds interval);
    ~LayerWatcher(); // stops the thread (a reload under way finishes first)
    LayerWatcher(const LayerWatcher&) = delete;
    LayerWatcher& operator=(const LayerWatcher&) = delete;

    // Checks every layer at once (SIGHUP), on the watcher's thread.
    void check_now();

private:
    void run();
    void check();
    void reload(std::size_t i);

    TileService& tiles_;
    std::vector<config::LayerConfig> layers_;
    std::vector<std::vector<std::string>> stamps_; // watcher thread only
    Stores& stores_;                               // watcher thread only, once serving
    std::chrono::seconds interval_;
    std::mutex mutex_;
    std::condition_variable wake_;
    bool stop_ = false, now_ = false;
    std::thread thread_; // last: started once the rest is ready
};

} // namespace tb::server
