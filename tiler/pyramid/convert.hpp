#pragma once
// `terrabound build STORE.sqlite -o OUT.mbtiles|OUT.pmtiles`: one layer's raster DEM tiles of a
// Terrabound SQLite store (tiler/stores/store_sqlite.cpp) copied into a standard container, as
// a build straight into the container would have written it.
//
// What is copied: the tiles of one layer in one DEM encoding (terrarium or mapbox), their bytes
// as they are (no re-encoding), each checked against its CRC-32 as the store's own reads check
// it; the layer's build manifest, with the formats, terrain extensions and shard count a build
// of that encoding alone records (so `build --resume` and `serve` treat the container as built
// directly); the encoding's TileJSON. The container's own metadata (bounds, zooms, centre,
// format, encoding) is made from the tiles by the container's code, as a build makes it. So
// the output equals a direct build's: tile for tile, and for PMTiles byte for byte.
//
// Only a finished build is converted: the layer must have a build manifest listing the encoding
// and, unless it was a --bbox build, the TileJSON a build writes last. Tiles a server cached
// are not a pyramid; a container made of them would have holes.
//
// The output appears whole or not at all: PMTiles is assembled in a temporary file and renamed
// into place (pmtiles::write_archive); MBTiles is written to OUT.mbtiles.converting, finished,
// fsynced and renamed. The input is only read, in one read transaction, so a server or build
// writing it meanwhile does not change what is copied.
#include "tiler/formats/format.hpp"

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>

namespace tb::tiler {

struct ConvertOptions {
    std::string input;            // a Terrabound SQLite store (.sqlite or .db)
    std::string output;           // OUT.mbtiles or OUT.pmtiles
    std::string layer;            // empty: the only layer holding raster DEM tiles
    std::optional<Format> format; // terrarium or mapbox; nullopt: the layer's only one
    bool force = false;           // replace an existing output
};

struct ConvertSummary {
    std::string layer;
    Format format = Format::Terrarium;
    std::int64_t tiles = 0; // tiles written
    std::int64_t bytes = 0; // their bytes
    double seconds = 0;
    bool interrupted = false; // stopped by the stop flag: nothing was written
};

// True when `path` names an SQLite store by its extension (.sqlite or .db), the inputs `build`
// converts instead of reading as a DEM.
bool is_store_input(const std::string& path);

// Converts. Polls `stop`: once it is true the conversion stops, removes what it wrote and
// returns with interrupted = true. Throws InputError when the input is not a Terrabound store,
// the layer or encoding is not there (the message lists what the store holds), the build is
// unfinished, or the output exists without `force`; IoError when a tile is damaged or a read
// or write fails (nothing is left at the output then either), or another build holds the
// output's lock.
ConvertSummary convert_store(const ConvertOptions& options, const std::atomic<bool>& stop);

} // namespace tb::tiler
