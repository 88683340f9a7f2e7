#pragma once
// The framing of one HTTP/1.x request, checked before any of it is parsed for routing: where
// the head ends, how long the body is, and whether the framing is sound enough to answer and
// keep the connection (RFC 9112 sections 2-6). No sockets here; the connection loop
// (server/connections.hpp) feeds it the bytes received so far.
#include <cstddef>
#include <string>
#include <string_view>

namespace tb::server {

struct HeadLimits {
    std::size_t head_bytes = 32 * 1024; // request line + header fields + blank line
    std::size_t header_count = 100;
    std::size_t body_bytes = 64 * 1024; // Content-Length accepted (this API takes no bodies)
};

struct RequestHead {
    enum class State { Incomplete, Complete, Bad };
    State state = State::Incomplete;
    std::size_t head_bytes = 0; // Complete: bytes through the blank line
    std::size_t body_bytes = 0; // Complete: Content-Length, 0 without one
    int status = 0;             // Bad: 400, 413, 414, 431, 501 or 505
    std::string error;          // Bad: what is wrong, for the client
};

// Checks the request at the start of `bytes` (the bytes received so far on a connection, which
// may hold more than one request when the client pipelines). Incomplete means: nothing wrong
// yet, wait for more bytes. Bad requests cannot be framed reliably, so the caller answers
// `status` and closes the connection. Refused: lines not ended by CRLF, a malformed request line
// or header field, a version other than HTTP/1.0 and 1.1, HTTP/1.1 without exactly one Host,
// obsolete line folding, any Transfer-Encoding, a Content-Length that is repeated, signed,
// not decimal or too large, and heads past `limits`.
RequestHead check_request_head(std::string_view bytes, const HeadLimits& limits);

// ASCII case-insensitive equality, as header names and tokens compare.
bool equals_ci(std::string_view a, std::string_view b);

// `s` without the optional whitespace (spaces and tabs) at either end, as field values and list
// items are read (RFC 9110 section 5.6.3).
std::string_view trim_ows(std::string_view s);

} // namespace tb::server
