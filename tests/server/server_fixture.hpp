#pragma once
// Shared helpers of the server tests: temp dirs, a small generated DEM, an in-process server
// on an ephemeral loopback port, and Prometheus metric lookup.
#include "config/config.hpp"
#include "server/http_server.hpp"
#include "server/metrics.hpp"
#include "server/tile_service.hpp"

#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <httplib.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>

namespace tb::test {

namespace fs = std::filesystem;

struct TempDir {
    fs::path path;
    TempDir() {
        std::random_device rd;
        path = fs::temp_directory_path() /
               ("tb_server_test_" + std::to_string(rd()) + "_" + std::to_string(rd()));
        fs::create_directories(path);
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
    std::string operator/(const std::string& name) const { return (path / name).string(); }
};

inline void write_file(const std::string& path, const std::string& text) {
    std::ofstream out(path, std::ios::binary);
    out << text;
}

inline std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

// Writes an ESRI ASCII grid (+ .prj, WGS84) of `n` x `n` cells covering one degree from
// (west, south): hills of a few hundred metres, so meshes have real work to do. GDAL reads it
// as a georeferenced DEM; no GDAL is needed in the test itself.
inline void write_dem(const std::string& path, int n = 257, double west = 11, double south = 57) {
    std::ostringstream s;
    const double cell = 1.0 / (n - 1);
    s << "ncols " << n << "\nnrows " << n << "\nxllcorner " << west - cell / 2 << "\nyllcorner "
      << south - cell / 2 << "\ncellsize " << cell << "\nNODATA_value -9999\n";
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            const double u = i * cell, v = j * cell;
            const double h = 300 + 200 * std::sin(u * 9.1) * std::cos(v * 7.3) +
                             60 * std::sin(u * 31 + v * 17) + 15 * std::cos(u * 83 - v * 61);
            s << static_cast<int>(std::lround(h)) << (i + 1 < n ? " " : "\n");
        }
    }
    write_file(path, s.str());
    const auto dot = path.rfind('.');
    write_file(path.substr(0, dot) + ".prj",
               "GEOGCS[\"GCS_WGS_1984\",DATUM[\"D_WGS_1984\",SPHEROID[\"WGS_1984\",6378137.0,"
               "298.257223563]],PRIMEM[\"Greenwich\",0.0],UNIT[\"Degree\",0.0174532925199433]]");
}

// The layer options the tests use: a small pyramid (zooms 5..8) of 64-sample tiles.
inline tiler::LayerOptions test_layer_options(const std::string& dem, const std::string& name) {
    tiler::LayerOptions o;
    o.name = name;
    o.sources = {dem};
    o.tile_size = 64;
    o.min_zoom = 5;
    o.max_zoom = 8;
    o.eps_levels = {5.0, 20.0};
    return o;
}

// The generated hills DEM as a layer (test_layer_options), and a tile of its max zoom that
// holds data.
struct HillsLayer {
    TempDir dir;
    std::shared_ptr<const tiler::Layer> layer;
    tiler::TileId inside;
    HillsLayer() {
        log::set_level(log::Level::Warn);
        write_dem(dir / "hills.asc");
        layer = tiler::Layer::open(test_layer_options(dir / "hills.asc", "hills"));
        const auto r = layer->tiles_at(layer->max_zoom());
        if (r.empty()) {
            throw std::runtime_error("the hills layer has no tile at its max zoom");
        }
        inside = {layer->max_zoom(), r.x0, r.y0};
    }
};

// A blocking TCP socket connected to 127.0.0.1:port; throws when it cannot connect.
inline int connect_loopback(int port) {
    const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) {
        throw std::runtime_error(std::string("socket: ") + std::strerror(errno));
    }
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<std::uint16_t>(port));
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
        const std::string why = std::strerror(errno);
        close(fd);
        throw std::runtime_error("connect to 127.0.0.1:" + std::to_string(port) + ": " + why);
    }
    return fd;
}

// A raw keep-alive connection that reads whole responses, framed by their Content-Length.
struct KeepAliveConn {
    int fd = -1;
    std::string buffer;

    explicit KeepAliveConn(int port) : fd(connect_loopback(port)) {}
    ~KeepAliveConn() { close(fd); }
    KeepAliveConn(const KeepAliveConn&) = delete;
    KeepAliveConn& operator=(const KeepAliveConn&) = delete;

    bool send_all(const std::string& bytes) const {
        std::size_t off = 0;
        while (off < bytes.size()) {
            const ssize_t n = ::send(fd, bytes.data() + off, bytes.size() - off, MSG_NOSIGNAL);
            if (n <= 0) {
                return false;
            }
            off += static_cast<std::size_t>(n);
        }
        return true;
    }
    // False when the server closed (or sent nothing for a long while: a hang, not a timing).
    bool receive() {
        pollfd p{fd, POLLIN, 0};
        if (poll(&p, 1, 30000) <= 0) {
            return false;
        }
        char chunk[65536];
        const ssize_t n = recv(fd, chunk, sizeof chunk, 0);
        if (n <= 0) {
            return false;
        }
        buffer.append(chunk, static_cast<std::size_t>(n));
        return true;
    }
    // The next response, head and body; `no_body`: the answer to a HEAD. Empty when the
    // connection closed first.
    std::string response(bool no_body) {
        std::size_t end;
        while ((end = buffer.find("\r\n\r\n")) == std::string::npos) {
            if (!receive()) {
                return "";
            }
        }
        const std::string head = buffer.substr(0, end + 4);
        std::size_t length = 0;
        const auto at = head.find("\r\nContent-Length: ");
        if (at != std::string::npos && !no_body) {
            length = std::stoul(head.substr(at + 18));
        }
        while (buffer.size() < end + 4 + length) {
            if (!receive()) {
                return "";
            }
        }
        std::string out = buffer.substr(0, end + 4 + length);
        buffer.erase(0, out.size());
        return out;
    }
    // True once the server has closed the connection with nothing more sent.
    bool closed_by_server() { return buffer.empty() && !receive() && buffer.empty(); }
};

// A TileService and HttpServer running in this process on 127.0.0.1:<ephemeral>.
struct RunningServer {
    server::Metrics metrics;
    std::unique_ptr<server::TileService> tiles;
    std::unique_ptr<server::HttpServer> http;
    std::thread thread;
    int port = 0;

    RunningServer(std::vector<server::ServedLayer> layers,
                  server::TileServiceOptions tile_options = {},
                  server::HttpOptions http_options = {}) {
        tiles = std::make_unique<server::TileService>(std::move(layers), tile_options, metrics);
        http_options.port = 0; // the host is HttpOptions' default, 127.0.0.1, unless given
        http = std::make_unique<server::HttpServer>(*tiles, metrics, http_options);
        port = http->bind();
        thread = std::thread([this] { http->run(); });
        for (int i = 0; i < 500 && !http->running(); ++i) {
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
    }
    ~RunningServer() {
        http->stop();
        thread.join();
    }
    httplib::Client client() const {
        httplib::Client c("127.0.0.1", port);
        c.set_read_timeout(30);
        c.set_url_encode(false);
        return c;
    }
};

// The value of an unlabelled Prometheus sample `name` in `text`, or -1 when absent.
inline double metric(const std::string& text, const std::string& name) {
    std::istringstream in(text);
    std::string line;
    while (std::getline(in, line)) {
        if (line.rfind(name + " ", 0) == 0) {
            return std::stod(line.substr(name.size() + 1));
        }
    }
    return -1;
}

inline double metric(int port, const std::string& name) {
    httplib::Client c("127.0.0.1", port);
    auto res = c.Get("/metrics");
    return res && res->status == 200 ? metric(res->body, name) : -2;
}

} // namespace tb::test
