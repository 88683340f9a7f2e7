// libFuzzer harness: raw request bytes through the server's whole request path without a
// socket: the framing check (check_request_head), then cpp-httplib's parser, the URL checks,
// the router and the handlers (HttpServer::answer), on a real layer of a small generated DEM
// and a viewer directory holding a link out of it. Also Accept-Encoding negotiation.
// A crash, a sanitizer report, a response that is not HTTP/1.1, a 500 (an exception escaped a
// handler), a file from outside the viewer's directory, or a quick-path answer (a tile in
// memory) that differs from the routes' answer to the same bytes is a finding.
#include "server/encoding.hpp"
#include "server/http_server.hpp"
#include "server/request_head.hpp"
#include "tests/server/server_fixture.hpp"
#include "tiler/log.hpp"

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <memory>

namespace {

struct World {
    tb::test::TempDir dir;
    tb::server::Metrics metrics;
    std::unique_ptr<tb::server::TileService> tiles;
    std::unique_ptr<tb::server::HttpServer> http;
    tb::server::HeadLimits limits;

    World() {
        tb::log::set_level(tb::log::Level::Off);
        tb::test::write_dem(dir / "hills.asc", 65);
        auto options = tb::test::test_layer_options(dir / "hills.asc", "hills");
        options.tile_size = 16;
        std::filesystem::create_directories(dir.path / "web");
        tb::test::write_file(dir / "web/index.html", "<!doctype html><title>v</title>");
        tb::test::write_file(dir / "web/app.js", "1;");
        tb::test::write_file(dir / "outside.txt", "OUTSIDE-THE-ROOT");
        std::filesystem::create_symlink(dir.path / "outside.txt", dir.path / "web/out.txt");
        std::vector<tb::server::ServedLayer> layers = {{tb::tiler::Layer::open(options),
                                                        {tb::tiler::Format::Glb,
                                                         tb::tiler::Format::Drc,
                                                         tb::tiler::Format::Terrain,
                                                         tb::tiler::Format::Terrain3d},
                                                        nullptr}};
        tb::server::TileServiceOptions tile_options;
        tile_options.cache_bytes = 8 << 20;
        tiles = std::make_unique<tb::server::TileService>(std::move(layers), tile_options, metrics);
        tb::server::HttpOptions http_options;
        http_options.web_root = dir / "web";
        http_options.http_threads = 2;
        http = std::make_unique<tb::server::HttpServer>(*tiles, metrics, http_options);
    }
};

World* world = nullptr;

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    world = new World; // lives for the whole run
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string_view bytes(reinterpret_cast<const char*>(data), size);
    (void)tb::server::pick_coding(bytes);
    const auto head = tb::server::check_request_head(bytes, world->limits);
    if (head.state == tb::server::RequestHead::State::Bad) {
        if (head.status < 400 || head.status > 505 || head.error.empty()) {
            std::abort();
        }
        return 0;
    }
    if (head.state != tb::server::RequestHead::State::Complete ||
        head.head_bytes + head.body_bytes > bytes.size()) {
        return 0;
    }
    const std::string_view request = bytes.substr(0, head.head_bytes + head.body_bytes);
    const auto quick_before = world->metrics.quick_answers.load();
    const auto reply = world->http->answer(request);
    if (world->metrics.quick_answers.load() != quick_before &&
        world->http->answer(request, false, false).bytes != reply.bytes) {
        std::abort();
    }
    const std::string& out = reply.bytes;
    if (out.rfind("HTTP/1.1 ", 0) != 0 || out.size() < 12) {
        std::abort();
    }
    const int status = std::atoi(out.substr(9, 3).c_str());
    if (status < 100 || status == 500 || status > 599) {
        std::abort();
    }
    // The file outside the root, served as a body (error messages, and CORS headers echoing
    // the request's, may repeat request text).
    const std::size_t body = out.find("\r\n\r\n");
    if (status / 100 == 2 && body != std::string::npos &&
        out.find("OUTSIDE-THE-ROOT", body) != std::string::npos) {
        std::abort();
    }
    return 0;
}
