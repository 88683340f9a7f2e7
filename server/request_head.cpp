// Request framing checks (RFC 9112): strict, since everything after a misframed request would
// be read as the wrong thing (request smuggling), and cheap, since it runs on every read.
#include "server/request_head.hpp"

#include <cstdint>

namespace tb::server {
namespace {

// RFC 9110 tchar: the characters of a method or a field name.
bool is_tchar(unsigned char c) {
    if ((c >= '0' && c <= '9') || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z')) {
        return true;
    }
    switch (c) {
    case '!':
    case '#':
    case '$':
    case '%':
    case '&':
    case '\'':
    case '*':
    case '+':
    case '-':
    case '.':
    case '^':
    case '_':
    case '`':
    case '|':
    case '~':
        return true;
    default:
        return false;
    }
}

RequestHead bad(int status, std::string error) {
    RequestHead h;
    h.state = RequestHead::State::Bad;
    h.status = status;
    h.error = std::move(error);
    return h;
}

// The request line: method SP request-target SP HTTP-version. Returns an empty string when it
// is fine, else why not; `status` gets the code to answer.
std::string check_request_line(std::string_view line, int& status) {
    status = 400;
    const std::size_t sp1 = line.find(' ');
    if (sp1 == std::string_view::npos || sp1 == 0) {
        return "malformed request line; expected 'METHOD /path HTTP/1.1'";
    }
    const std::size_t sp2 = line.find(' ', sp1 + 1);
    if (sp2 == std::string_view::npos || sp2 == sp1 + 1 ||
        line.find(' ', sp2 + 1) != std::string_view::npos) {
        return "malformed request line; expected 'METHOD /path HTTP/1.1'";
    }
    for (std::size_t i = 0; i < sp1; ++i) {
        if (!is_tchar(static_cast<unsigned char>(line[i]))) {
            return "malformed method in the request line";
        }
    }
    for (std::size_t i = sp1 + 1; i < sp2; ++i) {
        const unsigned char c = static_cast<unsigned char>(line[i]);
        if (c <= 0x20 || c >= 0x7f) {
            return "the request target holds a control, space or non-ASCII byte; "
                   "percent-encode it";
        }
    }
    const std::string_view version = line.substr(sp2 + 1);
    if (version.size() != 8 || version.substr(0, 5) != "HTTP/" || version[6] != '.' ||
        version[5] < '0' || version[5] > '9' || version[7] < '0' || version[7] > '9') {
        return "malformed HTTP version in the request line";
    }
    if (version != "HTTP/1.1" && version != "HTTP/1.0") {
        status = 505;
        return std::string(version) + " is not supported; use HTTP/1.1";
    }
    return "";
}

} // namespace

bool equals_ci(std::string_view a, std::string_view b) {
    if (a.size() != b.size()) {
        return false;
    }
    for (std::size_t i = 0; i < a.size(); ++i) {
        unsigned char x = static_cast<unsigned char>(a[i]);
        unsigned char y = static_cast<unsigned char>(b[i]);
        if (x >= 'A' && x <= 'Z') {
            x = static_cast<unsigned char>(x - 'A' + 'a');
        }
        if (y >= 'A' && y <= 'Z') {
            y = static_cast<unsigned char>(y - 'A' + 'a');
        }
        if (x != y) {
            return false;
        }
    }
    return true;
}

std::string_view trim_ows(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) {
        s.remove_prefix(1);
    }
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) {
        s.remove_suffix(1);
    }
    return s;
}

RequestHead check_request_head(std::string_view bytes, const HeadLimits& limits) {
    std::size_t pos = 0;
    std::size_t fields = 0;
    int hosts = 0;
    bool has_length = false;
    std::uint64_t length = 0;
    bool http11 = false;
    for (;;) {
        const std::size_t nl = bytes.find('\n', pos);
        const std::size_t limit_end = limits.head_bytes;
        if (nl == std::string_view::npos) {
            if (bytes.size() > limit_end) {
                return pos == 0 ? bad(414,
                                      "the request line is longer than " +
                                          std::to_string(limit_end) + " bytes")
                                : bad(431,
                                      "the request head is larger than " +
                                          std::to_string(limit_end) + " bytes");
            }
            // A bare CR followed by more than the terminator would be refused below anyway;
            // a partial line is simply not complete yet.
            RequestHead h;
            return h;
        }
        if (nl + 1 > limit_end) {
            return pos == 0 ? bad(414,
                                  "the request line is longer than " + std::to_string(limit_end) +
                                      " bytes")
                            : bad(431,
                                  "the request head is larger than " + std::to_string(limit_end) +
                                      " bytes");
        }
        if (nl == pos || bytes[nl - 1] != '\r') {
            return bad(400, "a line of the request head does not end with CRLF");
        }
        const std::string_view line = bytes.substr(pos, nl - 1 - pos);
        for (unsigned char c : line) {
            if (c == '\r' || c == '\0') {
                return bad(400, "the request head holds a bare CR or a NUL");
            }
        }
        if (pos == 0) {
            int status = 400;
            const std::string why = check_request_line(line, status);
            if (!why.empty()) {
                return bad(status, why);
            }
            http11 = line.substr(line.size() - 8) == "HTTP/1.1";
            pos = nl + 1;
            continue;
        }
        if (line.empty()) {
            pos = nl + 1;
            break; // the blank line: end of the head
        }
        if (line.front() == ' ' || line.front() == '\t') {
            return bad(400, "obsolete line folding in a header field; send each field on one line");
        }
        if (++fields > limits.header_count) {
            return bad(431, "more than " + std::to_string(limits.header_count) + " header fields");
        }
        const std::size_t colon = line.find(':');
        if (colon == std::string_view::npos || colon == 0) {
            return bad(400, "malformed header field; expected 'Name: value'");
        }
        const std::string_view name = line.substr(0, colon);
        for (unsigned char c : name) {
            if (!is_tchar(c)) {
                return bad(400, "malformed header field name (no space is allowed before ':')");
            }
        }
        const std::string_view value = trim_ows(line.substr(colon + 1));
        for (unsigned char c : value) {
            if ((c < 0x20 && c != '\t') || c == 0x7f) {
                return bad(400, "a header field value holds a control character");
            }
        }
        if (equals_ci(name, "Content-Length")) {
            if (has_length) {
                return bad(400, "Content-Length is given more than once");
            }
            has_length = true;
            if (value.empty() || value.size() > 18) {
                return bad(value.size() > 18 ? 413 : 400,
                           value.empty() ? "Content-Length is empty"
                                         : "Content-Length is too large");
            }
            for (char c : value) {
                if (c < '0' || c > '9') {
                    return bad(400, "Content-Length must be a non-negative decimal number");
                }
                length = length * 10 + static_cast<std::uint64_t>(c - '0');
            }
        } else if (equals_ci(name, "Transfer-Encoding")) {
            return bad(has_length ? 400 : 501,
                       "Transfer-Encoding in a request is not supported; this server takes no "
                       "request bodies");
        } else if (equals_ci(name, "Host")) {
            ++hosts;
        }
        pos = nl + 1;
    }
    // Transfer-Encoding after Content-Length was caught in the loop; before it too, since any
    // Transfer-Encoding is refused at once.
    if (http11 && hosts != 1) {
        return bad(400,
                   hosts == 0 ? "an HTTP/1.1 request needs a Host header"
                              : "Host is given more than once");
    }
    if (hosts > 1) {
        return bad(400, "Host is given more than once");
    }
    if (length > limits.body_bytes) {
        return bad(413,
                   "the request body is larger than " + std::to_string(limits.body_bytes) +
                       " bytes; this server takes no request bodies");
    }
    RequestHead h;
    h.state = RequestHead::State::Complete;
    h.head_bytes = pos;
    h.body_bytes = static_cast<std::size_t>(length);
    return h;
}

} // namespace tb::server
