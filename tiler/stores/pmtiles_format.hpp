#pragma once
// PMTiles version 3 (github.com/protomaps/PMTiles, spec/v3/spec.md), the parts a raster DEM
// archive needs: the 127-byte header, directories, Hilbert tile ids, gzip, and a reader that
// trusts nothing it reads.
//   header    little-endian fields at fixed offsets: "PMTiles", version 3, the offset and length
//             of the root directory, the JSON metadata, the leaf directories and the tile data,
//             counts, clustered flag, compressions, tile type, zooms, bounds and centre (e7);
//   directory a varint entry count, then four columns of varints: tile id deltas, run lengths,
//             lengths, and offsets (0 = right after the previous entry's bytes, else offset + 1);
//             an entry with run length 0 points at a leaf directory. Directories and metadata
//             are gzip-compressed here (internal compression 2); tiles are stored as they are.
// Entry offsets count from the start of their section (tile data, or leaf directories).
#include "tiler/tile_grid.hpp"

#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace tb::tiler::pmtiles {

inline constexpr std::size_t kHeaderSize = 127;
// The root directory must lie within the archive's first 16 KiB (spec, section 2).
inline constexpr std::uint64_t kRootLimit = 16384;
inline constexpr std::uint8_t kCompressionNone = 1, kCompressionGzip = 2;
inline constexpr std::uint8_t kTileTypePng = 2;

struct Header {
    std::uint64_t root_offset = 0, root_length = 0;
    std::uint64_t metadata_offset = 0, metadata_length = 0;
    std::uint64_t leaf_offset = 0, leaf_length = 0;
    std::uint64_t data_offset = 0, data_length = 0;
    std::uint64_t addressed_tiles = 0, tile_entries = 0, tile_contents = 0;
    bool clustered = false;
    std::uint8_t internal_compression = kCompressionGzip;
    std::uint8_t tile_compression = kCompressionNone;
    std::uint8_t tile_type = kTileTypePng;
    std::uint8_t min_zoom = 0, max_zoom = 0;
    std::int32_t min_lon_e7 = 0, min_lat_e7 = 0, max_lon_e7 = 0, max_lat_e7 = 0;
    std::uint8_t center_zoom = 0;
    std::int32_t center_lon_e7 = 0, center_lat_e7 = 0;
};

struct Entry {
    std::uint64_t tile_id = 0;
    std::uint64_t offset = 0;
    std::uint32_t length = 0;
    std::uint32_t run_length = 0; // 0: a leaf directory
};

// The tile's position on the Hilbert curves of zooms 0..z, counted across zooms: every tile of
// zoom z - 1 comes before every tile of zoom z. Requires an EPSG:3857 XYZ id, z <= kMaxZoom.
std::uint64_t tile_id(const TileId& id);
// The inverse: the XYZ tile of `id`; nullopt past zoom kMaxZoom.
std::optional<TileId> tile_of(std::uint64_t id);

std::string encode_header(const Header& h);
// Reads and checks a header of an archive of `file_size` bytes: magic, version, every section
// inside the file, the root directory inside the first 16 KiB, compressions this reader knows.
// InputError naming `name` otherwise.
Header decode_header(std::string_view bytes, std::uint64_t file_size, const std::string& name);

std::string encode_directory(std::span<const Entry> entries); // uncompressed
// Parses an uncompressed directory whose tile entries must lie inside `data_length` bytes and
// leaf entries inside `leaf_length`, with tile ids increasing. InputError naming `name`.
std::vector<Entry> decode_directory(std::string_view raw,
                                    std::uint64_t data_length,
                                    std::uint64_t leaf_length,
                                    const std::string& name);

std::string gzip(std::string_view bytes);
// Inflates a gzip stream of at most `max_out` bytes; InputError naming `name` when it is
// damaged or longer.
std::string gunzip(std::string_view bytes, std::size_t max_out, const std::string& name);

// What Terrabound keeps in the metadata JSON besides the spec's keys.
struct ArchiveContent {
    std::string layer;                            // "" when the archive names none
    std::string encoding;                         // "terrarium" | "mapbox" | ""
    std::map<std::string, std::string> documents; // the build's documents, by name
};
// The metadata JSON of an archive of `content`, with name, format, type, description, encoding,
// minzoom, maxzoom, bounds and center as TileJSON has them.
std::string metadata_json(const ArchiveContent& content, const Header& h);
// Reads `content` back from any metadata JSON (the "terrabound" object, else "name" and
// "encoding"). InputError naming `name` when it is not a JSON object.
ArchiveContent parse_metadata(std::string_view json, const std::string& name);

// Reads `length` bytes at `offset` of the archive, exactly, or throws IoError.
using ReadAt = std::function<std::string(std::uint64_t offset, std::uint64_t length)>;

// An archive opened for reading: header, metadata and root directory read and checked at once,
// leaf directories when a lookup reaches them (kept in a small cache). Safe from many threads.
class Reader {
public:
    // InputError naming `name` when the archive is damaged or not one this reader reads.
    Reader(std::string name, std::uint64_t size, ReadAt read);
    // The tile's bytes, or nullopt when the archive has none there. InputError when a leaf
    // directory on the way is damaged.
    std::optional<std::string> tile(const TileId& id) const;
    const Header& header() const { return header_; }
    const ArchiveContent& content() const { return content_; }
    // Calls fn(id, offset, length) for every tile the directories address (runs expanded), in
    // tile id order; for tests and tools. fn may throw to stop. InputError when a leaf
    // directory is damaged or listed twice.
    void for_each_entry(
        const std::function<void(std::uint64_t id, std::uint64_t offset, std::uint32_t length)>& fn)
        const;

private:
    std::vector<Entry> read_directory(std::uint64_t offset, std::uint64_t length) const;
    std::vector<Entry> leaf(const Entry& e) const; // a copy: the cache may be cleared
    void walk(const std::vector<Entry>& dir,
              int depth,
              std::uint64_t& budget,
              const std::function<void(std::uint64_t, std::uint64_t, std::uint32_t)>& fn) const;

    std::string name_;
    std::uint64_t size_ = 0;
    ReadAt read_;
    Header header_;
    ArchiveContent content_;
    std::vector<Entry> root_;
    mutable std::mutex mutex_;
    mutable std::map<std::uint64_t, std::vector<Entry>> leaves_; // by leaf offset
};

// Tiles of an archive to write: ids, lengths and a content hash, gathered before any byte is.
struct PlannedTile {
    std::uint64_t tile_id = 0;
    TileId id;
    std::uint32_t length = 0;
    std::uint64_t hash_a = 0, hash_b = 0; // two independent 64-bit hashes of the bytes
};
void hash_tile(std::string_view bytes, PlannedTile& t);

// Writes the archive of `tiles` (any order; ids unique) to `out_path` through a temporary file,
// fsync and rename: the tiles sorted by tile id, identical contents stored once (same length
// and both hashes) and consecutive ones as one run, the directories split into leaves when the
// root would not fit in 16 KiB. `bytes_of` gives a planned tile's bytes, which must hash as
// planned. IoError naming the path when the write fails.
void write_archive(const std::string& out_path,
                   std::vector<PlannedTile> tiles,
                   const ArchiveContent& content,
                   const std::function<std::string(const TileId&)>& bytes_of);

} // namespace tb::tiler::pmtiles
