// PMTiles v3: header, directories, Hilbert ids, gzip, metadata (pmtiles_format.hpp).
#include "tiler/stores/pmtiles_format.hpp"

#include "tiler/gzip.hpp"

#include "core/error.hpp"
#include "tiler/json_number.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace tb::tiler::pmtiles {
namespace {

void put_le(std::string& out, std::uint64_t v, int bytes) {
    for (int i = 0; i < bytes; ++i) {
        out += static_cast<char>((v >> (8 * i)) & 0xff);
    }
}

std::uint64_t get_le(std::string_view s, std::size_t at, int bytes) {
    std::uint64_t v = 0;
    for (int i = 0; i < bytes; ++i) {
        v |= std::uint64_t{static_cast<unsigned char>(s[at + i])} << (8 * i);
    }
    return v;
}

void put_varint(std::string& out, std::uint64_t v) {
    while (v >= 0x80) {
        out += static_cast<char>((v & 0x7f) | 0x80);
        v >>= 7;
    }
    out += static_cast<char>(v);
}

// Reads LEB128 varints off a buffer, refusing to run past its end or 64 bits.
struct VarintReader {
    std::string_view s;
    std::size_t at = 0;
    const std::string& name;
    std::uint64_t next() {
        std::uint64_t v = 0;
        for (int shift = 0; shift < 64; shift += 7) {
            if (at >= s.size()) {
                throw InputError(name + ": a directory ends inside a number; the file is damaged");
            }
            const auto byte = static_cast<unsigned char>(s[at++]);
            v |= std::uint64_t{byte & 0x7fu} << shift;
            if (!(byte & 0x80)) {
                return v;
            }
        }
        throw InputError(name + ": a directory holds a number longer than 64 bits; the file is "
                                "damaged");
    }
};

// Tiles of all zooms below z: (4^z - 1) / 3.
std::uint64_t tiles_before(int z) {
    return ((std::uint64_t{1} << (2 * z)) - 1) / 3;
}

} // namespace

// The Hilbert curve's index of (x, y) on a 2^z grid, turning the quadrant at each level as the
// curve does (the spec's reference orientation).
std::uint64_t tile_id(const TileId& id) {
    TB_ASSERT(id.z >= 0 && id.z <= kMaxZoom);
    const std::int64_t n = std::int64_t{1} << id.z;
    TB_ASSERT(id.x >= 0 && id.x < n && id.y >= 0 && id.y < n);
    std::int64_t x = id.x, y = id.y;
    std::uint64_t d = 0;
    for (std::int64_t s = n / 2; s > 0; s /= 2) {
        const std::int64_t rx = (x & s) > 0 ? 1 : 0;
        const std::int64_t ry = (y & s) > 0 ? 1 : 0;
        d += static_cast<std::uint64_t>(s) * static_cast<std::uint64_t>(s) *
             static_cast<std::uint64_t>((3 * rx) ^ ry);
        if (ry == 0) {
            if (rx == 1) {
                x = s - 1 - x;
                y = s - 1 - y;
            }
            std::swap(x, y);
        }
    }
    return tiles_before(id.z) + d;
}

std::optional<TileId> tile_of(std::uint64_t tid) {
    int z = 0;
    while (z <= kMaxZoom && tid >= tiles_before(z + 1)) {
        ++z;
    }
    if (z > kMaxZoom) {
        return std::nullopt;
    }
    std::uint64_t d = tid - tiles_before(z);
    const std::int64_t n = std::int64_t{1} << z;
    std::int64_t x = 0, y = 0;
    for (std::int64_t s = 1; s < n; s *= 2) {
        const std::int64_t rx = static_cast<std::int64_t>(1 & (d / 2));
        const std::int64_t ry = static_cast<std::int64_t>(1 & (d ^ static_cast<std::uint64_t>(rx)));
        if (ry == 0) {
            if (rx == 1) {
                x = s - 1 - x;
                y = s - 1 - y;
            }
            std::swap(x, y);
        }
        x += s * rx;
        y += s * ry;
        d /= 4;
    }
    return TileId{z, x, y};
}

std::string encode_header(const Header& h) {
    std::string out = "PMTiles";
    out += static_cast<char>(3);
    for (std::uint64_t v : {h.root_offset,
                            h.root_length,
                            h.metadata_offset,
                            h.metadata_length,
                            h.leaf_offset,
                            h.leaf_length,
                            h.data_offset,
                            h.data_length,
                            h.addressed_tiles,
                            h.tile_entries,
                            h.tile_contents}) {
        put_le(out, v, 8);
    }
    for (std::uint8_t v : {static_cast<std::uint8_t>(h.clustered ? 1 : 0),
                           h.internal_compression,
                           h.tile_compression,
                           h.tile_type,
                           h.min_zoom,
                           h.max_zoom}) {
        out += static_cast<char>(v);
    }
    for (std::int32_t v : {h.min_lon_e7, h.min_lat_e7, h.max_lon_e7, h.max_lat_e7}) {
        put_le(out, static_cast<std::uint32_t>(v), 4);
    }
    out += static_cast<char>(h.center_zoom);
    put_le(out, static_cast<std::uint32_t>(h.center_lon_e7), 4);
    put_le(out, static_cast<std::uint32_t>(h.center_lat_e7), 4);
    TB_ASSERT(out.size() == kHeaderSize);
    return out;
}

Header decode_header(std::string_view s, std::uint64_t file_size, const std::string& name) {
    if (s.size() < kHeaderSize || s.substr(0, 7) != "PMTiles") {
        throw InputError(name + ": not a PMTiles archive (no \"PMTiles\" header); name an archive "
                                "written by terrabound build, or move the file away");
    }
    if (s[7] != 3) {
        throw InputError(name + ": PMTiles version " +
                         std::to_string(static_cast<unsigned char>(s[7])) +
                         ", this terrabound reads version 3; convert it with the pmtiles tool");
    }
    Header h;
    std::uint64_t* fields[] = {&h.root_offset,
                               &h.root_length,
                               &h.metadata_offset,
                               &h.metadata_length,
                               &h.leaf_offset,
                               &h.leaf_length,
                               &h.data_offset,
                               &h.data_length,
                               &h.addressed_tiles,
                               &h.tile_entries,
                               &h.tile_contents};
    for (std::size_t i = 0; i < std::size(fields); ++i) {
        *fields[i] = get_le(s, 8 + 8 * i, 8);
    }
    h.clustered = s[96] == 1;
    h.internal_compression = static_cast<std::uint8_t>(s[97]);
    h.tile_compression = static_cast<std::uint8_t>(s[98]);
    h.tile_type = static_cast<std::uint8_t>(s[99]);
    h.min_zoom = static_cast<std::uint8_t>(s[100]);
    h.max_zoom = static_cast<std::uint8_t>(s[101]);
    h.min_lon_e7 = static_cast<std::int32_t>(get_le(s, 102, 4));
    h.min_lat_e7 = static_cast<std::int32_t>(get_le(s, 106, 4));
    h.max_lon_e7 = static_cast<std::int32_t>(get_le(s, 110, 4));
    h.max_lat_e7 = static_cast<std::int32_t>(get_le(s, 114, 4));
    h.center_zoom = static_cast<std::uint8_t>(s[118]);
    h.center_lon_e7 = static_cast<std::int32_t>(get_le(s, 119, 4));
    h.center_lat_e7 = static_cast<std::int32_t>(get_le(s, 123, 4));

    const auto inside = [&](std::uint64_t offset, std::uint64_t length, const char* what) {
        if (offset > file_size || length > file_size - offset) {
            throw InputError(name + ": the header puts the " + what + " at bytes " +
                             std::to_string(offset) + "+" + std::to_string(length) +
                             ", past the file's " + std::to_string(file_size) +
                             " bytes; the file is cut short or damaged");
        }
    };
    inside(h.root_offset, h.root_length, "root directory");
    inside(h.metadata_offset, h.metadata_length, "metadata");
    inside(h.leaf_offset, h.leaf_length, "leaf directories");
    inside(h.data_offset, h.data_length, "tile data");
    if (h.root_offset + h.root_length > kRootLimit) {
        throw InputError(name + ": the root directory ends past the first 16 KiB, which PMTiles "
                                "v3 forbids; the file is damaged");
    }
    if (h.internal_compression != kCompressionGzip && h.internal_compression != kCompressionNone) {
        throw InputError(name + ": directories compressed with method " +
                         std::to_string(h.internal_compression) +
                         "; this terrabound reads none (1) and gzip (2)");
    }
    if (h.tile_compression != kCompressionNone || h.tile_type != kTileTypePng) {
        throw InputError(name + ": tile type " + std::to_string(h.tile_type) +
                         " with tile compression " + std::to_string(h.tile_compression) +
                         "; this terrabound serves raster DEM archives of uncompressed PNG tiles "
                         "(type 2, compression 1)");
    }
    return h;
}

std::string encode_directory(std::span<const Entry> entries) {
    std::string out;
    put_varint(out, entries.size());
    std::uint64_t last_id = 0;
    for (const auto& e : entries) {
        put_varint(out, e.tile_id - last_id);
        last_id = e.tile_id;
    }
    for (const auto& e : entries) {
        put_varint(out, e.run_length);
    }
    for (const auto& e : entries) {
        put_varint(out, e.length);
    }
    for (std::size_t i = 0; i < entries.size(); ++i) {
        const bool follows =
            i > 0 && entries[i].offset == entries[i - 1].offset + entries[i - 1].length;
        put_varint(out, follows ? 0 : entries[i].offset + 1);
    }
    return out;
}

std::vector<Entry> decode_directory(std::string_view raw,
                                    std::uint64_t data_length,
                                    std::uint64_t leaf_length,
                                    const std::string& name) {
    VarintReader r{raw, 0, name};
    const std::uint64_t n = r.next();
    // Every entry takes at least four bytes: a count past that is damage, not a huge directory.
    if (n > raw.size() / 4) {
        throw InputError(name + ": a directory claims " + std::to_string(n) + " entries in " +
                         std::to_string(raw.size()) + " bytes; the file is damaged");
    }
    std::vector<Entry> entries(n);
    std::uint64_t id = 0;
    for (std::uint64_t i = 0; i < n; ++i) {
        const std::uint64_t delta = r.next();
        if ((i > 0 && delta == 0) || delta > UINT64_MAX - id) {
            throw InputError(name +
                             ": a directory's tile ids do not increase; the file is damaged");
        }
        id += delta;
        entries[i].tile_id = id;
    }
    const auto small = [&](std::uint64_t v) {
        if (v > UINT32_MAX) {
            throw InputError(name + ": a directory entry's run or length exceeds 32 bits; the "
                                    "file is damaged");
        }
        return static_cast<std::uint32_t>(v);
    };
    for (auto& e : entries) {
        e.run_length = small(r.next());
    }
    for (auto& e : entries) {
        e.length = small(r.next());
    }
    for (std::uint64_t i = 0; i < n; ++i) {
        const std::uint64_t v = r.next();
        if (v == 0 && i == 0) {
            throw InputError(name + ": a directory's first entry has no offset; the file is "
                                    "damaged");
        }
        entries[i].offset = v == 0 ? entries[i - 1].offset + entries[i - 1].length : v - 1;
        const std::uint64_t limit = entries[i].run_length == 0 ? leaf_length : data_length;
        if (entries[i].offset > limit || entries[i].length > limit - entries[i].offset) {
            throw InputError(name + ": a directory entry points past its section; the file is "
                                    "damaged");
        }
    }
    return entries;
}

std::string gzip(std::string_view bytes) {
    return gzip_compress(bytes, 6);
}

std::string gunzip(std::string_view bytes, std::size_t max_out, const std::string& name) {
    if (auto out = gzip_decompress(bytes, max_out)) {
        return std::move(*out);
    }
    throw InputError(name + ": a gzip-compressed section is damaged or longer than " +
                     std::to_string(max_out) + " bytes; the file is damaged");
}

} // namespace tb::tiler::pmtiles
