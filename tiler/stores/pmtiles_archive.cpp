// PMTiles v3 archives: the reader and the writer (pmtiles_format.hpp).
#include "core/error.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/atomic_file.hpp"
#include "tiler/stores/pmtiles_format.hpp"

#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <tuple>

namespace tb::tiler::pmtiles {
namespace {

// Bounds on what a reader inflates or reads in one piece: far above what a writer makes (the
// root is at most 16 KiB compressed, leaves a few hundred KiB), low enough that a damaged length
// cannot exhaust memory.
constexpr std::uint64_t kMaxSection = 64u << 20;
constexpr int kMaxDepth = 4;           // root, leaves, and two more levels at most
constexpr std::size_t kLeafCache = 64; // leaf directories kept parsed
constexpr std::size_t kFirstLeafSize = 4096;

std::int32_t e7(double degrees) {
    return static_cast<std::int32_t>(std::lround(degrees * 1e7));
}

// The last entry whose tile id is at most `tid`, or nullptr.
const Entry* entry_before(const std::vector<Entry>& dir, std::uint64_t tid) {
    auto it = std::upper_bound(
        dir.begin(), dir.end(), tid, [](std::uint64_t t, const Entry& e) { return t < e.tile_id; });
    return it == dir.begin() ? nullptr : &*(it - 1);
}

} // namespace

void hash_tile(std::string_view bytes, PlannedTile& t) {
    std::uint64_t fnv = 1469598103934665603ull;
    for (unsigned char c : bytes) {
        fnv = (fnv ^ c) * 1099511628211ull;
    }
    const auto* data = reinterpret_cast<const Bytef*>(bytes.data());
    const auto size = static_cast<uInt>(bytes.size());
    t.length = static_cast<std::uint32_t>(bytes.size());
    t.hash_a = fnv;
    t.hash_b = (std::uint64_t{crc32(0, data, size)} << 32) | adler32(1, data, size);
}

// ---- reading ----

Reader::Reader(std::string name, std::uint64_t size, ReadAt read)
    : name_(std::move(name)), size_(size), read_(std::move(read)) {
    if (size_ < kHeaderSize) {
        throw InputError(name_ + ": " + std::to_string(size_) +
                         " bytes, shorter than a PMTiles header; the file is cut short or is not "
                         "an archive");
    }
    header_ = decode_header(read_(0, kHeaderSize), size_, name_);
    if (header_.metadata_length > kMaxSection) {
        throw InputError(name_ + ": metadata of " + std::to_string(header_.metadata_length) +
                         " bytes; the file is damaged");
    }
    std::string meta = read_(header_.metadata_offset, header_.metadata_length);
    if (header_.internal_compression == kCompressionGzip) {
        meta = gunzip(meta, kMaxSection, name_);
    }
    content_ = parse_metadata(meta, name_);
    root_ = read_directory(header_.root_offset, header_.root_length);
}

std::vector<Entry> Reader::read_directory(std::uint64_t offset, std::uint64_t length) const {
    if (length > kMaxSection) {
        throw InputError(name_ + ": a directory of " + std::to_string(length) +
                         " bytes; the file is damaged");
    }
    std::string raw = read_(offset, length);
    if (header_.internal_compression == kCompressionGzip) {
        raw = gunzip(raw, kMaxSection, name_);
    }
    return decode_directory(raw, header_.data_length, header_.leaf_length, name_);
}

std::vector<Entry> Reader::leaf(const Entry& e) const {
    std::lock_guard lock(mutex_);
    auto it = leaves_.find(e.offset);
    if (it == leaves_.end()) {
        if (leaves_.size() >= kLeafCache) {
            leaves_.clear();
        }
        it = leaves_.emplace(e.offset, read_directory(header_.leaf_offset + e.offset, e.length))
                 .first;
    }
    return it->second;
}

std::optional<std::string> Reader::tile(const TileId& id) const {
    const std::int64_t n = std::int64_t{1} << std::clamp(id.z, 0, kMaxZoom);
    if (id.z < 0 || id.z > kMaxZoom || id.x < 0 || id.y < 0 || id.x >= n || id.y >= n) {
        return std::nullopt;
    }
    const std::uint64_t tid = tile_id(id);
    std::vector<Entry> dir = root_;
    for (int depth = 0; depth < kMaxDepth; ++depth) {
        const Entry* e = entry_before(dir, tid);
        if (e == nullptr) {
            return std::nullopt;
        }
        if (e->run_length > 0) {
            if (tid - e->tile_id >= e->run_length) {
                return std::nullopt;
            }
            return read_(header_.data_offset + e->offset, e->length);
        }
        dir = leaf(*e);
    }
    throw InputError(name_ + ": directories nest deeper than " + std::to_string(kMaxDepth) +
                     " levels; the file is damaged");
}

// `budget`: directory bytes left to read. A valid archive reads each leaf once, so reading more
// than the directory sections hold means leaves are listed twice (a damaged file that would
// otherwise take exponential time).
void Reader::walk(
    const std::vector<Entry>& dir,
    int depth,
    std::uint64_t& budget,
    const std::function<void(std::uint64_t, std::uint64_t, std::uint32_t)>& fn) const {
    if (depth >= kMaxDepth) {
        throw InputError(name_ + ": directories nest deeper than " + std::to_string(kMaxDepth) +
                         " levels; the file is damaged");
    }
    for (const auto& e : dir) {
        if (e.run_length == 0) {
            if (e.length > budget) {
                throw InputError(name_ + ": leaf directories are listed more than once; the file "
                                         "is damaged");
            }
            budget -= e.length;
            walk(read_directory(header_.leaf_offset + e.offset, e.length), depth + 1, budget, fn);
            continue;
        }
        for (std::uint32_t i = 0; i < e.run_length; ++i) {
            fn(e.tile_id + i, e.offset, e.length);
        }
    }
}

void Reader::for_each_entry(
    const std::function<void(std::uint64_t, std::uint64_t, std::uint32_t)>& fn) const {
    std::uint64_t budget = header_.leaf_length;
    walk(root_, 0, budget, fn);
}

// ---- writing ----

namespace {

struct Directories {
    std::string root, leaves; // compressed
};

// The root alone when it fits in the first 16 KiB beside the header; else leaves of ever more
// entries until the root listing them does.
Directories make_directories(const std::vector<Entry>& entries) {
    Directories d;
    d.root = gzip(encode_directory(entries));
    std::size_t leaf_size = kFirstLeafSize;
    while (d.root.size() > kRootLimit - kHeaderSize) {
        d.leaves.clear();
        std::vector<Entry> root;
        for (std::size_t i = 0; i < entries.size(); i += leaf_size) {
            const std::size_t end = std::min(entries.size(), i + leaf_size);
            const std::string leaf =
                gzip(encode_directory(std::span<const Entry>(entries.data() + i, end - i)));
            root.push_back(
                {entries[i].tile_id, d.leaves.size(), static_cast<std::uint32_t>(leaf.size()), 0});
            d.leaves += leaf;
        }
        d.root = gzip(encode_directory(root));
        leaf_size *= 2;
    }
    return d;
}

// Zooms, bounds (the finest zoom's tiles) and centre of the archive.
void describe_tiles(const std::vector<PlannedTile>& tiles, Header& h) {
    if (tiles.empty()) {
        return;
    }
    int min_z = kMaxZoom, max_z = 0;
    for (const auto& t : tiles) {
        min_z = std::min(min_z, t.id.z);
        max_z = std::max(max_z, t.id.z);
    }
    LonLatBox b{180, 90, -180, -90};
    for (const auto& t : tiles) {
        if (t.id.z == max_z) {
            const LonLatBox tb = tile_bounds(Scheme::Mercator, t.id);
            b = {std::min(b.west, tb.west),
                 std::min(b.south, tb.south),
                 std::max(b.east, tb.east),
                 std::max(b.north, tb.north)};
        }
    }
    h.min_zoom = static_cast<std::uint8_t>(min_z);
    h.max_zoom = static_cast<std::uint8_t>(max_z);
    h.min_lon_e7 = e7(b.west);
    h.min_lat_e7 = e7(b.south);
    h.max_lon_e7 = e7(b.east);
    h.max_lat_e7 = e7(b.north);
    h.center_zoom = static_cast<std::uint8_t>((min_z + max_z) / 2);
    h.center_lon_e7 = e7((b.west + b.east) / 2);
    h.center_lat_e7 = e7((b.south + b.north) / 2);
}

// Entries in tile id order: a tile with the previous entry's content right after it extends
// its run, one whose content was seen before points at those bytes, any other gets new bytes
// (listed in `fresh`, in the order they are written).
std::vector<Entry> plan_entries(const std::vector<PlannedTile>& tiles,
                                std::vector<const PlannedTile*>& fresh,
                                std::uint64_t& data_length) {
    using ContentKey = std::tuple<std::uint32_t, std::uint64_t, std::uint64_t>;
    std::map<ContentKey, std::uint64_t> seen; // content -> offset
    std::vector<Entry> entries;
    ContentKey last{};
    for (const auto& t : tiles) {
        const ContentKey key{t.length, t.hash_a, t.hash_b};
        if (!entries.empty() && key == last &&
            entries.back().tile_id + entries.back().run_length == t.tile_id &&
            entries.back().run_length < UINT32_MAX) {
            ++entries.back().run_length;
            continue;
        }
        auto [it, added] = seen.emplace(key, data_length);
        if (added) {
            fresh.push_back(&t);
            data_length += t.length;
        }
        entries.push_back({t.tile_id, it->second, t.length, 1});
        last = key;
    }
    return entries;
}

void write_all(std::FILE* f, std::string_view bytes, const std::string& path) {
    if (std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size()) {
        throw IoError(path + ": write failed (" + std::strerror(errno) +
                      "); free space and build again with --resume");
    }
}

} // namespace

void write_archive(const std::string& out_path,
                   std::vector<PlannedTile> tiles,
                   const ArchiveContent& content,
                   const std::function<std::string(const TileId&)>& bytes_of) {
    std::sort(tiles.begin(), tiles.end(), [](const PlannedTile& a, const PlannedTile& b) {
        return a.tile_id < b.tile_id;
    });
    std::vector<const PlannedTile*> fresh;
    Header h;
    const std::vector<Entry> entries = plan_entries(tiles, fresh, h.data_length);
    const Directories dirs = make_directories(entries);
    describe_tiles(tiles, h);
    h.clustered = true;
    h.addressed_tiles = tiles.size();
    h.tile_entries = entries.size();
    h.tile_contents = fresh.size();
    const std::string meta = gzip(metadata_json(content, h));
    h.root_offset = kHeaderSize;
    h.root_length = dirs.root.size();
    h.metadata_offset = h.root_offset + h.root_length;
    h.metadata_length = meta.size();
    h.leaf_offset = h.metadata_offset + h.metadata_length;
    h.leaf_length = dirs.leaves.size();
    h.data_offset = h.leaf_offset + h.leaf_length;

    const std::string temp = out_path + ".tmp-" + std::to_string(::getpid());
    std::FILE* f = std::fopen(temp.c_str(), "wb");
    if (f == nullptr) {
        throw IoError(out_path + ": cannot create a temporary file next to it (" +
                      std::strerror(errno) + ")");
    }
    try {
        write_all(f, encode_header(h) + dirs.root + meta + dirs.leaves, out_path);
        for (const PlannedTile* t : fresh) {
            const std::string bytes = bytes_of(t->id);
            PlannedTile check;
            hash_tile(bytes, check);
            if (check.length != t->length || check.hash_a != t->hash_a ||
                check.hash_b != t->hash_b) {
                throw IoError(out_path + ": a staged tile changed while the archive was written; "
                                         "build again with --resume");
            }
            write_all(f, bytes, out_path);
        }
        if (std::fflush(f) != 0 || ::fsync(::fileno(f)) != 0) {
            throw IoError(out_path + ": write failed (" + std::strerror(errno) +
                          "); free space and build again with --resume");
        }
    } catch (...) {
        std::fclose(f);
        std::remove(temp.c_str());
        throw;
    }
    if (std::fclose(f) != 0) {
        std::remove(temp.c_str());
        throw IoError(out_path + ": write failed (" + std::strerror(errno) + ")");
    }
    move_into_place(temp, out_path);
}

} // namespace tb::tiler::pmtiles
