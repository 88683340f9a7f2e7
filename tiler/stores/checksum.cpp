#include "tiler/stores/checksum.hpp"

#include <cstdio>
#include <zlib.h>

namespace tb::tiler {

std::uint32_t store_checksum(std::string_view bytes) {
    uLong crc = crc32(0L, Z_NULL, 0);
    const auto* p = reinterpret_cast<const Bytef*>(bytes.data());
    std::size_t left = bytes.size();
    while (left > 0) {
        const uInt n = left > (1u << 30) ? (1u << 30) : static_cast<uInt>(left);
        crc = crc32(crc, p, n);
        p += n;
        left -= n;
    }
    return static_cast<std::uint32_t>(crc);
}

std::string checksum_sidecar(std::string_view bytes) {
    char text[48];
    std::snprintf(text,
                  sizeof text,
                  "crc32 %08x %llu\n",
                  store_checksum(bytes),
                  static_cast<unsigned long long>(bytes.size()));
    return text;
}

} // namespace tb::tiler
