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
#include <optional>
#include <shared_mutex>
#include <thread>
#include <unordered_map>

namespace tb::server {
namespace {

// Nice value of the generation threads (0 is the default, 19 the lowest priority).
constexpr int kGenerationNice = 10;

// Default ceiling of TileServiceOptions::max_waiting (each waiter holds an HTTP thread).
constexpr long long kMaxWaiting = 1024;

using Clock = std::chrono::steady_clock;

// States of a queued generation (Job::state): a request drops it when it has not started within
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

    // Drops every entry whose key starts with one of `prefixes`.
    void erase_prefixed(const std::vector<std::string>& prefixes) {
        std::lock_guard<std::mutex> lock(mutex_);
        for (auto it = order_.begin(); it != order_.end();) {
            const auto next = std::next(it);
            if (std::any_of(prefixes.begin(), prefixes.end(), [&](const std::string& p) {
                    return it->key.compare(0, p.size(), p) == 0;
                })) {
                erase(it);
            }
            it = next;
        }
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

namespace {

// A queued generation and the requests waiting for it.
struct Job {
    std::atomic<int> state{kQueued}; // kQueued, kStarted or kDropped
    // Every request waiting for it passed its deadline: it stops at its next checkpoint.
    std::atomic<bool> cancelled{false};
    int waiters = 0; // requests waiting for it (under TileService::Impl::flight_mutex)
};

using Promise = std::promise<std::shared_ptr<const Blob>>;

// One tile being fetched: the answer every request for it waits for (nullptr: busy), and the
// generation that makes it.
struct Flight {
    std::shared_future<std::shared_ptr<const Blob>> result;
    std::shared_ptr<Job> job;
};

// A tile request past its checks.
struct TileRequest {
    std::shared_ptr<const ServedLayer> served; // as the request found it: one layer throughout
    std::string layer;
    tiler::ValidTile tile; // in the format's pyramid (check_tile)
    tiler::Format format;
    tiler::EpsChoice eps;
    std::string key; // the memory cache's
    Clock::time_point deadline;

    bool in_store() const {
        return served->store && (eps.level < 0 || served->store_eps_levels) &&
               (format != tiler::Format::Terrain || served->store_terrain);
    }
    tiler::TileKey store_key() const { return {layer, tile.id(), format, eps.level}; }
};

} // namespace

struct TileService::Impl {
    Impl(const TileServiceOptions& o, Metrics& m, const TileService& service)
        : options(o), metrics(m), cache(o.cache_bytes, m), owner(service),
          pool(o.threads, lower_priority) {}

    TileServiceOptions options; // start_wait at most deadline
    Metrics& metrics;
    LruCache cache;
    const TileService& owner;
    // Held shared while a tile or document is cached or stored, exclusively while a layer is
    // replaced (TileService::swap_layer), so nothing of a replaced layer is kept after it.
    std::shared_mutex swap_mutex;

    // Runs `keep` (caching or storing what `served` made) unless `served` has been replaced.
    template <typename Keep> void keep_if_current(const ServedLayer& served, Keep&& keep) {
        std::shared_lock<std::shared_mutex> lock(swap_mutex);
        const auto set = owner.layers();
        for (const ServedLayer& l : set->served) {
            if (&l == &served) {
                keep();
                return;
            }
        }
    }

    // Forgets what the memory cache and the flights hold of layer `name` (it was replaced).
    void forget(const std::string& name) {
        cache.erase_prefixed({"t/" + name + "/", "d/" + name + "/"});
        const std::string prefix = "t/" + name + "/";
        std::lock_guard<std::mutex> lock(flight_mutex);
        for (auto it = flights.begin(); it != flights.end();) {
            it = it->first.compare(0, prefix.size(), prefix) == 0 ? flights.erase(it)
                                                                  : std::next(it);
        }
    }

    std::mutex flight_mutex; // guards flights, pending, waiting and every Job::waiters
    std::map<std::string, Flight> flights;
    int pending = 0; // generations queued or running
    int waiting = 0; // requests waiting for a generation

    // A request counted in `waiting` and its job's waiters until it leaves, however it leaves.
    struct Waiting {
        Impl& s;
        const std::string& key;
        std::shared_ptr<Job> job;
        bool gave_up = false; // left at its deadline, without an answer
        ~Waiting() { s.leave(key, job, gave_up); }
    };

    std::shared_ptr<const Blob> fetch(const TileRequest& r);
    std::shared_ptr<const Blob> from_store(const TileRequest& r, Promise& promise, const Job& job);
    bool admit(const TileRequest& r, Promise& promise, Job& job);
    std::shared_ptr<const Blob>
    wait(const TileRequest& r, const Flight& flight, Promise* promise, bool& gave_up);
    bool drop_unstarted(const std::string& key, const Flight& flight, Promise& promise);
    void leave(const std::string& key, const std::shared_ptr<Job>& job, bool gave_up);
    void generate(const TileRequest& r, Promise& promise, Job& job);
    void keep(const TileRequest& r, const std::shared_ptr<const Blob>& made);
    std::shared_ptr<const Blob>
    make(const TileRequest& r, const Job& job, std::exception_ptr& error);

    // Forgets the flight of `key` if `job` still makes it (a cancelled one may have been
    // replaced by a newer flight meanwhile). Call with flight_mutex held.
    void erase_flight(const std::string& key, const Job& job) {
        if (const auto it = flights.find(key);
            it != flights.end() && it->second.job.get() == &job) {
            flights.erase(it);
        }
    }

    ThreadPool pool; // last: destroyed (drained and joined) first
};

// The tile of a request the memory cache does not hold: from the flight already fetching it,
// else from the store, else from a generation this request queues. nullptr when busy.
std::shared_ptr<const Blob> TileService::Impl::fetch(const TileRequest& r) {
    Flight flight;
    std::shared_ptr<Promise> promise; // set when this request leads the flight
    {
        std::lock_guard<std::mutex> lock(flight_mutex);
        if (const auto it = flights.find(r.key); it != flights.end()) {
            if (waiting >= options.max_waiting) {
                ++metrics.queue_rejections;
                return nullptr;
            }
            flight = it->second;
            ++waiting;
            ++flight.job->waiters;
            ++metrics.single_flight_waits;
        } else {
            promise = std::make_shared<Promise>();
            flight = {promise->get_future().share(), std::make_shared<Job>()};
            flights.emplace(r.key, flight);
        }
    }
    if (promise) {
        if (auto stored = from_store(r, *promise, *flight.job)) {
            return stored;
        }
        if (!admit(r, *promise, *flight.job)) {
            ++metrics.queue_rejections;
            return nullptr;
        }
        pool.submit([this, r, promise, job = flight.job] { generate(r, *promise, *job); });
    }
    Waiting waiting_for{*this, r.key, flight.job};
    return wait(r, flight, promise.get(), waiting_for.gave_up);
}

// The tile from the layer's store when it is there, answering the flight `promise` leads;
// nullptr when the store has no such tile or the layer no store.
std::shared_ptr<const Blob>
TileService::Impl::from_store(const TileRequest& r, Promise& promise, const Job& job) {
    if (!r.in_store()) {
        return nullptr;
    }
    std::optional<std::string> stored;
    try {
        stored = r.served->store->get(r.store_key()); // stores are thread-safe
    } catch (...) {
        std::lock_guard<std::mutex> lock(flight_mutex);
        promise.set_exception(std::current_exception());
        erase_flight(r.key, job);
        throw;
    }
    if (!stored) {
        return nullptr;
    }
    ++metrics.store_hits;
    auto found = make_blob(std::move(*stored));
    keep_if_current(*r.served, [&] { cache.put(r.key, found); });
    std::lock_guard<std::mutex> lock(flight_mutex);
    promise.set_value(found);
    erase_flight(r.key, job);
    return found;
}

// Counts the generation of the flight this request leads, and the request as waiting for it,
// when the queue and the waiters are below their limits: true, and the caller queues it.
// Otherwise the flight is answered busy (its followers too) and false.
bool TileService::Impl::admit(const TileRequest& r, Promise& promise, Job& job) {
    {
        std::lock_guard<std::mutex> lock(flight_mutex);
        if (pending >= options.threads + options.queue_limit || waiting >= options.max_waiting) {
            promise.set_value(nullptr);
            erase_flight(r.key, job);
            return false;
        }
        ++pending;
        ++waiting;
        ++job.waiters;
    }
    ++metrics.queued_generations;
    return true;
}

// Waits for the flight's answer until the request's deadline; the lead (`promise` set) first
// waits min(start_wait, deadline) for its generation to start, and drops it unstarted past
// that. nullptr when busy, dropped or past the deadline (then `gave_up`).
std::shared_ptr<const Blob> TileService::Impl::wait(const TileRequest& r,
                                                    const Flight& flight,
                                                    Promise* promise,
                                                    bool& gave_up) {
    if (promise != nullptr) {
        const auto start_by = std::min(Clock::now() + options.start_wait, r.deadline);
        if (flight.result.wait_until(start_by) != std::future_status::ready &&
            drop_unstarted(r.key, flight, *promise)) {
            ++metrics.queue_rejections;
            return nullptr;
        }
    }
    if (flight.result.wait_until(r.deadline) != std::future_status::ready) {
        gave_up = true;
        ++metrics.deadline_expiries;
        return nullptr;
    }
    std::shared_ptr<const Blob> blob = flight.result.get(); // rethrows InputError / IoError
    if (!blob) {
        ++metrics.queue_rejections; // its generation was dropped unstarted, or not admitted
    }
    return blob;
}

// Drops the flight's generation if it has not started: its followers get busy too. True then;
// false when it has started (its answer is coming).
bool TileService::Impl::drop_unstarted(const std::string& key,
                                       const Flight& flight,
                                       Promise& promise) {
    int queued = kQueued;
    if (!flight.job->state.compare_exchange_strong(queued, kDropped)) {
        return false;
    }
    --metrics.queued_generations;
    std::lock_guard<std::mutex> lock(flight_mutex);
    --pending;
    promise.set_value(nullptr);
    erase_flight(key, *flight.job);
    return true;
}

// A request stops waiting for `job`. When it gave up at its deadline and was the last one
// waiting, the generation is cancelled (it stops at its next checkpoint) and forgotten, so that
// the next request for the tile starts afresh instead of joining work that is about to stop.
void TileService::Impl::leave(const std::string& key,
                              const std::shared_ptr<Job>& job,
                              bool gave_up) {
    std::lock_guard<std::mutex> lock(flight_mutex);
    --waiting;
    if (--job->waiters > 0 || !gave_up) {
        return;
    }
    job->cancelled = true;
    erase_flight(key, *job);
}

// Runs on the pool: makes the tile unless the generation was dropped, stores and caches it,
// and answers the flight.
void TileService::Impl::generate(const TileRequest& r, Promise& promise, Job& job) {
    int queued = kQueued;
    if (!job.state.compare_exchange_strong(queued, kStarted)) {
        return; // dropped (start_wait): its requests were answered busy
    }
    --metrics.queued_generations;
    ++metrics.in_flight_generations;
    const auto start = Clock::now();
    std::exception_ptr error;
    const std::shared_ptr<const Blob> made = make(r, job, error);
    metrics.generation_micros += static_cast<std::uint64_t>(
        std::chrono::duration_cast<std::chrono::microseconds>(Clock::now() - start).count());
    --metrics.in_flight_generations;
    if (made) {
        keep_if_current(*r.served, [&] { keep(r, made); });
    }
    std::lock_guard<std::mutex> lock(flight_mutex);
    --pending;
    if (error) {
        promise.set_exception(error);
    } else {
        promise.set_value(made);
    }
    erase_flight(r.key, job);
}

// Stores (a payload) and caches what a generation made, even when nobody waits any more: the
// next request is a hit.
void TileService::Impl::keep(const TileRequest& r, const std::shared_ptr<const Blob>& made) {
    if (made->failure == 0 && r.in_store() && r.served->store->keeps(r.store_key())) {
        try {
            r.served->store->put(r.store_key(), made->bytes);
        } catch (const std::exception& e) {
            ++metrics.store_write_failures;
            log::warn(std::string("tile not stored: ") + e.what());
        }
    }
    cache.put(r.key, made);
}

// The request's tile, or a remembered failure (404: no data; 400: refused, deterministic for
// this tile and eps, so not remeshed), or nullptr: cancelled (every request gave up), or
// another error, set in `error`.
std::shared_ptr<const Blob>
TileService::Impl::make(const TileRequest& r, const Job& job, std::exception_ptr& error) {
    const tiler::Layer& layer = *r.served->layer;
    const tiler::CancelFn cancelled = [&job] { return job.cancelled.load(); };
    try {
        auto made = make_blob(tiler::is_dem_format(r.format)
                                  ? tiler::make_dem_tile(layer, r.tile, r.format, cancelled)
                                  : layer.make_tile(r.tile, r.format, r.eps, cancelled));
        ++metrics.tiles_generated;
        return made;
    } catch (const tiler::Cancelled& e) {
        ++metrics.generations_cancelled;
        log::info(std::string(e.what()) + ": every request for it passed its deadline");
    } catch (const NotFound& e) {
        ++metrics.tiles_empty;
        return make_failure(404, e.what());
    } catch (const InputError& e) {
        return make_failure(400, e.what());
    } catch (...) {
        error = std::current_exception();
    }
    return nullptr;
}

TileService::TileService(std::vector<ServedLayer> layers,
                         const TileServiceOptions& options,
                         Metrics& metrics,
                         std::vector<UnavailableLayer> unavailable)
    : set_(std::make_shared<const LayerSet>(LayerSet{std::move(layers), std::move(unavailable)})) {
    TB_ASSERT(options.threads >= 1 && options.queue_limit >= 0 && options.max_waiting >= 0);
    TB_ASSERT(options.deadline.count() > 0 && options.start_wait.count() > 0);
    TileServiceOptions resolved = options;
    resolved.start_wait = std::min(options.start_wait, options.deadline);
    if (resolved.max_waiting == 0) {
        resolved.max_waiting = static_cast<int>(
            std::min<long long>(2LL * (options.threads + options.queue_limit), kMaxWaiting));
    }
    impl_ = std::make_unique<Impl>(resolved, metrics, *this);
    TB_ASSERT(std::all_of(set_->served.begin(), set_->served.end(), [](const ServedLayer& l) {
        return l.layer != nullptr;
    }));
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

std::shared_ptr<const LayerSet> TileService::layers() const {
    std::lock_guard<std::mutex> lock(set_mutex_);
    return set_;
}

std::shared_ptr<const ServedLayer> TileService::find(const std::string& name) const {
    const auto set = layers();
    for (const auto& l : set->served) {
        if (l.layer->options().name == name) {
            return std::shared_ptr<const ServedLayer>(set, &l); // keeps the set alive
        }
    }
    return nullptr;
}

std::shared_ptr<const ServedLayer> TileService::require(const std::string& name) const {
    const auto set = layers();
    for (const auto& l : set->served) {
        if (l.layer->options().name == name) {
            return std::shared_ptr<const ServedLayer>(set, &l);
        }
    }
    for (const auto& u : set->unavailable) {
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

// The checks before a mesh tile is looked up: NotFound outside the layer's zooms or data.
void check_mesh_tile(const tiler::Layer& layer, const tiler::ValidTile& tile) {
    if (tile.z() < layer.min_zoom() || tile.z() > layer.max_zoom() || !layer.may_have_tile(tile)) {
        throw NotFound("layer '" + layer.options().name + "' has no tile " +
                       tiler::tile_name(tile.id()) + " (zooms " + std::to_string(layer.min_zoom()) +
                       ".." + std::to_string(layer.max_zoom()) + ")");
    }
}

// The same for a quantized-mesh tile, which every zoom up to max_zoom has (filler where the
// layer has no data).
void check_terrain_tile(const tiler::Layer& layer, const tiler::ValidTile& tile) {
    if (tile.z() > layer.max_zoom()) {
        throw NotFound("layer '" + layer.options().name + "' has no terrain tile " +
                       tiler::tile_name(tile.id()) + " (max zoom " +
                       std::to_string(layer.max_zoom()) + "; clients upsample its parent)");
    }
}

// The same for a raster DEM tile.
void check_dem_tile(const tiler::Layer& layer, const tiler::ValidTile& tile) {
    const tiler::TileRange r = tiler::dem_tiles_at(layer, tile.z());
    if (r.empty() || tile.x() < r.x0 || tile.x() > r.x1 || tile.y() < r.y0 || tile.y() > r.y1) {
        const tiler::DemTilePlan plan = tiler::dem_tile_plan(layer);
        throw NotFound("layer '" + layer.options().name + "' has no DEM tile " +
                       tiler::tile_name(tile.id()) + " (DEM zooms " +
                       std::to_string(plan.min_zoom) + ".." + std::to_string(plan.max_zoom) + ")");
    }
}

// The checks of a tile request, before any lookup: NotFound for a format the layer does not
// serve, then check_eps, then the id parsed as a tile of the format's pyramid (InputError
// outside it): EPSG:3857 XYZ for a raster DEM tile whatever the layer's scheme, the layer's
// scheme otherwise; then that pyramid's checks. Returns the tile.
tiler::ValidTile check_tile(const ServedLayer& served,
                            const tiler::TileId& id,
                            tiler::Format format,
                            tiler::EpsChoice eps) {
    const tiler::Layer& layer = *served.layer;
    if (std::find(served.formats.begin(), served.formats.end(), format) == served.formats.end()) {
        throw NotFound("layer '" + layer.options().name + "' does not serve ." +
                       tiler::extension(format) + " tiles");
    }
    check_eps(layer, format, eps);
    if (tiler::is_dem_format(format)) {
        const tiler::ValidTile tile = tiler::ValidTile::parse(tiler::Scheme::Mercator, id);
        check_dem_tile(layer, tile);
        return tile;
    }
    const tiler::ValidTile tile = layer.tile(id);
    if (tiler::is_terrain_format(format)) {
        check_terrain_tile(layer, tile);
    } else {
        check_mesh_tile(layer, tile);
    }
    return tile;
}

} // namespace

std::shared_ptr<const Blob> TileService::tile(const std::string& layer_name,
                                              const tiler::TileId& id,
                                              tiler::Format format,
                                              tiler::EpsChoice eps) {
    Impl& s = *impl_;
    const auto deadline = Clock::now() + s.options.deadline;
    const std::shared_ptr<const ServedLayer> served = require(layer_name);
    const TileRequest r{served,
                        layer_name,
                        check_tile(*served, id, format, eps),
                        format,
                        eps,
                        tile_key(layer_name, id, format, eps.level),
                        deadline};
    std::shared_ptr<const Blob> blob = s.cache.get(r.key);
    if (blob) {
        ++s.metrics.cache_hits;
    } else {
        ++s.metrics.cache_misses;
        blob = s.fetch(r);
        if (!blob) {
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
    const std::shared_ptr<const ServedLayer> served = require(layer_name);
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
        s.keep_if_current(*served, [&] { s.cache.put(key, blob); });
    }
    throw_if_failure(*blob);
    return blob;
}

void TileService::replace_layer(ServedLayer served,
                                const std::function<void(ServedLayer&)>& prepare) {
    TB_ASSERT(served.layer != nullptr);
    const std::string name = served.layer->options().name;
    std::unique_lock<std::shared_mutex> lock(impl_->swap_mutex);
    if (prepare) {
        prepare(served);
    }
    swap_layer(name, std::move(served), std::nullopt);
}

void TileService::make_unavailable(const std::string& name, const std::string& reason) {
    std::unique_lock<std::shared_mutex> lock(impl_->swap_mutex);
    swap_layer(name, std::nullopt, UnavailableLayer{name, reason});
}

// With swap_mutex held: a new set with `name` as `served` or `unavailable` (in its old place
// when it was served), then the old layer's cache entries and flights forgotten.
void TileService::swap_layer(const std::string& name,
                             std::optional<ServedLayer> served,
                             std::optional<UnavailableLayer> unavailable) {
    auto next = std::make_shared<LayerSet>(*layers());
    auto& u = next->unavailable;
    u.erase(std::remove_if(
                u.begin(), u.end(), [&](const UnavailableLayer& l) { return l.name == name; }),
            u.end());
    auto& s = next->served;
    const auto at = std::find_if(
        s.begin(), s.end(), [&](const ServedLayer& l) { return l.layer->options().name == name; });
    if (served && at != s.end()) {
        *at = std::move(*served);
    } else {
        if (at != s.end()) {
            s.erase(at);
        }
        if (served) {
            s.push_back(std::move(*served));
        }
    }
    if (unavailable) {
        u.push_back(std::move(*unavailable));
    }
    {
        std::lock_guard<std::mutex> lock(set_mutex_);
        set_ = std::move(next);
    }
    impl_->forget(name);
}

} // namespace tb::server
