// TileService: LRU -> store -> single-flight generation on a bounded pool.
#include "server/tile_service.hpp"
#include "server/thread_pool.hpp"

#include "tiler/formats/quantized_mesh.hpp"

#include "core/error.hpp"
#include "tiler/dem_tiles.hpp"
#include "tiler/log.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <future>
#include <list>
#include <map>
#include <mutex>
#include <thread>
#include <unordered_map>

namespace tb::server {
namespace {

// Nice value of the generation threads (0 is the default, 19 the lowest priority).
constexpr int kGenerationNice = 10;

// Default ceiling of TileServiceOptions::max_waiting (each waiter holds an HTTP thread).
constexpr long long kMaxWaiting = 1024;

// States of a queued generation: a request drops it when it has not started within
// TileServiceOptions::start_wait.
constexpr int kQueued = 0, kStarted = 1, kDropped = 2;

// Bookkeeping bytes charged per cache entry on top of key and payload.
constexpr std::size_t kEntryOverhead = 128;

// A least-recently-used map bounded by the bytes of its keys and values, the compressed copies
// the values carry included: a copy made while its blob is cached is charged to the blob's
// entry when made (charge), one made before when the blob is put.
class LruCache {
public:
    LruCache(std::size_t capacity, Metrics& metrics) : capacity_(capacity), metrics_(metrics) {}

    std::shared_ptr<const Blob> get(const std::string& key) {
        std::lock_guard<std::mutex> lock(mutex_);
        const auto it = index_.find(key);
        if (it == index_.end()) {
            return nullptr;
        }
        order_.splice(order_.begin(), order_, it->second);
        return it->second->blob;
    }

    void put(const std::string& key, std::shared_ptr<const Blob> blob) {
        std::lock_guard<std::mutex> lock(mutex_);
        Entry entry{key, std::move(blob), key.size() + kEntryOverhead, 0};
        entry.charged += entry.blob->bytes.size();
        // Under the lock, so that a copy made meanwhile is charged here or by charge(), once.
        for (const Coding coding : {Coding::Gzip, Coding::Brotli}) {
            if (const std::string* copy = entry.blob->encoded_if_made(coding)) {
                entry.charged += copy->size();
                entry.codings |= bit(coding);
            }
        }
        if (entry.charged > capacity_) {
            return; // larger than the whole cache: serve it, don't keep it
        }
        if (const auto it = index_.find(key); it != index_.end()) {
            erase(it->second);
        }
        bytes_ += entry.charged;
        order_.push_front(std::move(entry));
        index_.emplace(key, order_.begin());
        by_blob_[order_.front().blob.get()] = order_.begin();
        trim();
    }

    // The copy of `blob` in `coding`, of `size` bytes, was just made: charged to the blob's
    // entry, if the cache holds it and has not charged that copy yet.
    void charge(const Blob* blob, Coding coding, std::size_t size) {
        std::lock_guard<std::mutex> lock(mutex_);
        const auto it = by_blob_.find(blob);
        if (it == by_blob_.end() || (it->second->codings & bit(coding)) != 0) {
            return;
        }
        it->second->codings |= bit(coding);
        if (it->second->charged + size > capacity_) {
            // With its copies larger than the whole cache: dropped alone, as put() would not
            // have kept it, instead of evicting every other entry first.
            erase(it->second);
            trim();
            return;
        }
        it->second->charged += size;
        bytes_ += size;
        trim();
    }

private:
    struct Entry {
        std::string key;
        std::shared_ptr<const Blob> blob;
        std::size_t charged; // key, payload, copies charged so far and kEntryOverhead
        unsigned codings;    // bit(coding) of each copy charged
    };
    using Iterator = std::list<Entry>::iterator;

    static unsigned bit(Coding coding) { return 1u << static_cast<unsigned>(coding); }

    void erase(Iterator it) {
        bytes_ -= it->charged;
        index_.erase(it->key);
        if (const auto b = by_blob_.find(it->blob.get()); b != by_blob_.end() && b->second == it) {
            by_blob_.erase(b);
        }
        order_.erase(it);
    }

    // Evicts the least recently used entries until the bound holds.
    void trim() {
        while (bytes_ > capacity_ && !order_.empty()) {
            erase(std::prev(order_.end()));
        }
        metrics_.cache_bytes = bytes_;
        metrics_.cache_entries = index_.size();
    }

    std::size_t capacity_;
    Metrics& metrics_;
    std::mutex mutex_;
    std::size_t bytes_ = 0;
    std::list<Entry> order_; // most recent first
    std::unordered_map<std::string, Iterator> index_;
    std::unordered_map<const Blob*, Iterator> by_blob_;
};

// The generation threads yield the CPU to the threads that answer requests, so that health
// checks and cache hits stay fast while every core meshes. Linux sets the nice value per
// thread, and the mesher's own threads inherit it.
void lower_priority() {
    if (setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), kGenerationNice) != 0) {
        log::debug("cannot lower the priority of a generation thread");
    }
}

std::string
tile_key(const std::string& layer, const tiler::TileId& id, tiler::Format format, int eps_level) {
    return "t/" + layer + "/" + tiler::format_name(format) + "/" + std::to_string(eps_level) + "/" +
           std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
}

// The cache key of a quantized-mesh tile cut down to `extensions` from `full` (its ETag in the
// key, so a regenerated tile never meets an old copy).
std::string subset_key(const std::string& layer,
                       const tiler::TileId& id,
                       unsigned extensions,
                       const Blob& full) {
    return tile_key(layer, id, tiler::Format::Terrain, -1) + "/x" + std::to_string(extensions) +
           "/" + full.etag;
}

std::shared_ptr<const Blob> make_blob(std::string bytes) {
    auto blob = std::make_shared<Blob>();
    blob->etag = make_etag(bytes);
    blob->bytes = std::move(bytes);
    return blob;
}

std::shared_ptr<const Blob> make_failure(int status, std::string reason) {
    auto blob = std::make_shared<Blob>();
    blob->failure = status;
    blob->bytes = std::move(reason);
    return blob;
}

// Rethrows a remembered failure as the error it came from.
void throw_if_failure(const Blob& blob) {
    if (blob.failure == 404) {
        throw NotFound(blob.bytes);
    }
    if (blob.failure != 0) {
        throw InputError(blob.bytes);
    }
}

} // namespace

const std::string& Blob::encoded(Coding coding, Metrics& metrics, bool* made) const {
    if (coding == Coding::Brotli) {
        std::call_once(brotli_once_, [&] {
            brotli_ = compress(bytes, Coding::Brotli);
            brotli_made_.store(true, std::memory_order_release);
            ++metrics.brotli_compressions;
            if (made != nullptr) {
                *made = true;
            }
        });
        return brotli_;
    }
    if (coding == Coding::Gzip) {
        std::call_once(gzip_once_, [&] {
            gzip_ = compress(bytes, Coding::Gzip);
            gzip_made_.store(true, std::memory_order_release);
            ++metrics.gzip_compressions;
            if (made != nullptr) {
                *made = true;
            }
        });
        return gzip_;
    }
    return bytes;
}

const std::string* Blob::encoded_if_made(Coding coding) const {
    switch (coding) {
    case Coding::Brotli:
        return brotli_made_.load(std::memory_order_acquire) ? &brotli_ : nullptr;
    case Coding::Gzip:
        return gzip_made_.load(std::memory_order_acquire) ? &gzip_ : nullptr;
    default:
        return &bytes;
    }
}

std::string make_etag(std::string_view bytes) {
    std::uint64_t h = 14695981039346656037ull;
    for (unsigned char c : bytes) {
        h = (h ^ c) * 1099511628211ull;
    }
    char text[64];
    std::snprintf(
        text, sizeof text, "\"%016llx-%zx\"", static_cast<unsigned long long>(h), bytes.size());
    return text;
}

struct TileService::Impl {
    Impl(const TileServiceOptions& o, Metrics& m)
        : options(o), metrics(m), cache(o.cache_bytes, m), pool(o.threads, lower_priority) {}

    TileServiceOptions options;
    Metrics& metrics;
    LruCache cache;

    std::mutex flight_mutex; // guards `flights` and `pending`
    std::map<std::string, std::shared_future<std::shared_ptr<const Blob>>> flights;
    int pending = 0; // generations queued or running
    int waiting = 0; // requests waiting for a generation

    // Waits up to options.start_wait for `flight` (whose generation `job` this request leads)
    // to finish, and true when it did or its generation has started by then. Otherwise drops
    // the generation before it starts, answers its followers busy too, and returns false.
    bool started_in_time(std::atomic<int>& job,
                         const std::shared_future<std::shared_ptr<const Blob>>& flight,
                         std::promise<std::shared_ptr<const Blob>>& promise,
                         const std::string& key) {
        if (flight.wait_for(options.start_wait) == std::future_status::ready) {
            return true;
        }
        int queued = kQueued;
        if (!job.compare_exchange_strong(queued, kDropped)) {
            return true; // started meanwhile: its answer is coming
        }
        --metrics.queued_generations;
        std::lock_guard<std::mutex> lock(flight_mutex);
        --pending;
        promise.set_value(nullptr);
        flights.erase(key);
        return false;
    }

    ThreadPool pool; // last: destroyed (drained and joined) first
};

TileService::TileService(std::vector<ServedLayer> layers,
                         const TileServiceOptions& options,
                         Metrics& metrics,
                         std::vector<UnavailableLayer> unavailable)
    : layers_(std::move(layers)), unavailable_(std::move(unavailable)) {
    TB_ASSERT(options.threads >= 1 && options.queue_limit >= 0 && options.max_waiting >= 0);
    TileServiceOptions resolved = options;
    if (resolved.max_waiting == 0) {
        resolved.max_waiting = static_cast<int>(
            std::min<long long>(2LL * (options.threads + options.queue_limit), kMaxWaiting));
    }
    impl_ = std::make_unique<Impl>(resolved, metrics);
    TB_ASSERT(std::all_of(
        layers_.begin(), layers_.end(), [](const ServedLayer& l) { return l.layer != nullptr; }));
}

TileService::~TileService() = default;

const std::string& TileService::encoded(const Blob& blob, Coding coding) {
    bool made = false;
    const std::string& out = blob.encoded(coding, impl_->metrics, &made);
    if (made) {
        impl_->cache.charge(&blob, coding, out.size());
    }
    return out;
}

int TileService::max_waiting() const {
    return impl_->options.max_waiting;
}

const ServedLayer* TileService::find(const std::string& name) const {
    for (const auto& l : layers_) {
        if (l.layer->options().name == name) {
            return &l;
        }
    }
    return nullptr;
}

const ServedLayer& TileService::require(const std::string& name) const {
    if (const ServedLayer* served = find(name)) {
        return *served;
    }
    for (const auto& u : unavailable_) {
        if (u.name == name) {
            throw Unavailable("layer '" + name + "' is unavailable: " + u.reason);
        }
    }
    throw NotFound("unknown layer '" + name + "'");
}

namespace {

// An eps level (?eps=K) the layer has, asked of a format made at levels: InputError otherwise,
// the same for every format when the layer has no level K.
void check_eps(const tiler::Layer& layer, tiler::Format format, tiler::EpsChoice eps) {
    const int n_levels = static_cast<int>(layer.options().eps_levels.size());
    if (eps.level < -1 || eps.level >= n_levels) {
        throw InputError("eps level " + std::to_string(eps.level) + " is not configured; layer '" +
                         layer.options().name + "' has " + std::to_string(n_levels) +
                         " eps level(s)");
    }
    if (eps.level >= 0 && format != tiler::Format::Glb && format != tiler::Format::Drc) {
        throw InputError(std::string("eps levels (?eps=K) apply to .glb and .drc tiles only; .") +
                         tiler::extension(format) + " tiles are made at their zoom's own eps");
    }
}

// The checks before a mesh tile is looked up: InputError for an id outside the layer's scheme,
// NotFound outside its zooms or data.
void check_mesh_tile(const tiler::Layer& layer, const tiler::TileId& id) {
    if (!tiler::is_valid(layer.options().scheme, id)) {
        throw InputError("tile " + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
                         std::to_string(id.y) + " is outside the " +
                         tiler::to_string(layer.options().scheme) + " tiling scheme");
    }
    const std::string where =
        std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
    if (id.z < layer.min_zoom() || id.z > layer.max_zoom() || !layer.may_have_tile(id)) {
        throw NotFound("layer '" + layer.options().name + "' has no tile " + where + " (zooms " +
                       std::to_string(layer.min_zoom()) + ".." + std::to_string(layer.max_zoom()) +
                       ")");
    }
}

// The same for a quantized-mesh tile, which every zoom up to max_zoom has (filler where the
// layer has no data).
void check_terrain_tile(const tiler::Layer& layer, const tiler::TileId& id) {
    const std::string where =
        std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
    if (!tiler::is_valid(tiler::Scheme::Geodetic, id)) {
        throw InputError("terrain tile " + where +
                         " is outside the geodetic TMS (x below 2^(z+1), y below 2^z)");
    }
    if (id.z > layer.max_zoom()) {
        throw NotFound("layer '" + layer.options().name + "' has no terrain tile " + where +
                       " (max zoom " + std::to_string(layer.max_zoom()) +
                       "; clients upsample its parent)");
    }
}

// The same for a raster DEM tile, whose pyramid is EPSG:3857 XYZ whatever the layer's scheme.
void check_dem_tile(const tiler::Layer& layer, const tiler::TileId& id) {
    const std::string where =
        std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
    if (!tiler::is_valid(tiler::Scheme::Mercator, id)) {
        throw InputError("DEM tile " + where +
                         " is outside EPSG:3857 XYZ (x and y below 2^z at zoom z)");
    }
    const tiler::TileRange r = tiler::dem_tiles_at(layer, id.z);
    if (r.empty() || id.x < r.x0 || id.x > r.x1 || id.y < r.y0 || id.y > r.y1) {
        const tiler::DemTilePlan plan = tiler::dem_tile_plan(layer);
        throw NotFound("layer '" + layer.options().name + "' has no DEM tile " + where +
                       " (DEM zooms " + std::to_string(plan.min_zoom) + ".." +
                       std::to_string(plan.max_zoom) + ")");
    }
}

} // namespace

std::shared_ptr<const Blob> TileService::tile(const std::string& layer_name,
                                              const tiler::TileId& id,
                                              tiler::Format format,
                                              tiler::EpsChoice eps) {
    const ServedLayer* served = &require(layer_name);
    const tiler::Layer& layer = *served->layer;
    bool format_served = false;
    for (auto f : served->formats) {
        format_served = format_served || f == format;
    }
    if (!format_served) {
        throw NotFound("layer '" + layer_name + "' does not serve ." + tiler::extension(format) +
                       " tiles");
    }
    check_eps(layer, format, eps);
    if (tiler::is_dem_format(format)) {
        check_dem_tile(layer, id);
    } else if (tiler::is_terrain_format(format)) {
        check_terrain_tile(layer, id);
    } else {
        check_mesh_tile(layer, id);
    }

    Impl& s = *impl_;
    const std::string key = tile_key(layer_name, id, format, eps.level);
    std::shared_ptr<const Blob> blob = s.cache.get(key);
    if (blob) {
        ++s.metrics.cache_hits;
    } else {
        ++s.metrics.cache_misses;
        std::shared_future<std::shared_ptr<const Blob>> flight;
        std::shared_ptr<std::promise<std::shared_ptr<const Blob>>> promise;
        std::shared_ptr<std::atomic<int>> job; // the queued generation this request leads
        bool entered_wait = false;             // counted in s.waiting
        {
            std::lock_guard<std::mutex> lock(s.flight_mutex);
            const auto it = s.flights.find(key);
            if (it != s.flights.end()) {
                if (s.waiting >= s.options.max_waiting) {
                    ++s.metrics.queue_rejections;
                    return nullptr;
                }
                ++s.waiting;
                entered_wait = true;
                flight = it->second;
                ++s.metrics.single_flight_waits;
            } else {
                promise = std::make_shared<std::promise<std::shared_ptr<const Blob>>>();
                flight = promise->get_future().share();
                s.flights.emplace(key, flight);
            }
        }
        if (promise) {
            // This request leads: look in the store, else queue a generation.
            const tiler::TileKey store_key{layer_name, id, format, eps.level};
            const bool in_store = served->store && (eps.level < 0 || served->store_eps_levels);
            std::optional<std::string> stored;
            if (in_store) {
                try {
                    stored = served->store->get(store_key); // stores are thread-safe
                } catch (...) {
                    std::lock_guard<std::mutex> lock(s.flight_mutex);
                    promise->set_exception(std::current_exception());
                    s.flights.erase(key);
                    throw;
                }
            }
            if (stored) {
                ++s.metrics.store_hits;
                auto found = make_blob(std::move(*stored));
                s.cache.put(key, found);
                std::lock_guard<std::mutex> lock(s.flight_mutex);
                promise->set_value(found);
                s.flights.erase(key);
            } else {
                bool admitted = false;
                {
                    std::lock_guard<std::mutex> lock(s.flight_mutex);
                    if (s.pending < s.options.threads + s.options.queue_limit &&
                        s.waiting < s.options.max_waiting) {
                        ++s.pending;
                        ++s.waiting;
                        entered_wait = true;
                        admitted = true;
                    } else {
                        // Followers of this flight get the same answer: busy.
                        promise->set_value(nullptr);
                        s.flights.erase(key);
                    }
                }
                if (!admitted) {
                    ++s.metrics.queue_rejections;
                    return nullptr;
                }
                ++s.metrics.queued_generations;
                job = std::make_shared<std::atomic<int>>(kQueued);
                s.pool.submit(
                    [&s, served, &layer, store_key, in_store, key, promise, format, eps, id, job] {
                        int queued = kQueued;
                        if (!job->compare_exchange_strong(queued, kStarted)) {
                            return; // dropped (start_wait): its requests were answered busy
                        }
                        --s.metrics.queued_generations;
                        ++s.metrics.in_flight_generations;
                        const auto start = std::chrono::steady_clock::now();
                        std::shared_ptr<const Blob> made;
                        std::exception_ptr failure;
                        try {
                            made = make_blob(tiler::is_dem_format(format)
                                                 ? tiler::make_dem_tile(layer, id, format)
                                                 : layer.make_tile(id, format, eps));
                            ++s.metrics.tiles_generated;
                        } catch (const NotFound& e) {
                            made = make_failure(404, e.what());
                            ++s.metrics.tiles_empty;
                        } catch (const InputError& e) {
                            // Deterministic for this tile and eps: remember it, don't remesh.
                            made = make_failure(400, e.what());
                        } catch (...) {
                            failure = std::current_exception();
                        }
                        s.metrics.generation_micros += static_cast<std::uint64_t>(
                            std::chrono::duration_cast<std::chrono::microseconds>(
                                std::chrono::steady_clock::now() - start)
                                .count());
                        --s.metrics.in_flight_generations;
                        if (made && made->failure == 0 && in_store) {
                            try {
                                served->store->put(store_key, made->bytes);
                            } catch (const std::exception& e) {
                                ++s.metrics.store_write_failures;
                                log::warn(std::string("tile not stored: ") + e.what());
                            }
                        }
                        if (made) {
                            s.cache.put(key, made);
                        }
                        std::lock_guard<std::mutex> lock(s.flight_mutex);
                        --s.pending;
                        if (failure) {
                            promise->set_exception(failure);
                        } else {
                            promise->set_value(made);
                        }
                        s.flights.erase(key);
                    });
            }
        }
        // Leaves the count of waiting requests however get() returns. A lead that found its tile
        // in the store never entered it.
        struct Leave {
            Impl& s;
            bool entered;
            ~Leave() {
                if (entered) {
                    std::lock_guard<std::mutex> lock(s.flight_mutex);
                    --s.waiting;
                }
            }
        } leave{s, entered_wait};
        if (job && !s.started_in_time(*job, flight, *promise, key)) {
            ++s.metrics.queue_rejections;
            return nullptr;
        }
        blob = flight.get(); // rethrows the generation's InputError / IoError
        if (!blob) {
            ++s.metrics.queue_rejections;
            return nullptr;
        }
    }
    throw_if_failure(*blob);
    return blob;
}

std::shared_ptr<const Blob>
TileService::cached_tile(const std::string& layer, const tiler::TileId& id, tiler::Format format) {
    Impl& s = *impl_;
    std::shared_ptr<const Blob> blob = s.cache.get(tile_key(layer, id, format, -1));
    if (!blob || blob->failure != 0) {
        return nullptr;
    }
    ++s.metrics.cache_hits;
    return blob;
}

std::shared_ptr<const Blob> TileService::terrain(const std::string& layer,
                                                 const tiler::TileId& id,
                                                 unsigned extensions,
                                                 tiler::EpsChoice eps) {
    const std::shared_ptr<const Blob> full = tile(layer, id, tiler::Format::Terrain, eps);
    if (!full || extensions == tiler::kAllQuantizedMeshExtensions) {
        return full;
    }
    Impl& s = *impl_;
    const std::string key = subset_key(layer, id, extensions, *full);
    std::shared_ptr<const Blob> blob = s.cache.get(key);
    if (!blob) {
        blob = make_blob(tiler::select_extensions(full->bytes, extensions));
        s.cache.put(key, blob);
    }
    return blob;
}

std::shared_ptr<const Blob>
TileService::cached_terrain(const std::string& layer,
                            const tiler::TileId& id,
                            unsigned extensions,
                            const std::function<bool(const Blob&)>& usable) {
    Impl& s = *impl_;
    std::shared_ptr<const Blob> blob = s.cache.get(tile_key(layer, id, tiler::Format::Terrain, -1));
    if (!blob || blob->failure != 0) {
        return nullptr;
    }
    if (extensions != tiler::kAllQuantizedMeshExtensions) {
        blob = s.cache.get(subset_key(layer, id, extensions, *blob));
    }
    if (!blob || !usable(*blob)) {
        return nullptr;
    }
    ++s.metrics.cache_hits;
    return blob;
}

std::shared_ptr<const Blob> TileService::document(const std::string& layer_name,
                                                  const std::string& path) {
    const ServedLayer* served = &require(layer_name);
    if (path == "layer.json" &&
        std::find(served->formats.begin(), served->formats.end(), tiler::Format::Terrain) ==
            served->formats.end()) {
        throw NotFound("layer '" + layer_name + "' does not serve terrain (quantized-mesh)");
    }
    if (path.rfind("terrain/", 0) == 0 &&
        std::find(served->formats.begin(), served->formats.end(), tiler::Format::Terrain3d) ==
            served->formats.end()) {
        throw NotFound("layer '" + layer_name + "' does not serve 3D Tiles terrain (terrain3d)");
    }
    Impl& s = *impl_;
    const std::string key = "d/" + layer_name + "/" + path;
    std::shared_ptr<const Blob> blob = s.cache.get(key);
    if (blob) {
        ++s.metrics.cache_hits;
    } else {
        ++s.metrics.cache_misses;
        std::string text;
        if (served->layer->document(path, text)) {
            blob = make_blob(std::move(text));
        } else {
            blob = make_failure(404, "layer '" + layer_name + "' has no document '" + path + "'");
        }
        s.cache.put(key, blob);
    }
    throw_if_failure(*blob);
    return blob;
}

} // namespace tb::server
