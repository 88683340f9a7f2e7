#pragma once
// The checksum both stores keep beside every tile and document, so that a stored copy that is
// empty, truncated, overwritten with garbage or has a flipped bit is found before it is served.
// CRC-32 (zlib's, ISO-HDLC) catches every single-bit error and every burst up to 32 bits, and
// anything else with probability 1 - 2^-32.
#include <cstdint>
#include <string>
#include <string_view>

namespace tb::tiler {

std::uint32_t store_checksum(std::string_view bytes);

// The directory store's sidecar text for `bytes`: "crc32 {8 hex digits} {size}\n".
std::string checksum_sidecar(std::string_view bytes);

} // namespace tb::tiler
