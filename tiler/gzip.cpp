#include "tiler/gzip.hpp"

#include <cstring>
#include <stdexcept>
#include <zlib.h>

namespace tb::tiler {
namespace {

// zlib's window bits for a gzip wrapper rather than its own: 15 (32 KiB window) + 16.
constexpr int kGzipWindow = 15 + 16;

} // namespace

std::string gzip_compress(std::string_view bytes, int level) {
    z_stream z;
    std::memset(&z, 0, sizeof z);
    if (deflateInit2(&z, level, Z_DEFLATED, kGzipWindow, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
        throw std::runtime_error("gzip compression failed to start");
    }
    std::string out(deflateBound(&z, static_cast<uLong>(bytes.size())), '\0');
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
    z.avail_in = static_cast<uInt>(bytes.size());
    z.next_out = reinterpret_cast<Bytef*>(out.data());
    z.avail_out = static_cast<uInt>(out.size());
    const int rc = deflate(&z, Z_FINISH);
    const std::size_t size = out.size() - z.avail_out;
    deflateEnd(&z);
    if (rc != Z_STREAM_END) {
        throw std::runtime_error("gzip compression failed");
    }
    out.resize(size);
    return out;
}

bool looks_gzipped(std::string_view bytes) {
    return bytes.size() >= 18 && static_cast<unsigned char>(bytes[0]) == 0x1f &&
           static_cast<unsigned char>(bytes[1]) == 0x8b && bytes[2] == 8;
}

std::optional<std::string> gzip_decompress(std::string_view bytes, std::size_t max_bytes) {
    if (!looks_gzipped(bytes)) {
        return std::nullopt;
    }
    z_stream z;
    std::memset(&z, 0, sizeof z);
    if (inflateInit2(&z, kGzipWindow) != Z_OK) {
        throw std::runtime_error("gzip decompression failed to start");
    }
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
    z.avail_in = static_cast<uInt>(bytes.size());
    std::string out;
    char buffer[65536];
    int rc = Z_OK;
    while (rc == Z_OK) {
        z.next_out = reinterpret_cast<Bytef*>(buffer);
        z.avail_out = sizeof buffer;
        rc = inflate(&z, Z_NO_FLUSH);
        const std::size_t made = sizeof buffer - z.avail_out;
        if (out.size() + made > max_bytes) {
            rc = Z_MEM_ERROR;
            break;
        }
        out.append(buffer, made); // Z_BUF_ERROR next: the input ended before the member did
    }
    // Z_STREAM_END has checked the trailer's CRC-32 and length; nothing may follow the member.
    const bool whole = rc == Z_STREAM_END && z.avail_in == 0;
    inflateEnd(&z);
    if (!whole) {
        return std::nullopt;
    }
    return out;
}

} // namespace tb::tiler
