// HTTP routes of `terrabound serve`. Handlers are thin: parse the request, ask TileService,
// write the response. Errors are thrown and mapped to a status by one exception handler.
#include "server/http_server.hpp"

#include "core/error.hpp"
#include "tiler/json_number.hpp"
#include "tiler/log.hpp"
#include "tiler/tile_grid.hpp"

#include <httplib.h>

#include <sys/socket.h>

#include <charconv>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <sstream>

namespace tb::server {
namespace {

constexpr const char* kTileCacheControl = "public, max-age=604800"; // a week: tiles of a
                                                                    // config never change
constexpr const char* kDocumentCacheControl = "public, max-age=60";
constexpr const char* kNoStore = "no-store";
constexpr int kRetryAfterSeconds = 1;

// Per-request bookkeeping. cpp-httplib handles a request on one thread from the pre-routing
// handler to the logger, so a thread_local carries it between them.
struct RequestContext {
    std::chrono::steady_clock::time_point start;
    const char* route = "unmatched";
    bool active = false;
};
thread_local RequestContext t_request;

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

// A decimal digit string of at most `max_digits` digits, as a number.
bool parse_index(const std::string& text, std::size_t max_digits, std::int64_t& out) {
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

// True when the request's If-None-Match lists `etag` (or is "*").
bool not_modified(const httplib::Request& req, const std::string& etag) {
    if (!req.has_header("If-None-Match")) {
        return false;
    }
    const std::string header = req.get_header_value("If-None-Match");
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

void send_blob(const httplib::Request& req,
               httplib::Response& res,
               const Blob& blob,
               const char* media_type,
               const char* cache_control) {
    res.set_header("ETag", blob.etag);
    res.set_header("Cache-Control", cache_control);
    if (not_modified(req, blob.etag)) {
        res.status = 304;
        return;
    }
    res.status = 200;
    res.set_content(blob.bytes, media_type);
}

// cpp-httplib 0.11.4 listens with a backlog of 5: a burst of more simultaneous connections
// overflows the accept queue, and the dropped SYNs are retried by the client a second later.
// Listening again on the bound socket raises the backlog (Linux and BSD allow it).
class Server : public httplib::Server {
public:
    void raise_backlog() {
        const socket_t sock = svr_sock_;
        if (sock != INVALID_SOCKET && ::listen(sock, SOMAXCONN) != 0) {
            log::warn("cannot raise the listen backlog; bursts of connections may stall");
        }
    }
};

} // namespace

struct HttpServer::Impl {
    TileService& tiles;
    Metrics& metrics;
    HttpOptions options;
    Server server;
    int port = 0;
    std::mutex stop_mutex;
    bool stop_requested = false;

    Impl(TileService& t, Metrics& m, const HttpOptions& o) : tiles(t), metrics(m), options(o) {
        const int threads = std::max(2, options.http_threads);
        server.new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
        server.set_keep_alive_max_count(1000);
        server.set_keep_alive_timeout(5);
        server.set_read_timeout(10);
        server.set_write_timeout(10);
        server.set_payload_max_length(64 * 1024);
        server.set_tcp_nodelay(true);
        install();
    }

    void cors(const httplib::Request& req, httplib::Response& res) const {
        bool any = false;
        for (const auto& o : options.cors_origins) {
            any = any || o == "*";
        }
        if (any) {
            res.set_header("Access-Control-Allow-Origin", "*");
        } else if (req.has_header("Origin")) {
            const std::string origin = req.get_header_value("Origin");
            for (const auto& o : options.cors_origins) {
                if (o == origin) {
                    res.set_header("Access-Control-Allow-Origin", origin);
                }
            }
            res.set_header("Vary", "Origin");
        }
        if (!options.cors_origins.empty()) {
            res.set_header("Access-Control-Expose-Headers", "ETag, Content-Length, Retry-After");
        }
    }

    std::string layers_json() const {
        std::ostringstream out;
        out << "{\"layers\":[";
        bool first = true;
        for (const auto& served : tiles.layers()) {
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
                out << (i ? "," : "") << "\"" << tiler::extension(served.formats[i]) << "\"";
            }
            out << "],\"stored\":" << (served.store ? "true" : "false") << ",\"tileset\":\"/"
                << o.name << "/tileset.json\",\"tiles\":\"/" << o.name
                << "/{z}/{x}/{y}.{format}\"}";
            first = false;
        }
        out << "]}\n";
        return out.str();
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
        for (const auto& served : tiles.layers()) {
            const auto& layer = *served.layer;
            const std::string name = html_escape(layer.options().name);
            const int z = layer.min_zoom();
            const auto range = layer.tiles_at(z);
            out << "<tr><td>" << name << "</td><td>" << layer.min_zoom() << ".." << layer.max_zoom()
                << "</td><td><a href=\"/" << name << "/tileset.json\">tileset.json</a></td><td>";
            if (!range.empty() && !served.formats.empty()) {
                const std::string tile = "/" + name + "/" + std::to_string(z) + "/" +
                                         std::to_string(range.x0) + "/" + std::to_string(range.y0) +
                                         "." + tiler::extension(served.formats.front());
                out << "<a href=\"" << tile << "\">" << tile << "</a>";
            }
            out << "</td></tr>\n";
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
                log::info(loggable(req) + line);
            }
        });

        server.Options(".*", [this](const httplib::Request& req, httplib::Response& res) {
            t_request.route = "preflight";
            res.status = 204;
            res.set_header("Access-Control-Allow-Methods", "GET, HEAD, OPTIONS");
            const std::string asked = req.get_header_value("Access-Control-Request-Headers");
            res.set_header("Access-Control-Allow-Headers", asked.empty() ? "*" : asked);
            res.set_header("Access-Control-Max-Age", "86400");
            res.set_header("Allow", "GET, HEAD, OPTIONS");
        });

        if (!options.web_root.empty()) {
            // The viewer's static files. cpp-httplib matches mount points before any route and
            // refuses paths that climb out of the directory.
            for (const auto& [ext, type] :
                 std::initializer_list<std::pair<const char*, const char*>>{
                     {"js", "text/javascript"},
                     {"mjs", "text/javascript"},
                     {"wasm", "application/wasm"},
                     {"json", "application/json"},
                     {"css", "text/css"},
                     {"glb", "model/gltf-binary"}}) {
                server.set_file_extension_and_mimetype_mapping(ext, type);
            }
            if (!server.set_mount_point("/web", options.web_root)) {
                throw IoError(options.web_root + ": the viewer directory cannot be served");
            }
            server.set_file_request_handler([](const httplib::Request&, httplib::Response& res) {
                t_request.route = "web";
                res.set_header("Cache-Control", "public, max-age=3600");
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

        server.Get("/health", [this](const httplib::Request&, httplib::Response& res) {
            t_request.route = "health";
            res.set_header("Cache-Control", kNoStore);
            res.set_content("{\"status\":\"ok\"}\n", "application/json");
        });

        server.Get("/metrics", [this](const httplib::Request&, httplib::Response& res) {
            t_request.route = "metrics";
            res.set_header("Cache-Control", kNoStore);
            res.set_content(metrics.render(), "text/plain; version=0.0.4; charset=utf-8");
        });

        server.Get("/layers", [this](const httplib::Request& req, httplib::Response& res) {
            t_request.route = "layers";
            Blob blob;
            blob.bytes = layers_json();
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
                                 kDocumentCacheControl);
                       if (json && res.status == 200) {
                           res.set_header("Vary", "Accept-Encoding");
                       }
                   });
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
        if (z > tiler::kMaxZoom) {
            throw InputError("zoom " + std::to_string(z) + " is beyond the largest supported, " +
                             std::to_string(tiler::kMaxZoom));
        }
        const tiler::Format format =
            req.matches[5].str() == "glb" ? tiler::Format::Glb : tiler::Format::Drc;
        tiler::EpsChoice eps;
        if (req.has_param("eps")) {
            std::int64_t level = 0;
            if (!parse_index(req.get_param_value("eps"), 3, level)) {
                throw InputError("eps must be the index of one of the layer's eps_levels (0, 1, "
                                 "...); see /layers");
            }
            eps.level = static_cast<int>(level);
        }
        const auto blob = tiles.tile(layer, tiler::TileId{static_cast<int>(z), x, y}, format, eps);
        if (!blob) {
            res.set_header("Retry-After", std::to_string(kRetryAfterSeconds));
            send_error(res, 503, "the server is busy generating tiles; retry shortly");
            return;
        }
        // The body is copied (set_content), not streamed with set_content_provider: cpp-httplib
        // 0.11.4 aborts content providers once stop() is called, which would cut off the
        // responses in flight during a graceful shutdown.
        send_blob(req, res, *blob, tiler::media_type(format), kTileCacheControl);
    }
};

HttpServer::HttpServer(TileService& tiles, Metrics& metrics, const HttpOptions& options)
    : impl_(std::make_unique<Impl>(tiles, metrics, options)) {}

HttpServer::~HttpServer() = default;

int HttpServer::bind() {
    Impl& s = *impl_;
    if (s.options.port == 0) {
        s.port = s.server.bind_to_any_port(s.options.host);
        if (s.port <= 0) {
            throw IoError("cannot listen on " + s.options.host +
                          "; check the host name or address");
        }
    } else {
        if (!s.server.bind_to_port(s.options.host, s.options.port)) {
            throw IoError("cannot listen on " + s.options.host + ":" +
                          std::to_string(s.options.port) +
                          "; is another server using the port? pick one with --port");
        }
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
}

void HttpServer::stop() {
    std::lock_guard<std::mutex> lock(impl_->stop_mutex);
    impl_->stop_requested = true;
    impl_->server.stop();
}

bool HttpServer::running() const {
    return impl_->server.is_running();
}

} // namespace tb::server
