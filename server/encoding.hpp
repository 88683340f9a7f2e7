#pragma once
// Content codings of JSON documents: which one a client accepts (RFC 9110 section 12.5.3), and
// the compression itself (zlib's gzip, brotli).
#include <string>
#include <string_view>

namespace tb::server {

enum class Coding { Identity, Gzip, Brotli };

// The coding to send for an Accept-Encoding value: of gzip and br, the one with the highest
// q-value above 0 (br on a tie, as it is smaller), else identity. "q=0" refuses a coding, and
// "*" stands for every coding not named. Malformed items are ignored.
Coding pick_coding(std::string_view accept_encoding);

// "gzip" or "br" (nullptr for identity), as in Content-Encoding.
const char* coding_name(Coding coding);

// `bytes` compressed with `coding` (gzip: zlib level 6; br: quality 11, as these run once per
// document). Throws std::runtime_error if the compressor fails.
std::string compress(std::string_view bytes, Coding coding);

} // namespace tb::server
