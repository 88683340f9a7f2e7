// HTTP routes of `terrabound serve`. Handlers are thin: parse the request, ask TileService,
// write the response. Errors are thrown and mapped to a status by one exception handler.
#include "server/http_server.hpp"
#include "server/request_head.hpp"

#include "core/error.hpp"
#include "tiler/cpus.hpp"
#include "tiler/dem_tiles.hpp"
#include "tiler/formats/quantized_mesh.hpp"
#include "tiler/formats/terrain_tiles.hpp"
#include "tiler/json_number.hpp"
#include "tiler/log.hpp"
#include "tiler/pyramid/hosting.hpp"
#include "tiler/tile_grid.hpp"

#include <httplib.h>

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

namespace tb::server {
namespace {

constexpr const char* kTileCacheControl = "public, max-age=604800"; // a week: tiles of a
                                                                    // config never change
constexpr const char* kDocumentCacheControl = "public, max-age=60";
constexpr const char* kNoStore = "no-store";
constexpr int kRetryAfterSeconds = 1;
// Connection loops at most (one per core below that).
constexpr unsigned kMaxLoops = 4;

// Per-request bookkeeping. cpp-httplib handles a request on one thread from the pre-routing
// handler to the logger, so a thread_local carries it between them.
struct RequestContext {
    std::chrono::steady_clock::time_point start;
    const char* route = "unmatched";
    bool active = false;
};
thread_local RequestContext t_request;
// The request's Accept-Encoding. It is taken off the request before routing, so that
// cpp-httplib never compresses a response itself (it would, on every request, and ignores
// q=0); send_blob compresses documents once per ETag instead.
thread_local std::string t_accept_encoding;
// The request's Range header, taken off before cpp-httplib reads the request (take_range):
// cpp-httplib 0.11.4 cuts every body to the range, error bodies included, and keeps the 200 a
// handler set, so a client got a 200 with part of a tile. apply_range answers it instead, after
// routing, for complete 200 answers only.
thread_local std::string t_range;
// The address of the request's peer, for /metrics' loopback check.
thread_local std::string t_peer_ip;

std::string json_escape(std::string_view text) {
    std::string out;
    out.reserve(text.size() + 2);
    for (unsigned char c : text) {
        switch (c) {
        case '"':
            out += "\\\"";
            break;
        case '\\':
            out += "\\\\";
            break;
        case '\n':
            out += "\\n";
            break;
        default:
            if (c < 0x20) {
                char buf[8];
                std::snprintf(buf, sizeof buf, "\\u%04x", c);
                out += buf;
            } else {
                out += static_cast<char>(c);
            }
        }
    }
    return out;
}

std::string html_escape(std::string_view text) {
    std::string out;
    for (char c : text) {
        switch (c) {
        case '<':
            out += "&lt;";
            break;
        case '>':
            out += "&gt;";
            break;
        case '&':
            out += "&amp;";
            break;
        case '"':
            out += "&quot;";
            break;
        default:
            out += c;
        }
    }
    return out;
}

std::string number(double v) {
    return tiler::json_number(v, "a layer-list number");
}

const char* reason(int status) {
    switch (status) {
    case 400:
        return "bad request";
    case 403:
        return "forbidden";
    case 404:
        return "not found; see / for the layers and their URLs";
    case 405:
        return "method not allowed";
    case 413:
        return "request too large";
    case 414:
        return "URL too long";
    case 416:
        return "range not satisfiable";
    case 431:
        return "request headers too large";
    case 503:
        return "service unavailable";
    default:
        return status < 500 ? "bad request" : "internal error";
    }
}

void send_error(httplib::Response& res, int status, std::string_view message) {
    res.status = status;
    res.set_header("Cache-Control", kNoStore);
    res.set_content("{\"error\":\"" + json_escape(message.substr(0, 300)) + "\"}\n",
                    "application/json");
}

// "METHOD target" for the log: the raw target (still percent-encoded, with the query), cut
// and cleaned so that a hostile URL can neither forge nor flood log lines.
std::string loggable(const httplib::Request& req) {
    const std::string& target = req.target.empty() ? req.path : req.target;
    std::string text = req.method.substr(0, 16) + " " +
                       (target.size() > 200 ? target.substr(0, 200) + "..." : target);
    for (char& c : text) {
        if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
            c = '?';
        }
    }
    return text;
}

// True when `ip` (as inet_ntop writes it) is this machine's loopback: 127.0.0.0/8, ::1, or an
// IPv4-mapped 127 address.
bool is_loopback(std::string_view ip) {
    if (ip.rfind("::ffff:", 0) == 0) {
        ip.remove_prefix(7);
    }
    return ip == "::1" || ip.rfind("127.", 0) == 0;
}

// True when the request comes from this machine itself: a loopback peer that is not a reverse
// proxy forwarding someone else's request (it would name the client in one of these headers).
bool from_this_machine(const httplib::Request& req) {
    return is_loopback(t_peer_ip) && !req.has_header("Forwarded") &&
           !req.has_header("X-Forwarded-For") && !req.has_header("X-Real-IP");
}

// A non-empty comma-separated list of HTTP tokens (header names), optional spaces around commas.
bool is_token_list(std::string_view text) {
    const auto tchar = [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) ||
               std::string_view("!#$%&'*+-.^_`|~").find(c) != std::string_view::npos;
    };
    bool any = false, in_token = false, after_token = false;
    for (char c : text) {
        if (tchar(c) && !after_token) {
            in_token = any = true;
        } else if (c == ' ' || c == '\t') {
            after_token = after_token || in_token;
            in_token = false;
        } else if (c == ',' && (in_token || after_token)) {
            in_token = after_token = false;
        } else {
            return false;
        }
    }
    return any && (in_token || after_token);
}

// A decimal digit string of at most `max_digits` digits, as a number.
bool parse_index(std::string_view text, std::size_t max_digits, std::int64_t& out) {
    if (text.empty() || text.size() > max_digits) {
        return false;
    }
    for (char c : text) {
        if (c < '0' || c > '9') {
            return false;
        }
    }
    const auto r = std::from_chars(text.data(), text.data() + text.size(), out);
    return r.ec == std::errc() && r.ptr == text.data() + text.size();
}

bool contains_ci(std::string_view haystack, std::string_view needle) {
    if (needle.size() > haystack.size()) {
        return false;
    }
    for (std::size_t i = 0; i + needle.size() <= haystack.size(); ++i) {
        bool match = true;
        for (std::size_t j = 0; j < needle.size() && match; ++j) {
            match = std::tolower(static_cast<unsigned char>(haystack[i + j])) ==
                    std::tolower(static_cast<unsigned char>(needle[j]));
        }
        if (match) {
            return true;
        }
    }
    return false;
}

// Why a decoded path is refused, or nullptr when it is fine. Nothing in the server maps a URL
// to a file, but paths that try to climb or smuggle separators are refused outright anyway.
const char* bad_path(const httplib::Request& req) {
    const std::string& p = req.path;
    if (p.empty() || p[0] != '/') {
        return "the path must start with /";
    }
    if (p.find('\0') != std::string::npos || p.find('\\') != std::string::npos) {
        return "the path contains a NUL or backslash";
    }
    // Only the path part of the raw target: a query string may well carry an encoded '/'.
    const std::string raw_path = req.target.substr(0, req.target.find('?'));
    if (contains_ci(raw_path, "%2f") || contains_ci(raw_path, "%5c") ||
        contains_ci(raw_path, "%00")) {
        return "the path contains an encoded separator or NUL";
    }
    std::size_t begin = 1;
    while (begin <= p.size()) {
        std::size_t end = p.find('/', begin);
        if (end == std::string::npos) {
            end = p.size();
        }
        const std::string_view segment(p.data() + begin, end - begin);
        if (segment == "." || segment == "..") {
            return "the path contains a . or .. segment";
        }
        begin = end + 1;
    }
    for (unsigned char c : p) {
        if (c < 0x20 || c == 0x7f) {
            return "the path contains a control character";
        }
    }
    return nullptr;
}

// True when If-None-Match value `header` lists `etag` (or is "*").
bool lists_etag(const std::string& header, const std::string& etag) {
    std::size_t pos = 0;
    while (pos < header.size()) {
        std::size_t comma = header.find(',', pos);
        if (comma == std::string::npos) {
            comma = header.size();
        }
        std::string item = header.substr(pos, comma - pos);
        const auto first = item.find_first_not_of(" \t");
        const auto last = item.find_last_not_of(" \t");
        item = first == std::string::npos ? "" : item.substr(first, last - first + 1);
        if (item.rfind("W/", 0) == 0) {
            item = item.substr(2); // weak comparison, as RFC 9110 wants for If-None-Match
        }
        if (item == "*" || item == etag) {
            return true;
        }
        pos = comma + 1;
    }
    return false;
}

// True when the request's If-None-Match lists `etag` (or is "*").
bool not_modified(const httplib::Request& req, const std::string& etag) {
    return req.has_header("If-None-Match") &&
           lists_etag(req.get_header_value("If-None-Match"), etag);
}

// Documents shorter than this are sent as they are: compression would hardly shrink them.
constexpr std::size_t kMinCompressBytes = 256;

// Sends `blob`; `compress` non-null: it may be compressed (JSON documents, quantized-mesh and
// 3D Tiles terrain tiles), in the coding the client's Accept-Encoding prefers, made once per
// blob by that service.
void send_blob(const httplib::Request& req,
               httplib::Response& res,
               const Blob& blob,
               const char* media_type,
               const char* cache_control,
               TileService* compress = nullptr) {
    res.set_header("ETag", blob.etag);
    res.set_header("Cache-Control", cache_control);
    if (compress) {
        res.set_header("Vary", "Accept-Encoding");
    }
    if (not_modified(req, blob.etag)) {
        res.status = 304;
        return;
    }
    res.status = 200;
    const Coding coding = compress && blob.bytes.size() >= kMinCompressBytes
                              ? pick_coding(t_accept_encoding)
                              : Coding::Identity;
    if (coding == Coding::Identity) {
        res.set_content(blob.bytes, media_type);
        return;
    }
    res.set_content(compress->encoded(blob, coding), media_type);
    res.set_header("Content-Encoding", coding_name(coding));
}

// The eps a tile request asks for with ?eps=K: the layer's eps_levels[K], or the zoom's own
// eps when absent. Every tile route reads it here, so a bad value gets one answer whatever the
// format; whether the layer has level K, and whether the format takes levels at all, is
// TileService::tile's to say (400 either way).
tiler::EpsChoice eps_param(const httplib::Request& req) {
    tiler::EpsChoice eps;
    if (req.has_param("eps")) {
        std::int64_t level = 0;
        if (!parse_index(req.get_param_value("eps"), 3, level)) {
            throw InputError("eps must be the index of one of the layer's eps_levels (0, 1, "
                             "...); see /layers");
        }
        eps.level = static_cast<int>(level);
    }
    return eps;
}

// The DEM tile encoding a request asks for with ?encoding= (terrarium when absent).
tiler::Format dem_encoding(const httplib::Request& req) {
    if (!req.has_param("encoding")) {
        return tiler::Format::Terrarium;
    }
    const std::string e = req.get_param_value("encoding");
    if (e == "terrarium") {
        return tiler::Format::Terrarium;
    }
    if (e == "mapbox") {
        return tiler::Format::Mapbox;
    }
    throw InputError("encoding '" + e.substr(0, 40) + "' is unknown; use terrarium or mapbox");
}

// The quantized-mesh extensions a request's Accept header asks for: the names in the
// `extensions` parameter of its application/vnd.quantized-mesh media ranges, joined by '-'
// (CesiumJS sends "application/vnd.quantized-mesh;extensions=octvertexnormals-watermask-
// metadata,application/octet-stream;q=0.9,*/*;q=0.01"). Unknown names are ignored.
unsigned accepted_extensions(const std::string& accept) {
    unsigned mask = 0;
    std::size_t start = 0;
    while (start <= accept.size()) {
        std::size_t end = accept.find(',', start);
        if (end == std::string::npos) {
            end = accept.size();
        }
        std::string range = accept.substr(start, end - start);
        std::transform(range.begin(), range.end(), range.begin(), [](unsigned char c) {
            return static_cast<char>(std::tolower(c));
        });
        range.erase(std::remove_if(range.begin(),
                                   range.end(),
                                   [](unsigned char c) { return std::isspace(c); }),
                    range.end());
        if (range.rfind("application/vnd.quantized-mesh", 0) == 0) {
            const std::size_t at = range.find(";extensions=");
            if (at != std::string::npos) {
                std::string list = range.substr(at + 12);
                list = list.substr(0, list.find(';'));
                std::size_t p = 0;
                while (p <= list.size()) {
                    std::size_t q = list.find('-', p);
                    if (q == std::string::npos) {
                        q = list.size();
                    }
                    const std::string name = list.substr(p, q - p);
                    if (name == "octvertexnormals") {
                        mask |= tiler::kOctVertexNormals;
                    } else if (name == "watermask") {
                        mask |= tiler::kWaterMask;
                    } else if (name == "metadata") {
                        mask |= tiler::kMetadata;
                    }
                    p = q + 1;
                }
            }
        }
        start = end + 1;
    }
    return mask;
}

// The scheme and authority clients reach this server by, for the absolute URLs of TileJSON:
// the request's Host (and X-Forwarded-Proto behind a TLS proxy), else the listening address.
std::string public_origin(const httplib::Request& req, const std::string& host, int port) {
    std::string authority = req.get_header_value("Host");
    const bool plain = !authority.empty() && authority.size() <= 255 &&
                       std::all_of(authority.begin(), authority.end(), [](char c) {
                           return std::isalnum(static_cast<unsigned char>(c)) || c == '.' ||
                                  c == '-' || c == ':' || c == '[' || c == ']' || c == '_';
                       });
    if (!plain) {
        authority = host + ":" + std::to_string(port);
    }
    const bool https = req.get_header_value("X-Forwarded-Proto") == "https";
    return (https ? "https://" : "http://") + authority;
}

const char* status_text(int status) {
    switch (status) {
    case 400:
        return "Bad Request";
    case 408:
        return "Request Timeout";
    case 413:
        return "Payload Too Large";
    case 414:
        return "URI Too Long";
    case 431:
        return "Request Header Fields Too Large";
    case 501:
        return "Not Implemented";
    case 503:
        return "Service Unavailable";
    case 505:
        return "HTTP Version Not Supported";
    default:
        return "Error";
    }
}

// Media types of the viewer's files, by extension; others are application/octet-stream.
const char* file_media_type(const std::string& path) {
    static const std::pair<const char*, const char*> types[] = {
        {"html", "text/html; charset=utf-8"},
        {"htm", "text/html; charset=utf-8"},
        {"js", "text/javascript"},
        {"mjs", "text/javascript"},
        {"cjs", "text/javascript"},
        {"css", "text/css"},
        {"json", "application/json"},
        {"wasm", "application/wasm"},
        {"glb", "model/gltf-binary"},
        {"gltf", "model/gltf+json"},
        {"png", "image/png"},
        {"jpg", "image/jpeg"},
        {"jpeg", "image/jpeg"},
        {"gif", "image/gif"},
        {"svg", "image/svg+xml"},
        {"webp", "image/webp"},
        {"ico", "image/x-icon"},
        {"ktx2", "image/ktx2"},
        {"txt", "text/plain; charset=utf-8"},
        {"xml", "application/xml"},
        {"woff", "font/woff"},
        {"woff2", "font/woff2"},
        {"ttf", "font/ttf"},
    };
    const auto dot = path.rfind('.');
    const auto slash = path.rfind('/');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) {
        return "application/octet-stream";
    }
    std::string ext = path.substr(dot + 1);
    for (char& c : ext) {
        c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    }
    for (const auto& [e, type] : types) {
        if (ext == e) {
            return type;
        }
    }
    return "application/octet-stream";
}

// True when canonical path `p` is `root` or lies below it (both canonical, no trailing '/').
bool within(const std::filesystem::path& p, const std::filesystem::path& root) {
    const std::string ps = p.string(), rs = root.string();
    return ps == rs || (ps.size() > rs.size() && ps.compare(0, rs.size(), rs) == 0 &&
                        (rs.back() == '/' || ps[rs.size()] == '/'));
}

// One byte range (RFC 9110 14.1.2): first-last, first- (to the end) or -suffix_length.
// -1 marks the absent bound.
struct ByteRange {
    std::int64_t first = -1;
    std::int64_t last = -1;
};

// The single range of a Range value, or nothing when the value is not exactly one byte range
// (several ranges, another unit, a malformed one): such a Range is ignored.
std::optional<ByteRange> single_byte_range(std::string_view value) {
    value = trim_ows(value);
    constexpr std::string_view kUnit = "bytes=";
    if (value.size() < kUnit.size() || !equals_ci(value.substr(0, kUnit.size()), kUnit)) {
        return std::nullopt;
    }
    value = trim_ows(value.substr(kUnit.size()));
    const std::size_t dash = value.find('-');
    if (dash == std::string_view::npos || value.find(',') != std::string_view::npos) {
        return std::nullopt;
    }
    // Up to 18 digits: below 2^63, far beyond any body.
    const auto digits = [](std::string_view v, std::int64_t& out) {
        if (v.empty() || v.size() > 18) {
            return false;
        }
        out = 0;
        for (const char c : v) {
            if (c < '0' || c > '9') {
                return false;
            }
            out = out * 10 + (c - '0');
        }
        return true;
    };
    ByteRange r;
    const std::string_view a = trim_ows(value.substr(0, dash)),
                           b = trim_ows(value.substr(dash + 1));
    if (a.empty()) {
        if (!digits(b, r.last)) {
            return std::nullopt;
        }
        return r; // a suffix: the last r.last bytes
    }
    if (!digits(a, r.first) || (!b.empty() && !digits(b, r.last)) ||
        (r.last >= 0 && r.last < r.first)) {
        return std::nullopt;
    }
    return r;
}

// Takes the Range header lines off a framed request (head and body, lines ended by CRLF as
// the connection loop requires): true, with `without` the request minus those lines and
// `value` the field's value, when there was one. Several Range lines give an empty value,
// which apply_range ignores.
bool take_range(std::string_view request, std::string& value, std::string& without) {
    const std::size_t head_end = request.find("\r\n\r\n");
    if (head_end == std::string_view::npos) {
        return false;
    }
    constexpr std::string_view kName = "range:";
    int found = 0;
    std::size_t line = request.find("\r\n") + 2; // after the request line
    std::size_t copied = 0;
    while (line <= head_end) {
        const std::size_t end = request.find("\r\n", line);
        const std::string_view text = request.substr(line, end - line);
        if (text.size() >= kName.size() && equals_ci(text.substr(0, kName.size()), kName)) {
            if (++found == 1) {
                without.reserve(request.size());
            }
            without.append(request.substr(copied, line - copied));
            copied = end + 2;
            value = text.substr(kName.size(), 1024);
        }
        line = end + 2;
    }
    if (found == 0) {
        return false;
    }
    without.append(request.substr(copied));
    if (found > 1) {
        value.clear();
    }
    return true;
}

// Answers t_range (the request's Range, taken off before routing) on a complete 200: one
// satisfiable byte range gives 206 with that part of the body and its Content-Range, a range
// starting past the end 416 with Content-Range "bytes */length". Everything else gets the whole
// answer, as RFC 9110 allows: methods other than GET (14.2: HEAD too), other statuses (errors,
// 304), bodies streamed by cpp-httplib (files), compressed documents (their codings share one
// ETag, so a range resumed under another Accept-Encoding would splice two codings), several
// ranges, a malformed value, and an If-Range that is not the answer's ETag.
void apply_range(const httplib::Request& req, httplib::Response& res) {
    if (t_range.empty() || req.method != "GET" || res.status != 200 || res.body.empty() ||
        res.has_header("Content-Encoding")) {
        return;
    }
    const std::optional<ByteRange> r = single_byte_range(t_range);
    if (!r) {
        return;
    }
    if (req.has_header("If-Range")) {
        // Strong comparison: a weak tag or a date never matches (RFC 9110 13.1.5).
        const std::string etag = res.get_header_value("ETag");
        if (etag.empty() || etag.front() != '"' || req.get_header_value("If-Range") != etag) {
            return;
        }
    }
    const auto size = static_cast<std::int64_t>(res.body.size());
    std::int64_t first = r->first, last = r->last;
    if (first < 0) {
        first = size - std::min(last, size); // a suffix
        last = size - 1;
    } else if (last < 0 || last >= size) {
        last = size - 1;
    }
    res.headers.erase("Content-Length");
    if (first >= size) {
        // Unsatisfiable: starts past the end, or an empty suffix. The error replaces the
        // answer's own headers.
        const std::string length = std::to_string(size);
        for (const char* name : {"Content-Type", "ETag", "Cache-Control"}) {
            res.headers.erase(name);
        }
        send_error(res,
                   416,
                   r->first < 0 ? "the range asks for the last 0 bytes"
                                : "the range starts past the end of the " + length + " bytes");
        res.set_header("Content-Range", "bytes */" + length);
        res.set_header("Content-Length", std::to_string(res.body.size()));
        return;
    }
    res.status = 206;
    res.set_header("Content-Range",
                   "bytes " + std::to_string(first) + "-" + std::to_string(last) + "/" +
                       std::to_string(size));
    res.body = res.body.substr(static_cast<std::size_t>(first),
                               static_cast<std::size_t>(last - first + 1));
    res.set_header("Content-Length", std::to_string(res.body.size()));
}

// A request the connection loop may answer itself, read from its framed bytes: a GET or HEAD
// of /{layer}/{z}/{x}/{y}.{glb|drc|terrain} over HTTP/1.1, in a plain target (unreserved characters
// only, so cpp-httplib's decoding would leave it as it is and bad_path would accept it), with no
// body and none of the headers cpp-httplib acts on by itself (Range, Expect). The header values
// kept are what cpp-httplib would give the handlers: the first non-empty one of each name, blanks
// trimmed; a value it would percent-decode is not taken.
struct QuickRequest {
    std::string_view method, target, layer, z, x, y, extension;
    std::string_view origin, if_none_match, connection; // empty: absent
    std::string_view accept, accept_encoding;           // read for .terrain only
};

// Header lines longer than this are left to cpp-httplib (it refuses those over 8192 bytes).
constexpr std::size_t kQuickLineBytes = 4096;

bool parse_quick(std::string_view request, QuickRequest& q) {
    const auto line_end = request.find("\r\n");
    if (line_end == std::string_view::npos || line_end > kQuickLineBytes) {
        return false;
    }
    const std::string_view line = request.substr(0, line_end);
    const auto sp1 = line.find(' ');
    const auto sp2 = sp1 == std::string_view::npos ? sp1 : line.find(' ', sp1 + 1);
    if (sp2 == std::string_view::npos || line.substr(sp2 + 1) != "HTTP/1.1") {
        return false;
    }
    q.method = line.substr(0, sp1);
    q.target = line.substr(sp1 + 1, sp2 - sp1 - 1);
    if ((q.method != "GET" && q.method != "HEAD") || q.target.size() > kMaxUrlLength) {
        return false;
    }
    for (char c : q.target) {
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '/' && c != '-' && c != '.' &&
            c != '_' && c != '~') {
            return false;
        }
    }
    // Four segments, single slashes: the tile route's own shape, and no other route's ("web"
    // is the viewer's files when there is a viewer).
    std::string_view segments[4];
    std::string_view rest = q.target;
    for (auto& segment : segments) {
        if (rest.empty() || rest[0] != '/') {
            return false;
        }
        rest.remove_prefix(1);
        segment = rest.substr(0, rest.find('/'));
        rest.remove_prefix(segment.size());
        if (segment.empty()) {
            return false;
        }
    }
    if (!rest.empty() || segments[0] == "." || segments[0] == ".." || segments[0] == "web") {
        return false;
    }
    const auto dot = segments[3].find('.');
    if (dot == std::string_view::npos) {
        return false;
    }
    q.layer = segments[0];
    q.z = segments[1];
    q.x = segments[2];
    q.y = segments[3].substr(0, dot);
    q.extension = segments[3].substr(dot + 1);
    if (q.extension != "glb" && q.extension != "drc" && q.extension != "terrain") {
        return false;
    }
    const bool terrain = q.extension == "terrain";
    std::size_t pos = line_end + 2;
    for (;;) {
        const auto end = request.find("\r\n", pos);
        if (end == std::string_view::npos || end - pos > kQuickLineBytes) {
            return false;
        }
        if (end == pos) {
            return end + 2 == request.size(); // no body
        }
        const std::string_view field = request.substr(pos, end - pos);
        pos = end + 2;
        const auto colon = field.find(':');
        if (colon == std::string_view::npos) {
            return false;
        }
        const std::string_view name = field.substr(0, colon);
        const std::string_view value = trim_ows(field.substr(colon + 1));
        if (equals_ci(name, "Range") || equals_ci(name, "Expect")) {
            return false;
        }
        std::string_view* kept = equals_ci(name, "Origin")            ? &q.origin
                                 : equals_ci(name, "If-None-Match")   ? &q.if_none_match
                                 : equals_ci(name, "Connection")      ? &q.connection
                                 : !terrain                           ? nullptr
                                 : equals_ci(name, "Accept")          ? &q.accept
                                 : equals_ci(name, "Accept-Encoding") ? &q.accept_encoding
                                                                      : nullptr;
        if (!kept || value.empty() || !kept->empty()) {
            continue; // cpp-httplib drops empty values and answers with the first
        }
        if (value.find('%') != std::string_view::npos) {
            return false;
        }
        *kept = value;
    }
}

// The request bytes of one framed request, read by cpp-httplib's parser; what it writes is the
// response. Reading stops at the end of this request, so it can never eat into the next one.
class MemoryStream final : public httplib::Stream {
public:
    MemoryStream(std::string_view in, const Peer& peer, std::string& out)
        : in_(in), peer_(peer), out_(out) {}
    bool is_readable() const override { return pos_ < in_.size(); }
    bool is_writable() const override { return true; }
    ssize_t read(char* ptr, size_t size) override {
        const std::size_t n = std::min(size, in_.size() - pos_);
        std::memcpy(ptr, in_.data() + pos_, n);
        pos_ += n;
        return static_cast<ssize_t>(n);
    }
    ssize_t write(const char* ptr, size_t size) override {
        out_.append(ptr, size);
        return static_cast<ssize_t>(size);
    }
    void get_remote_ip_and_port(std::string& ip, int& port) const override {
        ip = peer_.ip;
        port = peer_.port;
    }
    void get_local_ip_and_port(std::string& ip, int& port) const override {
        ip.clear();
        port = 0;
    }
    socket_t socket() const override { return INVALID_SOCKET; }

private:
    std::string_view in_;
    std::size_t pos_ = 0;
    const Peer& peer_;
    std::string& out_;
};

// cpp-httplib's accept loop hands each connection to a task queue; this one runs the task at
// once, as it only passes the socket on to the connection loop.
class InlineQueue final : public httplib::TaskQueue {
public:
    void enqueue(std::function<void()> fn) override { fn(); }
    void shutdown() override {}
};

// cpp-httplib 0.11.4 gives each connection a thread of its own for its whole life, reading
// requests one by one with blocking reads: idle and slow clients then starve everyone else,
// and bytes of pipelined requests are lost. Its per-connection entry point is virtual, and
// its request parser and router (process_request) take any Stream; so this server hands
// accepted sockets to its own connection loop (server/connections.hpp), which frames each
// request and calls process_request on a worker with the request's bytes in memory.
class Server : public httplib::Server {
public:
    std::function<void(socket_t)> adopt;

    // Parses, routes and answers one request held in `strm`.
    bool answer(httplib::Stream& strm,
                bool last,
                bool& closed,
                const std::function<void(httplib::Request&)>& setup) {
        return process_request(strm, last, closed, setup);
    }

    // cpp-httplib 0.11.4 listens with a backlog of 5: a burst of more simultaneous connections
    // overflows the accept queue, and the dropped SYNs are retried by the client a second
    // later. Listening again on the bound socket raises the backlog (Linux and BSD allow it).
    void raise_backlog() {
        const socket_t sock = svr_sock_;
        if (sock != INVALID_SOCKET && ::listen(sock, SOMAXCONN) != 0) {
            log::warn("cannot raise the listen backlog; bursts of connections may stall");
        }
    }

private:
    bool process_and_close_socket(socket_t sock) override {
        adopt(sock);
        return true;
    }
};

// Raises the soft limit of open files to the hard one (many idle connections are fine, each
// is a descriptor), and returns how many connections fit in it.
std::size_t connection_capacity(std::size_t wanted) {
    rlimit lim{};
    if (getrlimit(RLIMIT_NOFILE, &lim) != 0) {
        return wanted;
    }
    if (lim.rlim_cur < lim.rlim_max) {
        rlimit raised = lim;
        raised.rlim_cur = lim.rlim_max;
        if (setrlimit(RLIMIT_NOFILE, &raised) == 0) {
            lim = raised;
        }
    }
    // Keep descriptors for stores, DEMs, files of the viewer and the process itself.
    constexpr rlim_t kReserve = 256;
    const rlim_t room = lim.rlim_cur > 2 * kReserve ? lim.rlim_cur - kReserve : lim.rlim_cur / 2;
    return std::min<std::size_t>(wanted, static_cast<std::size_t>(room));
}

} // namespace

struct HttpServer::Impl {
    TileService& tiles;
    Metrics& metrics;
    HttpOptions options;
    Server server;
    int port = 0;
    std::mutex stop_mutex;
    bool stop_requested = false;
    std::vector<std::filesystem::path> web_roots; // canonical; files are served from these only
    // /layers of the layer set it was made from; made again once a reload swaps the set.
    std::mutex layers_mutex;
    std::shared_ptr<const Blob> layers_blob;
    std::shared_ptr<const LayerSet> layers_set;
    std::string keep_alive; // the Keep-Alive header cpp-httplib sends
    bool cors_any = false;  // cors_origins holds "*"
    // A list of origins (no "*"): every answer depends on Origin, one asked without it too, so
    // that a shared cache never gives that one to a page of a listed origin.
    bool vary_origin = false;
    std::unique_ptr<Connections> connections; // last: stopped first

    Impl(TileService& t, Metrics& m, const HttpOptions& o) : tiles(t), metrics(m), options(o) {
        const auto& limits = options.limits;
        server.new_task_queue = [] { return new InlineQueue; };
        // These only shape the Keep-Alive header now; the connection loop enforces them.
        server.set_keep_alive_max_count(static_cast<std::size_t>(limits.max_requests));
        const time_t keep_alive_seconds = std::max<time_t>(
            1, std::chrono::duration_cast<std::chrono::seconds>(limits.idle_timeout).count());
        server.set_keep_alive_timeout(keep_alive_seconds);
        keep_alive = "timeout=" + std::to_string(keep_alive_seconds) +
                     ", max=" + std::to_string(limits.max_requests);
        for (const auto& origin : options.cors_origins) {
            cors_any = cors_any || origin == "*";
        }
        vary_origin = !cors_any && !options.cors_origins.empty();
        server.set_payload_max_length(limits.head.body_bytes);
        // SO_REUSEADDR alone: cpp-httplib's default adds SO_REUSEPORT, with which a second
        // server on the same port starts "successfully" and steals part of the connections.
        server.set_socket_options([](socket_t sock) {
            const int yes = 1;
            setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
        });
        if (!options.web_root.empty()) {
            namespace fs = std::filesystem;
            std::error_code ec;
            const fs::path root = fs::canonical(options.web_root, ec);
            if (ec) {
                throw IoError(options.web_root + ": the viewer directory cannot be served (" +
                              ec.message() + ")");
            }
            web_roots.push_back(root);
            // node_modules may be a link to a shared install (workspaces); it is the one link
            // followed out of the directory, fixed here at startup.
            const fs::path modules = fs::canonical(root / "node_modules", ec);
            if (!ec && !within(modules, root)) {
                web_roots.push_back(modules);
            }
        }
        install();
        ConnectionLimits capped = limits;
        capped.max_connections = connection_capacity(limits.max_connections);
        ConnectionHandlers handlers;
        handlers.answer = [this](std::string_view request, const Peer& peer, bool last) {
            return answer(request, peer, last);
        };
        handlers.quick = [this](std::string_view request, const Peer&, bool last, Reply& reply) {
            return quick(request, last, reply);
        };
        handlers.refuse = [this](int status, const std::string& why, const Peer& peer) {
            return refuse(status, why, peer);
        };
        // One connection loop per core (up to 4): cached tiles are answered on the loops'
        // threads, so one loop alone would leave the other cores to the clients.
        const int loops = std::clamp(tiler::usable_cpus(), 1, static_cast<int>(kMaxLoops));
        connections =
            std::make_unique<Connections>(capped,
                                          std::max(2, options.http_threads) + tiles.max_waiting(),
                                          std::move(handlers),
                                          metrics,
                                          loops);
        server.adopt = [this](socket_t sock) { connections->adopt(sock); };
    }

    Reply answer(std::string_view request, const Peer& peer, bool last) {
        Reply reply;
        // Range is answered by apply_range after routing, so cpp-httplib must not see it: it
        // would answer 416 to a unit it does not know, which RFC 9110 says to ignore.
        std::string without_range;
        t_range.clear();
        if (take_range(request, t_range, without_range)) {
            request = without_range;
        }
        t_peer_ip = peer.ip;
        MemoryStream strm(request, peer, reply.bytes);
        bool closed = false;
        bool ok = false;
        try {
            ok = server.answer(strm, last, closed, [](httplib::Request& req) {
                t_accept_encoding.clear();
                const auto it = req.headers.find("Accept-Encoding");
                if (it != req.headers.end()) {
                    t_accept_encoding = it->second.substr(0, 1024);
                }
                req.headers.erase("Accept-Encoding");
            });
        } catch (const std::exception& e) {
            // Handlers do not throw past the exception handler; this is cpp-httplib itself.
            log::error(std::string("answering a request failed: ") + e.what());
        }
        if (t_request.active) {
            --metrics.in_flight_requests;
            t_request.active = false;
        }
        reply.close = !ok || closed || last || reply.bytes.empty();
        return reply;
    }

    // The answer to a request for a tile already in memory, made without cpp-httplib and so
    // cheap enough for the connection loop's thread: the bytes the routes above would send
    // (pre-routing's CORS, serve_tile and send_blob, cpp-httplib's framing headers, sorted by
    // name as its header map sorts them), the same metrics and access log line. False, with
    // nothing counted, for anything else (see parse_quick) and for tiles not in memory.
    bool quick(std::string_view request, bool last, Reply& reply) {
        const auto start = std::chrono::steady_clock::now();
        QuickRequest q;
        std::int64_t z = 0, x = 0, y = 0;
        // An id outside the scheme is never cached (TileService::tile parses it first): it
        // misses here and the route answers 400.
        if (!parse_quick(request, q) || !parse_index(q.z, 2, z) || !parse_index(q.x, 10, x) ||
            !parse_index(q.y, 10, y)) {
            return false;
        }
        const tiler::TileId id{static_cast<int>(z), x, y};
        const bool terrain = q.extension == "terrain";
        const tiler::Format format = terrain                ? tiler::Format::Terrain
                                     : q.extension == "glb" ? tiler::Format::Glb
                                                            : tiler::Format::Drc;
        // A .terrain tile as serve_terrain sends it: the extensions Accept names, in the coding
        // Accept-Encoding prefers, when that coding is already made (compressing is a worker's
        // job). A 304 sends no body, so any coding will do.
        Coding coding = Coding::Identity;
        const std::string* body = nullptr;
        const auto blob =
            terrain
                ? tiles.cached_terrain(std::string(q.layer),
                                       id,
                                       accepted_extensions(std::string(q.accept)),
                                       [&](const Blob& b) {
                                           coding =
                                               b.bytes.size() >= kMinCompressBytes
                                                   ? pick_coding(q.accept_encoding.substr(0, 1024))
                                                   : Coding::Identity;
                                           body = b.encoded_if_made(coding);
                                           if (!body && !q.if_none_match.empty() &&
                                               lists_etag(std::string(q.if_none_match), b.etag)) {
                                               body = &b.bytes; // a 304: none of it is sent
                                           }
                                           return body != nullptr;
                                       })
                : tiles.cached_tile(std::string(q.layer), id, format);
        if (!blob) {
            return false;
        }
        if (!terrain) {
            body = &blob->bytes;
        }
        const bool head = q.method == "HEAD";
        const bool fresh =
            !q.if_none_match.empty() && lists_etag(std::string(q.if_none_match), blob->etag);
        const int status = fresh ? 304 : 200;
        // cpp-httplib closes on exactly "close" (and on HTTP/1.0, which is not taken here).
        reply.close = last || q.connection == "close";
        std::string& out = reply.bytes;
        out.reserve(512);
        out += fresh ? "HTTP/1.1 304 Not Modified\r\n" : "HTTP/1.1 200 OK\r\n";
        if (head) {
            out += "Accept-Ranges: bytes\r\n";
        }
        if (cors_any) {
            out += "Access-Control-Allow-Origin: *\r\n";
        } else if (vary_origin && !q.origin.empty()) {
            for (const auto& o : options.cors_origins) {
                if (o == q.origin) {
                    out += "Access-Control-Allow-Origin: ";
                    out += o;
                    out += "\r\n";
                }
            }
        }
        if (!options.cors_origins.empty()) {
            out += "Access-Control-Expose-Headers: ETag, Content-Length, Content-Range, "
                   "Retry-After\r\n";
        }
        out += "Cache-Control: ";
        out += kTileCacheControl;
        out += "\r\n";
        if (reply.close) {
            out += "Connection: close\r\n";
        }
        if (!fresh && coding != Coding::Identity) {
            out += "Content-Encoding: ";
            out += coding_name(coding);
            out += "\r\n";
        }
        out += "Content-Length: ";
        out += fresh ? "0" : std::to_string(body->size());
        out += "\r\n";
        if (!fresh) {
            out += "Content-Type: ";
            out += tiler::media_type(format);
            out += "\r\n";
        }
        out += "ETag: ";
        out += blob->etag;
        out += "\r\n";
        if (!reply.close) {
            out += "Keep-Alive: ";
            out += keep_alive;
            out += "\r\n";
        }
        if (terrain || vary_origin) {
            out += "Vary: ";
            out += terrain ? terrain_vary() : "Origin";
            out += "\r\n";
        }
        out += "\r\n";
        if (!fresh && !head) {
            reply.body = std::shared_ptr<const std::string>(blob, body);
        }
        ++metrics.quick_answers;
        const double seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        metrics.record_request(terrain ? "terrain" : "tile", status, seconds);
        if (log::level() <= log::Level::Info) {
            // As the logger of the routes writes it (the target needs no cleaning here).
            const std::string_view target =
                q.target.size() > 200 ? q.target.substr(0, 200) : q.target;
            char line[160];
            std::snprintf(line,
                          sizeof line,
                          " %d %zu B %.2f ms",
                          status,
                          fresh ? std::size_t{0} : body->size(),
                          seconds * 1e3);
            log::write_queued(log::Level::Info,
                              std::string(q.method) + " " + std::string(target) +
                                  (q.target.size() > 200 ? "..." : "") + line);
        }
        return true;
    }

    // The answer to a request the connection loop could not frame (or that came too slowly):
    // one JSON error, and the connection closes.
    std::string refuse(int status, const std::string& why, const Peer& peer) {
        metrics.record_request(status == 503 ? "refused" : "malformed", status, 0.0);
        log::write_queued(log::Level::Info,
                          peer.ip + ":" + std::to_string(peer.port) + " " + std::to_string(status) +
                              " " + why + "; connection closed");
        const std::string body = "{\"error\":\"" + json_escape(why) + "\"}\n";
        std::string text =
            "HTTP/1.1 " + std::to_string(status) + " " + status_text(status) +
            "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
            "\r\nCache-Control: no-store\r\nConnection: close\r\n";
        if (!options.cors_origins.empty()) {
            bool any = false;
            for (const auto& o : options.cors_origins) {
                any = any || o == "*";
            }
            if (any) {
                text += "Access-Control-Allow-Origin: *\r\n";
            }
        }
        if (status == 503) {
            text += "Retry-After: " + std::to_string(kRetryAfterSeconds) + "\r\n";
        }
        return text + "\r\n" + body;
    }

    // A file of the viewer: `rel` is the decoded path below /web/ (bad_path has refused '..',
    // NUL, backslashes and encoded separators). The real path, links resolved, must lie in one
    // of web_roots, whatever links the directory holds.
    void serve_web_file(const std::string& rel, httplib::Response& res) {
        namespace fs = std::filesystem;
        const auto refuse_missing = [&] {
            throw NotFound("no file /web/" + rel.substr(0, 200) + " in the viewer");
        };
        std::error_code ec;
        fs::path real = fs::canonical(web_roots.front() / rel, ec);
        if (ec) {
            refuse_missing();
        }
        if (fs::is_directory(real, ec)) {
            real = fs::canonical(real / "index.html", ec);
            if (ec) {
                refuse_missing();
            }
        }
        bool inside = false;
        for (const auto& root : web_roots) {
            inside = inside || within(real, root);
        }
        if (!inside) {
            log::warn("/web/" + rel.substr(0, 200) + " leads out of the viewer's directory (to " +
                      real.string().substr(0, 200) + "); refused");
            refuse_missing();
        }
        // O_NOFOLLOW: the last component cannot have become a link since it was resolved.
        const int fd = ::open(real.c_str(), O_RDONLY | O_NOFOLLOW | O_CLOEXEC);
        if (fd < 0) {
            refuse_missing();
        }
        struct stat st {};
        std::string bytes;
        const bool regular = fstat(fd, &st) == 0 && S_ISREG(st.st_mode);
        if (regular) {
            bytes.resize(static_cast<std::size_t>(st.st_size));
            std::size_t got = 0;
            while (got < bytes.size()) {
                const ssize_t n = ::read(fd, bytes.data() + got, bytes.size() - got);
                if (n <= 0) {
                    break;
                }
                got += static_cast<std::size_t>(n);
            }
            bytes.resize(got);
        }
        ::close(fd);
        if (!regular) {
            refuse_missing();
        }
        res.set_header("Cache-Control", "public, max-age=3600");
        res.set_content(std::move(bytes), file_media_type(real.string()));
    }

    void cors(const httplib::Request& req, httplib::Response& res) const {
        if (cors_any) {
            res.set_header("Access-Control-Allow-Origin", "*");
        } else if (vary_origin) {
            if (req.has_header("Origin")) {
                const std::string origin = req.get_header_value("Origin");
                for (const auto& o : options.cors_origins) {
                    if (o == origin) {
                        res.set_header("Access-Control-Allow-Origin", origin);
                    }
                }
            }
            res.set_header("Vary", "Origin");
        }
        if (!options.cors_origins.empty()) {
            res.set_header("Access-Control-Expose-Headers",
                           "ETag, Content-Length, Content-Range, Retry-After");
        }
    }

    // The Vary of a .terrain tile: its extensions depend on Accept, its coding on
    // Accept-Encoding, and with a list of CORS origins the answer on Origin.
    const char* terrain_vary() const {
        return vary_origin ? "Origin, Accept, Accept-Encoding" : "Accept, Accept-Encoding";
    }

    // /layers as the layer set now served says (a reload swaps the set).
    std::shared_ptr<const Blob> layers_document() {
        const auto set = tiles.layers();
        std::lock_guard lock(layers_mutex);
        if (!layers_blob || layers_set != set) {
            auto blob = std::make_shared<Blob>();
            blob->bytes = layers_json(set);
            blob->etag = make_etag(blob->bytes);
            layers_blob = std::move(blob);
            layers_set = set;
        }
        return layers_blob;
    }

    std::string layers_json(const std::shared_ptr<const LayerSet>& set) const {
        std::ostringstream out;
        out << "{\"layers\":[";
        bool first = true;
        for (const auto& served : set->served) {
            const auto& layer = *served.layer;
            const auto& o = layer.options();
            const auto b = layer.data_bounds();
            out << (first ? "" : ",") << "{\"name\":\"" << json_escape(o.name) << "\""
                << ",\"scheme\":\"" << tiler::to_string(o.scheme) << "\""
                << ",\"tile_size\":" << o.tile_size << ",\"min_zoom\":" << layer.min_zoom()
                << ",\"max_zoom\":" << layer.max_zoom()
                << ",\"bounds\":{\"west\":" << number(b.west) << ",\"south\":" << number(b.south)
                << ",\"east\":" << number(b.east) << ",\"north\":" << number(b.north) << "}"
                << ",\"eps_by_zoom\":{";
            for (int z = layer.min_zoom(); z <= layer.max_zoom(); ++z) {
                out << (z == layer.min_zoom() ? "" : ",") << "\"" << z
                    << "\":" << number(layer.eps_for_zoom(z));
            }
            out << "},\"eps_levels\":[";
            for (std::size_t i = 0; i < o.eps_levels.size(); ++i) {
                out << (i ? "," : "") << number(o.eps_levels[i]);
            }
            out << "],\"formats\":[";
            for (std::size_t i = 0; i < served.formats.size(); ++i) {
                out << (i ? "," : "") << "\"" << tiler::format_name(served.formats[i]) << "\"";
            }
            out << "],\"stored\":" << (served.store ? "true" : "false") << ",\"tileset\":\"/"
                << o.name << "/tileset.json\",\"tiles\":\"/" << o.name << "/{z}/{x}/{y}.{format}\"";
            if (o.scheme == tiler::Scheme::Geodetic &&
                std::find(served.formats.begin(), served.formats.end(), tiler::Format::Terrain) !=
                    served.formats.end()) {
                out << ",\"layer_json\":\"/" << o.name << "/layer.json\"";
            }
            if (o.scheme == tiler::Scheme::Geodetic &&
                std::find(served.formats.begin(), served.formats.end(), tiler::Format::Terrain3d) !=
                    served.formats.end()) {
                out << ",\"terrain_tileset\":\"/" << o.name << "/terrain/tileset.json\"";
            }
            out << dem_json(served) << "}";
            first = false;
        }
        // Layers that failed to open at startup: their routes answer 503 with this reason.
        out << "],\"unavailable\":[";
        first = true;
        for (const auto& u : set->unavailable) {
            out << (first ? "" : ",") << "{\"name\":\"" << json_escape(u.name) << "\",\"error\":\""
                << json_escape(u.reason) << "\"}";
            first = false;
        }
        out << "]}\n";
        return out.str();
    }

    // ",\"dem\":{...}" for a layer serving raster DEM tiles, else "".
    static std::string dem_json(const ServedLayer& served) {
        std::string encodings;
        for (auto f : served.formats) {
            if (tiler::is_dem_format(f)) {
                encodings +=
                    std::string(encodings.empty() ? "" : ",") + "\"" + tiler::format_name(f) + "\"";
            }
        }
        if (encodings.empty()) {
            return "";
        }
        const auto& o = served.layer->options();
        const tiler::DemTilePlan plan = tiler::dem_tile_plan(*served.layer);
        return ",\"dem\":{\"tilejson\":\"/" + o.name + "/dem/tilejson.json\",\"tiles\":\"/" +
               o.name + "/dem/{z}/{x}/{y}.png\",\"encodings\":[" + encodings +
               "],\"tile_size\":" + std::to_string(plan.tile_size) +
               ",\"min_zoom\":" + std::to_string(plan.min_zoom) +
               ",\"max_zoom\":" + std::to_string(plan.max_zoom) + ",\"heights\":\"" +
               tiler::to_string(o.dem_heights) + "\"}";
    }

    // TileJSON 3.0.0 of a layer's raster DEM tiles in one encoding, as MapLibre's raster-dem
    // source reads it (with its `encoding` and `tileSize`).
    std::string
    tilejson(const ServedLayer& served, tiler::Format encoding, const std::string& origin) const {
        const std::string& name = served.layer->options().name;
        return tiler::dem_tilejson(
            *served.layer,
            encoding,
            origin + "/" + name + "/dem/{z}/{x}/{y}.png?encoding=" + tiler::format_name(encoding));
    }

    // The layer, which must serve `format` (NotFound otherwise).
    std::shared_ptr<const ServedLayer> serving(const std::string& name,
                                               tiler::Format format) const {
        std::shared_ptr<const ServedLayer> served = tiles.require(name);
        if (std::find(served->formats.begin(), served->formats.end(), format) ==
            served->formats.end()) {
            throw NotFound("layer '" + name + "' does not serve " + tiler::format_name(format) +
                           " DEM tiles");
        }
        return served;
    }

    std::string landing_html() const {
        std::ostringstream out;
        out << "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>Terrabound</title>"
               "<style>body{font-family:sans-serif;margin:2em}td,th{padding:.2em 1em;"
               "text-align:left}</style></head><body>\n<h1>Terrabound</h1>\n"
               "<p>Terrain tiles with a guaranteed vertical error. Layers as JSON: "
               "<a href=\"/layers\">/layers</a>. Metrics: <a href=\"/metrics\">/metrics</a>."
               "</p>\n<table><tr><th>layer</th><th>zooms</th><th>tileset</th>"
               "<th>sample tile</th></tr>\n";
        const auto set = tiles.layers();
        for (const auto& served : set->served) {
            const auto& layer = *served.layer;
            const std::string name = html_escape(layer.options().name);
            const int z = layer.min_zoom();
            const auto range = layer.tiles_at(z);
            out << "<tr><td>" << name << "</td><td>" << layer.min_zoom() << ".." << layer.max_zoom()
                << "</td><td><a href=\"/" << name << "/tileset.json\">tileset.json</a></td><td>";
            const auto mesh =
                std::find_if(served.formats.begin(), served.formats.end(), [](tiler::Format f) {
                    return !tiler::is_dem_format(f);
                });
            if (!range.empty() && mesh != served.formats.end()) {
                const std::string tile = "/" + name + "/" + std::to_string(z) + "/" +
                                         std::to_string(range.x0) + "/" + std::to_string(range.y0) +
                                         "." + tiler::extension(*mesh);
                out << "<a href=\"" << tile << "\">" << tile << "</a>";
            }
            out << "</td></tr>\n";
        }
        for (const auto& u : set->unavailable) {
            out << "<tr><td>" << html_escape(u.name)
                << "</td><td colspan=\"3\">unavailable: " << html_escape(u.reason)
                << "</td></tr>\n";
        }
        out << "</table>\n</body></html>\n";
        return out.str();
    }

    void install() {
        server.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
            t_request = {std::chrono::steady_clock::now(), "unmatched", true};
            ++metrics.in_flight_requests;
            cors(req, res);
            if (req.target.size() > kMaxUrlLength) {
                t_request.route = "rejected";
                send_error(res,
                           414,
                           "the URL is longer than " + std::to_string(kMaxUrlLength) +
                               " characters");
                return httplib::Server::HandlerResponse::Handled;
            }
            if (req.method != "GET" && req.method != "HEAD" && req.method != "OPTIONS") {
                t_request.route = "rejected";
                res.set_header("Allow", "GET, HEAD, OPTIONS");
                send_error(res, 405, "method " + req.method + " is not allowed; use GET");
                return httplib::Server::HandlerResponse::Handled;
            }
            if (const char* why = bad_path(req)) {
                t_request.route = "rejected";
                send_error(res, 400, std::string("bad path: ") + why);
                return httplib::Server::HandlerResponse::Handled;
            }
            return httplib::Server::HandlerResponse::Unhandled;
        });

        server.set_exception_handler(
            [](const httplib::Request& req, httplib::Response& res, std::exception_ptr ep) {
                try {
                    std::rethrow_exception(ep);
                } catch (const InputError& e) {
                    send_error(res, 400, e.what());
                } catch (const NotFound& e) {
                    send_error(res, 404, e.what());
                } catch (const Unavailable& e) {
                    send_error(res, 503, e.what()); // logged once, when it failed to open
                } catch (const std::exception& e) {
                    log::error(loggable(req) + ": " + e.what());
                    send_error(res, 500, "internal error; see the server log");
                } catch (...) {
                    log::error(loggable(req) + ": unknown exception");
                    send_error(res, 500, "internal error; see the server log");
                }
            });

        // Fills in a JSON body for errors that cpp-httplib produced itself (no route, 414, ...).
        server.set_error_handler(httplib::Server::HandlerWithResponse(
            [](const httplib::Request&, httplib::Response& res) {
                if (res.body.empty()) {
                    send_error(res, res.status, reason(res.status));
                }
                return httplib::Server::HandlerResponse::Handled;
            }));

        // After routing, before anything is written: the Range taken off the request.
        server.set_post_routing_handler(
            [](const httplib::Request& req, httplib::Response& res) { apply_range(req, res); });

        server.set_logger([this](const httplib::Request& req, const httplib::Response& res) {
            const auto now = std::chrono::steady_clock::now();
            const bool active = t_request.active;
            const double seconds =
                active ? std::chrono::duration<double>(now - t_request.start).count() : 0.0;
            const char* route = active ? t_request.route : "unparsed";
            if (active) {
                --metrics.in_flight_requests;
                t_request.active = false;
            }
            metrics.record_request(route, res.status, seconds);
            if (log::level() <= log::Level::Info) {
                char line[160];
                std::snprintf(line,
                              sizeof line,
                              " %d %zu B %.2f ms",
                              res.status,
                              res.body.size(),
                              seconds * 1e3);
                log::write_queued(log::Level::Info, loggable(req) + line);
            }
        });

        server.Options(".*", [](const httplib::Request& req, httplib::Response& res) {
            t_request.route = "preflight";
            res.status = 204;
            res.set_header("Access-Control-Allow-Methods", "GET, HEAD, OPTIONS");
            // The header names asked for are allowed, echoed only when they are a list of
            // header-name tokens (RFC 9110); anything else gets "*" rather than its text back.
            const std::string asked = req.get_header_value("Access-Control-Request-Headers");
            res.set_header("Access-Control-Allow-Headers",
                           is_token_list(asked) ? asked : std::string("*"));
            res.set_header("Access-Control-Max-Age", "86400");
            res.set_header("Allow", "GET, HEAD, OPTIONS");
        });

        if (!web_roots.empty()) {
            // The viewer's static files; before the layer routes, which would match too.
            server.Get(R"(/web/(.*))", [this](const httplib::Request& req, httplib::Response& res) {
                t_request.route = "web";
                serve_web_file(req.matches[1].str(), res);
            });
        }

        server.Get("/", [this](const httplib::Request& req, httplib::Response& res) {
            t_request.route = "landing";
            res.set_header("Cache-Control", kNoStore);
            if (!options.web_root.empty()) {
                std::ifstream in(options.web_root + "/index.html", std::ios::binary);
                std::ostringstream page;
                page << in.rdbuf();
                if (in && !page.str().empty()) {
                    res.set_content(page.str(), "text/html; charset=utf-8");
                    return;
                }
                log::warn(loggable(req) + ": " + options.web_root +
                          "/index.html is unreadable; sending the plain landing page");
            }
            res.set_content(landing_html(), "text/html; charset=utf-8");
        });

        server.Get("/health", [](const httplib::Request&, httplib::Response& res) {
            t_request.route = "health";
            res.set_header("Cache-Control", kNoStore);
            res.set_content("{\"status\":\"ok\"}\n", "application/json");
        });

        server.Get("/metrics", [this](const httplib::Request& req, httplib::Response& res) {
            t_request.route = "metrics";
            if (options.metrics == MetricsAccess::Off) {
                throw NotFound("/metrics is off on this server (\"metrics\" in the config's "
                               "server section, or --metrics)");
            }
            if (options.metrics == MetricsAccess::Loopback && !from_this_machine(req)) {
                send_error(res,
                           403,
                           "/metrics answers this machine only (127.0.0.1 or ::1, not through a "
                           "proxy); \"metrics\": \"on\" in the config, or --metrics on, opens it");
                return;
            }
            res.set_header("Cache-Control", kNoStore);
            std::string text = metrics.render();
            text += "# HELP tb_tiles_over_eps Tiles made whose error measured at the source's "
                    "pixels exceeds their zoom's eps (they publish the larger bound).\n"
                    "# TYPE tb_tiles_over_eps gauge\n";
            const auto set = tiles.layers();
            for (const auto& served : set->served) {
                text += "tb_tiles_over_eps{layer=\"" + served.layer->options().name + "\"} " +
                        std::to_string(served.layer->tiles_over_eps()) + "\n";
            }
            text += "# HELP tb_layers_unavailable Configured layers that failed to open at "
                    "startup (their routes answer 503).\n"
                    "# TYPE tb_layers_unavailable gauge\n"
                    "tb_layers_unavailable " +
                    std::to_string(set->unavailable.size()) + "\n";
            res.set_content(text, "text/plain; version=0.0.4; charset=utf-8");
        });

        server.Get("/layers", [this](const httplib::Request& req, httplib::Response& res) {
            t_request.route = "layers";
            send_blob(
                req, res, *layers_document(), "application/json", kDocumentCacheControl, &tiles);
        });

        // Raster DEM tiles and their TileJSON (EPSG:3857 XYZ, whatever the layer's scheme).
        server.Get(R"(/+([^/]+)/+dem/+([^/]*)/+([^/]*)/+([^/]*)\.png)",
                   [this](const httplib::Request& req, httplib::Response& res) {
                       t_request.route = "dem_tile";
                       serve_dem_tile(req, res);
                   });

        server.Get(R"(/+([^/]+)/+dem/+tilejson\.json)",
                   [this](const httplib::Request& req, httplib::Response& res) {
                       t_request.route = "tilejson";
                       const tiler::Format encoding = dem_encoding(req);
                       const auto served = serving(req.matches[1].str(), encoding);
                       Blob blob;
                       blob.bytes =
                           tilejson(*served, encoding, public_origin(req, options.host, port));
                       blob.etag = make_etag(blob.bytes);
                       send_blob(req, res, blob, "application/json", kDocumentCacheControl);
                       res.set_header("Vary", "Accept-Encoding");
                   });

        // Repeated slashes are tolerated ("/dem//8/1/2.glb"): some clients join a base URL that
        // ends in '/' with another '/' (FORMATS.md, 3d-tiles-renderer).
        server.Get(R"(/+([^/]+)/+([^/]*)/+([^/]*)/+([^/]*)\.(glb|drc))",
                   [this](const httplib::Request& req, httplib::Response& res) {
                       t_request.route = "tile";
                       serve_tile(req, res);
                   });

        // quantized-mesh tiles for CesiumTerrainProvider (their layer.json is a document).
        server.Get(R"(/+([^/]+)/+([^/]*)/+([^/]*)/+([^/]*)\.terrain)",
                   [this](const httplib::Request& req, httplib::Response& res) {
                       t_request.route = "terrain";
                       serve_terrain(req, res);
                   });

        // 3D Tiles terrain content for Cesium3DTilesTerrainProvider:
        // /{layer}/terrain/{root}/{level}/{x}/{y}.glb (its tileset and subtrees are documents).
        server.Get(R"(/+([^/]+)/+terrain/+([^/]*)/+([^/]*)/+([^/]*)/+([^/]*)\.glb)",
                   [this](const httplib::Request& req, httplib::Response& res) {
                       t_request.route = "terrain3d";
                       serve_terrain3d(req, res);
                   });

        server.Get(R"(/+([^/]+)/+(.+))",
                   [this](const httplib::Request& req, httplib::Response& res) {
                       t_request.route = "document";
                       std::string path;
                       for (char c : req.matches[2].str()) {
                           if (c != '/' || (!path.empty() && path.back() != '/')) {
                               path += c;
                           }
                       }
                       const auto blob = tiles.document(req.matches[1].str(), path);
                       const bool json =
                           path.size() >= 5 && path.compare(path.size() - 5, 5, ".json") == 0;
                       send_blob(req,
                                 res,
                                 *blob,
                                 json ? "application/json" : "application/octet-stream",
                                 kDocumentCacheControl,
                                 json ? &tiles : nullptr);
                   });
    }

    // No tile (the generation queue is full): 503 with Retry-After, and true.
    static bool busy(const std::shared_ptr<const Blob>& blob, httplib::Response& res) {
        if (blob) {
            return false;
        }
        res.set_header("Retry-After", std::to_string(kRetryAfterSeconds));
        send_error(res, 503, "the server is busy generating tiles; retry shortly");
        return true;
    }

    void serve_dem_tile(const httplib::Request& req, httplib::Response& res) {
        std::int64_t z = 0, x = 0, y = 0;
        if (!parse_index(req.matches[2].str(), 2, z) || !parse_index(req.matches[3].str(), 10, x) ||
            !parse_index(req.matches[4].str(), 10, y)) {
            throw InputError("DEM tile coordinates must be /dem/{z}/{x}/{y}.png with "
                             "non-negative integers (z up to " +
                             std::to_string(tiler::kMaxZoom) + ")");
        }
        const tiler::Format encoding = dem_encoding(req);
        const auto blob = tiles.tile(req.matches[1].str(),
                                     tiler::TileId{static_cast<int>(z), x, y},
                                     encoding,
                                     eps_param(req));
        if (busy(blob, res)) {
            return;
        }
        send_blob(req, res, *blob, tiler::media_type(encoding), kTileCacheControl);
    }

    void serve_terrain(const httplib::Request& req, httplib::Response& res) {
        std::int64_t z = 0, x = 0, y = 0;
        if (!parse_index(req.matches[2].str(), 2, z) || !parse_index(req.matches[3].str(), 10, x) ||
            !parse_index(req.matches[4].str(), 10, y)) {
            throw InputError("terrain tile coordinates must be /{z}/{x}/{y}.terrain with "
                             "non-negative integers (z up to " +
                             std::to_string(tiler::kMaxZoom) + ")");
        }
        const unsigned extensions = accepted_extensions(req.get_header_value("Accept"));
        const auto blob = tiles.terrain(req.matches[1].str(),
                                        tiler::TileId{static_cast<int>(z), x, y},
                                        extensions,
                                        eps_param(req));
        if (busy(blob, res)) {
            return;
        }
        send_blob(
            req, res, *blob, tiler::media_type(tiler::Format::Terrain), kTileCacheControl, &tiles);
        res.headers.erase("Vary");
        res.set_header("Vary", terrain_vary());
    }

    void serve_terrain3d(const httplib::Request& req, httplib::Response& res) {
        std::int64_t root = 0, level = 0, x = 0, y = 0;
        std::optional<tiler::ValidTile> tile;
        if (!parse_index(req.matches[2].str(), 1, root) ||
            !parse_index(req.matches[3].str(), 2, level) ||
            !parse_index(req.matches[4].str(), 10, x) ||
            !parse_index(req.matches[5].str(), 10, y) ||
            !(tile = tiler::terrain_tile_id(root, level, x, y))) {
            throw InputError("3D Tiles terrain tile coordinates must be "
                             "/terrain/{root}/{level}/{x}/{y}.glb with root 0 or 1, level up to " +
                             std::to_string(tiler::kMaxZoom) + ", and x, y below 2^level");
        }
        const auto blob =
            tiles.tile(req.matches[1].str(), tile->id(), tiler::Format::Terrain3d, eps_param(req));
        if (busy(blob, res)) {
            return;
        }
        send_blob(req,
                  res,
                  *blob,
                  tiler::media_type(tiler::Format::Terrain3d),
                  kTileCacheControl,
                  &tiles);
    }

    void serve_tile(const httplib::Request& req, httplib::Response& res) {
        const std::string layer = req.matches[1].str();
        std::int64_t z = 0, x = 0, y = 0;
        if (!parse_index(req.matches[2].str(), 2, z) || !parse_index(req.matches[3].str(), 10, x) ||
            !parse_index(req.matches[4].str(), 10, y)) {
            throw InputError("tile coordinates must be /{z}/{x}/{y} with non-negative integers "
                             "(z up to " +
                             std::to_string(tiler::kMaxZoom) + ")");
        }
        const tiler::Format format =
            req.matches[5].str() == "glb" ? tiler::Format::Glb : tiler::Format::Drc;
        const tiler::EpsChoice eps = eps_param(req);
        const auto blob = tiles.tile(layer, tiler::TileId{static_cast<int>(z), x, y}, format, eps);
        if (busy(blob, res)) {
            return;
        }
        // The body is copied (set_content), not streamed with set_content_provider: cpp-httplib
        // 0.11.4 aborts content providers once stop() is called, which would cut off the
        // responses in flight during a graceful shutdown.
        send_blob(req, res, *blob, tiler::media_type(format), kTileCacheControl);
    }
};

MetricsAccess parse_metrics_access(const std::string& text, const std::string& what) {
    if (text == "loopback") {
        return MetricsAccess::Loopback;
    }
    if (text == "on") {
        return MetricsAccess::On;
    }
    if (text == "off") {
        return MetricsAccess::Off;
    }
    throw InputError(what + ": expected loopback, on or off, got '" + text.substr(0, 40) + "'");
}

HttpServer::HttpServer(TileService& tiles, Metrics& metrics, const HttpOptions& options)
    : impl_(std::make_unique<Impl>(tiles, metrics, options)) {}

HttpServer::~HttpServer() = default;

int HttpServer::bind() {
    Impl& s = *impl_;
    const std::string where = s.options.host + ":" + std::to_string(s.options.port);
    errno = 0;
    const bool bound = s.options.port == 0
                           ? (s.port = s.server.bind_to_any_port(s.options.host)) > 0
                           : s.server.bind_to_port(s.options.host, s.options.port);
    if (!bound) {
        const int err = errno;
        if (err == EADDRINUSE) {
            throw InputError("cannot listen on " + where +
                             ": the port is in use by another program; stop it, or pick "
                             "another port with --port (0 picks a free one)");
        }
        if (err == EACCES) {
            throw InputError("cannot listen on " + where +
                             ": permission denied (ports below 1024 need privileges); pick "
                             "another port with --port");
        }
        throw InputError(
            "cannot listen on " + where + ": " +
            (err != 0 ? std::string(std::strerror(err)) : std::string("no such address")) +
            "; check --host (an address of this machine, or 0.0.0.0)");
    }
    if (s.options.port != 0) {
        s.port = s.options.port;
    }
    s.server.raise_backlog();
    return s.port;
}

void HttpServer::run() {
    {
        std::lock_guard<std::mutex> lock(impl_->stop_mutex);
        if (impl_->stop_requested) {
            return;
        }
    }
    impl_->server.listen_after_bind();
    impl_->connections->drain(); // answers what has fully arrived, then closes everything
}

void HttpServer::stop() {
    std::lock_guard<std::mutex> lock(impl_->stop_mutex);
    impl_->stop_requested = true;
    impl_->server.stop();
}

bool HttpServer::running() const {
    return impl_->server.is_running();
}

Reply HttpServer::answer(std::string_view request, bool last, bool quick) {
    Reply reply;
    if (!quick || !impl_->quick(request, last, reply)) {
        return impl_->answer(request, Peer{"127.0.0.1", 0}, last);
    }
    if (reply.body) {
        reply.bytes += *reply.body;
        reply.body.reset();
    }
    return reply;
}

} // namespace tb::server
