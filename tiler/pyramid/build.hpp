#pragma once
// The offline pyramid builder behind `terrabound build`: every tile of a layer, zoom by zoom,
// made by N worker threads and written to a TileStore by one writer, resumable and shardable.
//
// Order of events, which is what makes a build safe to kill at any moment:
//   0. the lock on the output (tiler/stores/output_lock.hpp), held until build_pyramid returns:
//      Exclusive for an unsharded run, Shared by the shards of one build, so no two builds mix
//      their tiles in one output;
//   1. the manifest document "build-manifest.json" (everything that decides the tiles' bytes);
//   2. tiles, each write atomic (directory: temp + fsync + rename; SQLite: batched transactions);
//   3. unsharded: the layer's tileset documents, "tileset.json" last, so a tileset never points
//      at a missing tile. An update (--update) writes "build-update.json" (the last build's
//      manifest) before step 1 and removes it after step 3, so an interrupted update is
//      finished by running it again (tiler/pyramid/update.hpp). A shard I of N instead writes
//      "build-shards/I-of-N.json" when all its tiles are in, and `--finalize` writes the tileset
//      once every shard has reported.
// Tiles are enumerated in a fixed order (zoom ascending, then row-major y, x) and each tile's
// bytes depend on the tile alone, so the output is the same whatever the thread count.
#include "tiler/formats/format.hpp"
#include "tiler/formats/quantized_mesh.hpp"
#include "tiler/layer.hpp"
#include "tiler/tile_grid.hpp"

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tb::tiler {

// Shard I of N, 0-based (0 <= index < count), like Kubernetes' JOB_COMPLETION_INDEX.
struct ShardSpec {
    int index = 0;
    int count = 1;
};

// "I/N", or "auto/N" to take I from JOB_COMPLETION_INDEX (Kubernetes Indexed Job) or else
// SLURM_ARRAY_TASK_ID. InputError naming the problem otherwise.
ShardSpec parse_shard(std::string_view text);
// The shard that owns a tile: a hash of (z, x, y), so shards get even shares of every zoom.
int shard_of(const TileId& id, int count);

enum class ProgressMode {
    Auto,  // a live bar when stderr is a terminal, log lines every few seconds otherwise
    Bar,   // a single line redrawn with '\r'
    Lines, // "info  build 1234/5000 tiles (24.7%), 310 tiles/s, eta 12 s" every few seconds
    Off,
};

struct BuildOptions {
    LayerOptions layer;            // name, sources, scheme, tile size, zooms, finest eps
    std::string output;            // a directory, or a file ending in .sqlite / .db
    std::optional<LonLatBox> bbox; // only tiles meeting this box (degrees)
    // Mesh formats make the layer's pyramid; DEM formats (terrarium, mapbox) the EPSG:3857 DEM
    // pyramid of tiler/dem_tiles.hpp, written alongside.
    std::vector<Format> formats{Format::Glb};
    // The quantized-mesh extensions stored with each .terrain tile, and listed by layer.json. A
    // static file cannot follow the Accept header, so by default it holds only the small
    // metadata extension (child availability, the tile's bound): the 64 KiB water mask and
    // the normals cost every client bytes that only a few ask for (`serve` sends those on
    // request).
    unsigned terrain_extensions = kMetadata;
    // Where the output will be hosted ("https://example.com/tiles"), for the absolute tile URLs
    // of the raster DEM TileJSON; empty: URLs relative to the TileJSON.
    std::string base_url;
    int threads = 0;       // worker threads; 0 = one per core
    bool resume = false;   // continue a build: same manifest, present tiles skipped
    bool force = false;    // delete the layer's existing tiles and documents first
    bool finalize = false; // after all shards: verify and write the tileset
    // Remake only the tiles a change of the DEMs since the last build touches, and remove the
    // ones it leaves without data (tiler/pyramid/update.hpp); the result is the store a full
    // build would make. Implies resume (missing tiles are made too); works with --shard.
    bool update = false;
    std::optional<ShardSpec> shard; // build only this shard's tiles (implies resume)
    ProgressMode progress = ProgressMode::Auto;
};

struct BuildSummary {
    std::int64_t planned = 0; // tiles of this run (this shard's share)
    std::int64_t written = 0; // tiles made and written now (DEM tiles included)
    std::int64_t skipped = 0; // already in the store (resume)
    std::int64_t empty = 0;   // no data there (NotFound): nothing written
    std::int64_t failed = 0;  // make_tile threw anything else: logged, nothing written
    std::int64_t removed = 0; // tiles an update removed (no data there any more)
    std::int64_t bytes = 0;   // bytes of tiles written now
    double seconds = 0;
    bool interrupted = false; // stopped by the stop flag (SIGINT/SIGTERM)
    bool tileset_written = false;
    // Of `written`, the raster DEM tiles (their own pyramid).
    std::int64_t dem_written = 0;
    // Tiles whose error measured at the source's pixels exceeds their zoom's eps, so that they
    // publish the larger bound (layers whose pixels are not on the scheme's grid only).
    std::int64_t over_eps = 0;
};

// One line of JSON: {"planned":..,"written":..,...,"interrupted":false}.
std::string to_json(const BuildSummary& summary);

// Runs a build. `stop` is polled: once it is true no new tile is started, tiles in flight are
// finished and written, and the summary comes back with interrupted = true. Throws InputError
// for bad options or a manifest mismatch, IoError when the store fails (the build stops at
// once; everything written before stays valid for --resume), and IoError at once, before
// touching the output, when another build holds it (the message names its pid and host).
BuildSummary build_pyramid(const BuildOptions& options, const std::atomic<bool>& stop);

} // namespace tb::tiler
