#pragma once
// The HTTP front of `terrabound serve` (cpp-httplib; not visible in this header). Routes:
//   GET /                               the 3D viewer (web_root/index.html), or a landing page
//   GET /web/{path}                     the viewer's files under web_root (CesiumJS, three.js)
//   GET /layers                         the layers as JSON
//   GET /health                         {"status":"ok"}
//   GET /metrics                        Prometheus text (HttpOptions::metrics says to whom)
//   GET /{layer}/{z}/{x}/{y}.{glb|drc}  a tile; ?eps=K picks the layer's eps_levels[K]
//   GET /{layer}/{document path}        tileset.json, subtrees, ... (whatever the layer has)
// HEAD works wherever GET does; OPTIONS answers CORS preflights.
#include "server/connections.hpp"
#include "server/metrics.hpp"
#include "server/tile_service.hpp"

#include <memory>
#include <string>
#include <vector>

namespace tb::server {

// Who may read GET /metrics.
enum class MetricsAccess {
    Loopback, // requests from this machine only (127.0.0.0/8, ::1, no proxy headers); 403 else
    On,       // anyone who reaches the port
    Off,      // nobody: 404
};

// "loopback", "on" or "off" as a MetricsAccess; InputError naming `what` otherwise.
MetricsAccess parse_metrics_access(const std::string& text, const std::string& what);

struct HttpOptions {
    std::string host = "127.0.0.1";
    int port = 8080; // 0: any free port (see bind())
    std::vector<std::string> cors_origins = {"*"};
    // Worker threads for requests that do not wait for a generation (health, cached tiles,
    // documents, files). The pool gets one more per request TileService lets wait for a
    // generation (TileService::max_waiting), so those can never take all of it. Connections
    // themselves hold no thread (server/connections.hpp).
    int http_threads = 16;
    std::string web_root; // the viewer's directory (index.html, node_modules/); empty: none
    MetricsAccess metrics = MetricsAccess::Loopback;
    ConnectionLimits limits; // timeouts and sizes; max_connections is also capped by the fd limit
};

// Longest request target accepted; longer ones get 414.
inline constexpr std::size_t kMaxUrlLength = 2048;

class HttpServer {
public:
    HttpServer(TileService& tiles, Metrics& metrics, const HttpOptions& options);
    ~HttpServer();
    HttpServer(const HttpServer&) = delete;
    HttpServer& operator=(const HttpServer&) = delete;

    // Binds the listening socket and returns the port (the chosen one when options.port is 0).
    // Throws InputError when the address cannot be bound (port in use, no such address, no
    // permission), naming it and the reason.
    int bind();
    // Serves until stop(); returns after in-flight requests have finished.
    void run();
    // Stops accepting connections; safe from any thread, and before or during run().
    void stop();
    // True once run() accepts connections.
    bool running() const;

    // Answers one complete request, given as its raw bytes (head and body, already framed by
    // check_request_head), exactly as a connection would: a tile in memory by the quick path
    // the connection loop takes, anything else by routing, handlers, error mapping; the whole
    // response in `bytes`. No socket is involved; the fuzz harness calls it directly, and with
    // `quick` false (the routes only) to check that both paths give the same bytes.
    Reply answer(std::string_view request, bool last = false, bool quick = true);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace tb::server
