#pragma once
// gzip (RFC 1952) through zlib, for what is stored or sent compressed: globe terrain tiles in
// a directory store (static hosts send them with Content-Encoding: gzip, as CesiumJS expects)
// and the server's compressed responses.
#include <cstddef>
#include <optional>
#include <string>
#include <string_view>

namespace tb::tiler {

// `bytes` in one gzip member at zlib `level` (1..9). Throws std::runtime_error if zlib fails.
std::string gzip_compress(std::string_view bytes, int level = 6);

// Whether `bytes` starts like a gzip member (magic 1f 8b, method deflate).
bool looks_gzipped(std::string_view bytes);

// The bytes of one whole gzip member, or nullopt when it is not one: damaged, cut short,
// followed by anything, failing its CRC-32 or size check, or inflating past `max_bytes`.
std::optional<std::string> gzip_decompress(std::string_view bytes, std::size_t max_bytes);

} // namespace tb::tiler
