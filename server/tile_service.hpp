#pragma once
// TileService: what the HTTP handlers ask for tiles and tileset documents. No sockets here.
//
// A tile request goes: memory LRU (bounded in bytes) -> the layer's store, if any -> generation
// on a bounded pool. Generation is single-flight: concurrent requests for the same missing tile
// wait for one make_tile call. A generated tile is written to the store (atomically, by
// TileStore::put) and inserted in the LRU. Tiles with no data are remembered in the LRU too, so
// repeated requests outside the data stay cheap.
#include "core/error.hpp"
#include "server/encoding.hpp"
#include "server/metrics.hpp"
#include "tiler/formats/format.hpp"
#include "tiler/layer.hpp"
#include "tiler/stores/store.hpp"

#include <atomic>
#include <chrono>
#include <cstddef>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace tb::server {

struct ServedLayer {
    std::shared_ptr<const tiler::Layer> layer;
    std::vector<tiler::Format> formats;      // the formats served; others are 404
    std::shared_ptr<tiler::TileStore> store; // may be null; may be shared between layers
    // Whether tiles at eps levels (EpsChoice::level >= 0) go to the store too (StoreUse).
    bool store_eps_levels = true;
    // Whether .terrain tiles go to the store too: not when a build stored them with only some
    // quantized-mesh extensions (StoreUse::terrain_extensions).
    bool store_terrain = true;
};

// A configured layer that could not be opened at startup (its DEM is unreadable, damaged, ...):
// the other layers serve, and its routes answer 503 with `reason`.
struct UnavailableLayer {
    std::string name;
    std::string reason; // the error that stopped it, naming the file
};

// What a TileService serves at one moment: replaced whole when a layer is reloaded, so that a
// request sees one set from start to end.
struct LayerSet {
    std::vector<ServedLayer> served;
    std::vector<UnavailableLayer> unavailable;
};

// A request for an UnavailableLayer: HTTP 503 with the message.
struct Unavailable : Error {
    using Error::Error;
};

struct TileServiceOptions {
    std::size_t cache_bytes = std::size_t{256} << 20;
    int threads = 1;      // generation threads, >= 1
    int queue_limit = 64; // generations allowed to wait for a thread, >= 0
    // Requests allowed to wait for a generation at once (their own or another request's for the
    // same tile); past it they get 503 at once. 0: 2 x (threads + queue_limit), at most 1024.
    // Each waiting request holds an HTTP worker thread, so the server sizes its pool with it.
    int max_waiting = 0;
    // How long a request waits for the generation it queued to start. Past it the generation is
    // dropped, unstarted, and its requests get 503 (Retry-After) at once, rather than waiting
    // behind the whole queue; one that has started is waited for. 10 s by default: CesiumJS
    // does not retry a 3D Tiles tile or subtree that got 503, so a shorter wait turns a viewer's
    // first burst of cold tiles on a small server into holes (1 s failed the browser tests on 2
    // busy cores).
    std::chrono::milliseconds start_wait{10000};
    // How long a tile request may take in all (> 0): past it the request gets 503 (Retry-After),
    // and a generation whose every request has given up stops at its next checkpoint
    // (tiler::CancelFn) instead of using a core for nobody. start_wait counts within it: the
    // wait for a start is min(start_wait, deadline). A follower of a generation has its own
    // deadline, so the generation goes on while any of its requests still waits.
    std::chrono::milliseconds deadline{10000};
};

// An immutable response payload with its strong validator, or a remembered failure.
struct Blob {
    std::string bytes;
    std::string etag; // quoted, e.g. "\"3f2a...-1c40\""
    // 0 for a payload. A remembered answer otherwise, with the reason in `bytes`: 404 (no data
    // there, no such document) or 400 (the layer refused the request, e.g. an eps too fine for
    // the tile); tile() and document() rethrow it as NotFound / InputError.
    int failure = 0;

    // The payload in `coding` (gzip or br), compressed on first use and kept with the blob: a
    // cached document is compressed once per ETag. Thread-safe; counts compressions in
    // `metrics`. Sets `*made`, when given, if this call made the copy. TileService::encoded
    // also counts the copy against the memory cache's bound.
    const std::string& encoded(Coding coding, Metrics& metrics, bool* made = nullptr) const;
    // The payload in `coding` when it is already made (always for Identity), else nullptr:
    // never compresses, so it never takes long.
    const std::string* encoded_if_made(Coding coding) const;

private:
    mutable std::once_flag gzip_once_, brotli_once_;
    mutable std::string gzip_, brotli_;
    mutable std::atomic<bool> gzip_made_{false}, brotli_made_{false};
};

// Strong ETag of `bytes`: a 64-bit FNV-1a hash and the length, quoted.
std::string make_etag(std::string_view bytes);

class TileService {
public:
    TileService(std::vector<ServedLayer> layers,
                const TileServiceOptions& options,
                Metrics& metrics,
                std::vector<UnavailableLayer> unavailable = {});
    ~TileService(); // finishes queued generations, then joins the pool
    TileService(const TileService&) = delete;
    TileService& operator=(const TileService&) = delete;

    // The layers served now (bind the result before iterating: it keeps them alive).
    std::shared_ptr<const LayerSet> layers() const;
    std::shared_ptr<const ServedLayer> find(const std::string& name) const; // null: unknown
    // The layer named `name`: throws Unavailable for an unavailable one (with its reason),
    // NotFound for a name no layer has.
    std::shared_ptr<const ServedLayer> require(const std::string& name) const;

    // Serves `served` from now on in place of the layer of its name (served or unavailable;
    // added if neither). First, with no tile cached or stored meanwhile, runs `prepare` (which
    // readies the layer's store: tiler::prepare_store_for_serving). The layer's cached tiles
    // and documents and its generations in flight are forgotten, and a generation of the old
    // layer that finishes later neither caches nor stores its tile: no answer after the swap
    // comes from the old layer, and none mixes the two. Thread-safe.
    void replace_layer(ServedLayer served, const std::function<void(ServedLayer&)>& prepare = {});
    // The same, the layer answering 503 with `reason` from now on.
    void make_unavailable(const std::string& name, const std::string& reason);
    // Requests that may wait for generations at once (TileServiceOptions::max_waiting, resolved).
    int max_waiting() const;

    // blob.encoded(coding): a compressed copy made here counts against the memory cache's
    // bound (TileServiceOptions::cache_bytes) for as long as the cache keeps the blob, so that
    // tiles and documents sent in gzip and br do not hold several times the bound.
    const std::string& encoded(const Blob& blob, Coding coding);

    // The encoded tile, or nullptr when the generation queue or the requests waiting for
    // generations are at their limit (answer 503; decided at once, without waiting), when its
    // generation could not start within options.start_wait (503 after that wait), or when the
    // tile was not ready by options.deadline after the call (503 then). Throws
    // NotFound for an unknown layer, a format the layer does not serve, or a tile with no data;
    // InputError for an id outside the format's pyramid (the id is parsed into a ValidTile
    // here, where the layer and so its scheme are known: EPSG:3857 XYZ for raster DEM tiles,
    // the layer's scheme otherwise), an eps level the layer does not have (the same message for
    // every format), or an eps level asked of a format other than glb and drc.
    std::shared_ptr<const Blob> tile(const std::string& layer,
                                     const tiler::TileId& id,
                                     tiler::Format format,
                                     tiler::EpsChoice eps);

    // The tile when the memory cache holds it (a payload, not a remembered failure), else
    // nullptr. Never reads the store nor generates, so it never waits; what it returns is what
    // tile() would (a cached key passed tile()'s checks). Counts a cache hit when it finds one.
    std::shared_ptr<const Blob>
    cached_tile(const std::string& layer, const tiler::TileId& id, tiler::Format format);

    // The layer's quantized-mesh tile with only the extensions in `extensions` (a mask of
    // tiler::QuantizedMeshExtension): the tile with all of them, as tile() gives it, cut down
    // and cached per mask. nullptr when busy, as tile(); `eps` is checked as tile() checks it.
    std::shared_ptr<const Blob> terrain(const std::string& layer,
                                        const tiler::TileId& id,
                                        unsigned extensions,
                                        tiler::EpsChoice eps = {});

    // What terrain() gives when the memory cache holds it (the tile with all extensions and,
    // for fewer, its cut-down copy) and `usable` accepts it, else nullptr. Never generates, cuts
    // down or reads the store, so it never waits; counts a cache hit, as terrain() does, only
    // when it returns a tile.
    std::shared_ptr<const Blob> cached_terrain(const std::string& layer,
                                               const tiler::TileId& id,
                                               unsigned extensions,
                                               const std::function<bool(const Blob&)>& usable);

    // A tileset document of the layer ("tileset.json", "subtrees/0/0/0.subtree", ...). Throws
    // NotFound for an unknown layer or a path the layer has no document for. tile(), terrain()
    // and document() throw Unavailable for an unavailable layer.
    std::shared_ptr<const Blob> document(const std::string& layer, const std::string& path);

private:
    struct Impl;
    void swap_layer(const std::string& name,
                    std::optional<ServedLayer> served,
                    std::optional<UnavailableLayer> unavailable);
    mutable std::mutex set_mutex_; // guards set_ (the pointer; the set itself is immutable)
    std::shared_ptr<const LayerSet> set_;
    std::unique_ptr<Impl> impl_;
};

} // namespace tb::server
