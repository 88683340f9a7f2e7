#pragma once
// The HTTP front of `terrabound serve` (cpp-httplib; not visible in this header). Routes:
//   GET /                               the 3D viewer (web_root/index.html), or a landing page
//   GET /web/{path}                     the viewer's files under web_root (CesiumJS, three.js)
//   GET /layers                         the layers as JSON
//   GET /health                         {"status":"ok"}
//   GET /metrics                        Prometheus text
//   GET /{layer}/{z}/{x}/{y}.{glb|drc}  a tile; ?eps=K picks the layer's eps_levels[K]
//   GET /{layer}/{document path}        tileset.json, subtrees, ... (whatever the layer has)
// HEAD works wherever GET does; OPTIONS answers CORS preflights.
#include "server/metrics.hpp"
#include "server/tile_service.hpp"

#include <memory>
#include <string>
#include <vector>

namespace tb::server {

struct HttpOptions {
    std::string host = "127.0.0.1";
    int port = 8080; // 0: any free port (see bind())
    std::vector<std::string> cors_origins = {"*"};
    int http_threads = 16; // connection-handling threads
    std::string web_root;  // the viewer's directory (index.html, node_modules/); empty: none
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
    // Throws IoError when the address cannot be bound.
    int bind();
    // Serves until stop(); returns after in-flight requests have finished.
    void run();
    // Stops accepting connections; safe from any thread, and before or during run().
    void stop();
    // True once run() accepts connections.
    bool running() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace tb::server
