// The HTTP server against hostile and overloading clients, over real loopback sockets: idle
// and slow connections, malformed framing, oversized heads, pipelining, a full generation
// queue, a port already in use, links out of the viewer's directory, content codings.
#include "server/request_head.hpp"
#include "server_fixture.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <doctest/doctest.h>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace {

using namespace tb;
using Clock = std::chrono::steady_clock;

struct Fixture {
    test::TempDir dir;
    std::shared_ptr<const tiler::Layer> layer;
    Fixture() {
        log::set_level(log::Level::Warn);
        test::write_dem(dir / "hills.asc");
        layer = tiler::Layer::open(test::test_layer_options(dir / "hills.asc", "hills"));
    }
    server::ServedLayer served() const { return {layer, {tiler::Format::Glb}, nullptr}; }
    std::string some_tile() const {
        const auto r = layer->tiles_at(layer->max_zoom());
        return "/hills/" + std::to_string(r.z) + "/" + std::to_string(r.x0) + "/" +
               std::to_string(r.y0) + ".glb";
    }
};

Fixture& fixture() {
    static Fixture f;
    return f;
}

// A raw TCP connection to the server: bytes exactly as written, no client-side framing.
struct Raw {
    int fd = -1;
    explicit Raw(int port) : fd(test::connect_loopback(port)) {}
    ~Raw() {
        if (fd >= 0) {
            close(fd);
        }
    }
    Raw(const Raw&) = delete;
    Raw& operator=(const Raw&) = delete;
    Raw(Raw&& o) noexcept : fd(o.fd) { o.fd = -1; }

    void send_all(const std::string& bytes) const {
        std::size_t off = 0;
        while (off < bytes.size()) {
            const ssize_t n = ::send(fd, bytes.data() + off, bytes.size() - off, MSG_NOSIGNAL);
            if (n <= 0) {
                return; // the server may close early on a bad request; that is tested by reading
            }
            off += static_cast<std::size_t>(n);
        }
    }
    // Everything until the server closes, or until `timeout` passes; `closed` says which.
    std::string read_until_close(std::chrono::milliseconds timeout, bool& closed) const {
        std::string out;
        closed = false;
        const auto end = Clock::now() + timeout;
        char buf[65536];
        while (Clock::now() < end) {
            pollfd p{fd, POLLIN, 0};
            const auto left =
                std::chrono::duration_cast<std::chrono::milliseconds>(end - Clock::now());
            if (poll(&p, 1, static_cast<int>(std::max<long long>(1, left.count()))) <= 0) {
                continue;
            }
            const ssize_t n = recv(fd, buf, sizeof buf, 0);
            if (n <= 0) {
                closed = true;
                break;
            }
            out.append(buf, static_cast<std::size_t>(n));
        }
        return out;
    }
};

int status_of(const std::string& response) {
    if (response.rfind("HTTP/1.1 ", 0) != 0 || response.size() < 12) {
        return -1;
    }
    return std::stoi(response.substr(9, 3));
}

// Splits a stream of responses (each with a Content-Length; HEAD responses have no body) into
// status codes, in order.
std::vector<int> split_responses(std::string stream, const std::vector<bool>& head) {
    std::vector<int> statuses;
    for (std::size_t i = 0; !stream.empty(); ++i) {
        const auto end = stream.find("\r\n\r\n");
        if (end == std::string::npos) {
            break;
        }
        const std::string header = stream.substr(0, end + 4);
        statuses.push_back(status_of(header));
        std::size_t length = 0;
        const auto cl = header.find("Content-Length: ");
        if (cl != std::string::npos) {
            length = std::stoul(header.substr(cl + 16));
        }
        if (i < head.size() && head[i]) {
            length = 0;
        }
        stream.erase(0, std::min(stream.size(), end + 4 + length));
    }
    return statuses;
}

double labelled_metric(int port, const std::string& sample) {
    httplib::Client c("127.0.0.1", port);
    auto res = c.Get("/metrics");
    if (!res) {
        return -2;
    }
    const auto at = res->body.find(sample + " ");
    return at == std::string::npos ? -1 : std::stod(res->body.substr(at + sample.size() + 1));
}

// Milliseconds for one GET on `c`, or -1 if it failed or was not 200.
double timed_get(httplib::Client& c, const std::string& path) {
    const auto start = Clock::now();
    auto res = c.Get(path);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    return res && res->status == 200 ? ms : -1;
}

double percentile(std::vector<double> v, double p) {
    std::sort(v.begin(), v.end());
    return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

} // namespace

TEST_CASE("400 idle and slow connections leave /health and cached tiles answering fast") {
    auto& f = fixture();
    server::HttpOptions http;
    http.limits.head_timeout = std::chrono::milliseconds(1500);
    http.limits.idle_timeout = std::chrono::milliseconds(20000);
    test::RunningServer s({f.served()}, {}, http);
    auto c = s.client();
    REQUIRE(timed_get(c, f.some_tile()) >= 0); // now cached

    // 300 connections that send nothing, and 100 that send a request head slowly.
    std::vector<Raw> idle, slow;
    for (int i = 0; i < 300; ++i) {
        idle.emplace_back(s.port);
    }
    for (int i = 0; i < 100; ++i) {
        slow.emplace_back(s.port);
        slow.back().send_all("GET /health HTTP/1.1\r\n");
    }
    for (int i = 0; i < 500 && test::metric(s.port, "tb_http_connections") < 401; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    CHECK(test::metric(s.port, "tb_http_connections") >= 401); // 400 + the metrics request

    std::vector<double> health, tile;
    for (int round = 0; round < 10; ++round) {
        for (auto& r : slow) {
            r.send_all("X-Slow: " + std::to_string(round) + "\r\n");
        }
        for (int i = 0; i < 5; ++i) {
            health.push_back(timed_get(c, "/health"));
            tile.push_back(timed_get(c, f.some_tile()));
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    CHECK(*std::min_element(health.begin(), health.end()) >= 0);
    CHECK(*std::min_element(tile.begin(), tile.end()) >= 0);
    const double health_p99 = percentile(health, 0.99), tile_p99 = percentile(tile, 0.99);
    MESSAGE("with 400 idle/slow connections open: /health p99 "
            << health_p99 << " ms, cached tile p99 " << tile_p99 << " ms");
    // Generous bounds for a shared machine; unhardened, these requests wait for seconds.
    CHECK(health_p99 < 250);
    CHECK(tile_p99 < 250);

    // The slow heads run out of time: 408, then the connection is closed.
    bool closed = false;
    const std::string answer = slow.front().read_until_close(std::chrono::seconds(5), closed);
    CHECK(status_of(answer) == 408);
    CHECK(closed);
    CHECK(test::metric(s.port, "tb_http_timeouts_total") >= 1);
}

TEST_CASE("malformed framing gets 400 (or 501/505) and the connection is closed") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    const std::string host = "Host: x\r\n";
    const std::vector<std::pair<std::string, int>> cases = {
        {"GET /health HTTP/1.1\r\n" + host + "Content-Length: 1\r\nContent-Length: 1\r\n\r\nx",
         400},
        {"GET /health HTTP/1.1\r\n" + host + "Content-Length: 1\r\nContent-Length: 2\r\n\r\nxy",
         400},
        {"GET /health HTTP/1.1\r\n" + host + "Content-Length: -1\r\n\r\n", 400},
        {"GET /health HTTP/1.1\r\n" + host + "Content-Length: +1\r\n\r\nx", 400},
        {"GET /health HTTP/1.1\r\n" + host + "Content-Length: 1,1\r\n\r\nx", 400},
        {"GET /health HTTP/1.1\r\n" + host + "Content-Length: 0x10\r\n\r\n", 400},
        {"GET /health HTTP/1.1\r\n" + host + "Content-Length: 18446744073709551617\r\n\r\n", 413},
        {"GET /health HTTP/1.1\r\n" + host + "Content-Length: 9999999\r\n\r\n", 413},
        {"GET /health HTTP/1.1\r\n" + host + "Transfer-Encoding: chunked\r\n\r\n0\r\n\r\n", 501},
        {"GET /health HTTP/1.1\r\n" + host +
             "Content-Length: 5\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n",
         400},
        {"GET /health HTTP/1.1\nHost: x\n\n", 400},                        // bare LF
        {"GET /health HTTP/1.1\r\n\r\n", 400},                             // no Host
        {"GET /health HTTP/1.1\r\n" + host + host + "\r\n", 400},          // two Hosts
        {"GET /health HTTP/1.1\r\n" + host + "X-A: 1\r\n b\r\n\r\n", 400}, // obs-fold
        {"GET /health HTTP/1.1\r\n" + host + "X-A : 1\r\n\r\n", 400},      // space before ':'
        {"GET  /health HTTP/1.1\r\n" + host + "\r\n", 400},
        {"GET /health HTTP/2.0\r\n" + host + "\r\n", 505},
        {"GET /he\x01lth HTTP/1.1\r\n" + host + "\r\n", 400},
        {std::string("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\r\n\r\n", 15), 400}, // TLS
    };
    for (const auto& [request, status] : cases) {
        INFO(request.substr(0, 80));
        Raw r(s.port);
        r.send_all(request + "GET /health HTTP/1.1\r\nHost: x\r\n\r\n");
        bool closed = false;
        const std::string answer = r.read_until_close(std::chrono::seconds(5), closed);
        CHECK(status_of(answer) == status);
        CHECK(answer.find("Connection: close") != std::string::npos);
        CHECK(answer.find("{\"error\":") != std::string::npos);
        CHECK(closed);
        // Exactly one response: the request smuggled behind the bad one is never answered.
        CHECK(answer.find("\nHTTP/1.1 ") == std::string::npos);
    }
    auto health = s.client().Get("/health");
    REQUIRE(health);
    CHECK(health->status == 200);
}

TEST_CASE("oversized request heads get 414 or 431 and the connection is closed") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    const std::vector<std::pair<std::string, int>> cases = {
        {"GET /health HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(40 * 1024, 'a') + "\r\n\r\n",
         431},
        {"GET /" + std::string(40 * 1024, 'a') + " HTTP/1.1\r\nHost: x\r\n\r\n", 414},
        {[] {
             std::string many = "GET /health HTTP/1.1\r\nHost: x\r\n";
             for (int i = 0; i < 150; ++i) {
                 many += "X-" + std::to_string(i) + ": 1\r\n";
             }
             return many + "\r\n";
         }(),
         431},
    };
    for (const auto& [request, status] : cases) {
        INFO(request.substr(0, 60));
        Raw r(s.port);
        r.send_all(request);
        bool closed = false;
        const std::string answer = r.read_until_close(std::chrono::seconds(5), closed);
        CHECK(status_of(answer) == status);
        CHECK(closed);
    }
    // A client that keeps sending headers gets no further than the limit: it is cut off, and
    // the server's memory is not filled with them.
    Raw flood(s.port);
    flood.send_all("GET /health HTTP/1.1\r\nHost: x\r\n");
    std::string line = "X-Flood: " + std::string(100, 'f') + "\r\n";
    std::string chunk;
    for (int i = 0; i < 100; ++i) {
        chunk += line;
    }
    for (int i = 0; i < 100; ++i) {
        flood.send_all(chunk); // stops quietly once the server has closed
    }
    bool closed = false;
    const std::string answer = flood.read_until_close(std::chrono::seconds(5), closed);
    CHECK(status_of(answer) == 431);
    CHECK(closed);
}

TEST_CASE("pipelined requests are all answered, in order") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    const std::vector<std::pair<std::string, int>> requests = {
        {"GET /health", 200},
        {"GET /layers", 200},
        {"GET " + f.some_tile(), 200},
        {"GET /nope/tileset.json", 404},
        {"HEAD /health", 200},
        {"GET /hills/tileset.json", 200},
        {"GET /hills/99/1/1.glb", 400},
        {"GET /metrics", 200},
        {"OPTIONS /health", 204},
        {"GET " + f.some_tile(), 200},
        {"GET /health", 200},
    };
    std::string bytes;
    std::vector<bool> head;
    for (std::size_t i = 0; i < requests.size(); ++i) {
        const bool last = i + 1 == requests.size();
        bytes += requests[i].first + " HTTP/1.1\r\nHost: x\r\n" +
                 (last ? "Connection: close\r\n" : "") + "\r\n";
        head.push_back(requests[i].first.rfind("HEAD", 0) == 0);
    }
    Raw r(s.port);
    r.send_all(bytes); // all eleven at once, in one write
    bool closed = false;
    const std::string answer = r.read_until_close(std::chrono::seconds(20), closed);
    CHECK(closed);
    const auto statuses = split_responses(answer, head);
    REQUIRE(statuses.size() == requests.size());
    for (std::size_t i = 0; i < requests.size(); ++i) {
        INFO(requests[i].first);
        CHECK(statuses[i] == requests[i].second);
    }
}

TEST_CASE("past the queue limit tile requests get 503 with Retry-After at once") {
    auto& f = fixture();
    // Bigger tiles than the other tests: each generation takes long enough to fill the queue.
    auto options = test::test_layer_options(f.dir / "hills.asc", "hills");
    options.tile_size = 256;
    const server::ServedLayer slow{
        tiler::Layer::open(options), {tiler::Format::Glb, tiler::Format::Drc}, nullptr};
    server::TileServiceOptions tiles;
    tiles.threads = 1;
    tiles.queue_limit = 2;
    test::RunningServer s({slow}, tiles);
    CHECK(s.tiles->max_waiting() == 6); // 2 x (threads + queue_limit)

    std::vector<std::string> urls;
    for (int z = slow.layer->min_zoom(); z <= slow.layer->max_zoom(); ++z) {
        const auto r = slow.layer->tiles_at(z);
        for (auto y = r.y0; y <= r.y1; ++y) {
            for (auto x = r.x0; x <= r.x1; ++x) {
                for (const char* q : {"", "?eps=0", "?eps=1"}) {
                    for (const char* ext : {".glb", ".drc"}) {
                        urls.push_back("/hills/" + std::to_string(z) + "/" + std::to_string(x) +
                                       "/" + std::to_string(y) + ext + q);
                    }
                }
            }
        }
    }
    REQUIRE(urls.size() >= 24);
    std::mutex mutex;
    int ok = 0, busy = 0, other = 0;
    bool retry_after = true;
    double slowest_busy_ms = 0;
    std::vector<double> health_ms;
    std::atomic<bool> burst_done{false};
    std::thread prober([&] {
        auto c = s.client();
        while (!burst_done) {
            const double ms = timed_get(c, "/health");
            std::lock_guard<std::mutex> lock(mutex);
            health_ms.push_back(ms);
        }
    });
    std::vector<std::thread> threads;
    for (const auto& url : urls) {
        threads.emplace_back([&, url] {
            auto c = s.client();
            const auto start = Clock::now();
            auto res = c.Get(url);
            const double ms =
                std::chrono::duration<double, std::milli>(Clock::now() - start).count();
            std::lock_guard<std::mutex> lock(mutex);
            if (res && res->status == 200) {
                ++ok;
            } else if (res && res->status == 503) {
                ++busy;
                slowest_busy_ms = std::max(slowest_busy_ms, ms);
                retry_after = retry_after && res->get_header_value("Retry-After") == "1";
            } else {
                ++other;
            }
        });
    }
    for (auto& t : threads) {
        t.join();
    }
    burst_done = true;
    prober.join();
    MESSAGE(urls.size() << " cold requests: " << ok << " x 200, " << busy << " x 503 (slowest 503 "
                        << slowest_busy_ms << " ms), /health p99 " << percentile(health_ms, 0.99)
                        << " ms over " << health_ms.size());
    CHECK(other == 0);
    CHECK(ok >= 3);
    CHECK(busy >= static_cast<int>(urls.size()) / 2);
    CHECK(retry_after);
    CHECK(slowest_busy_ms < 500); // refused at once, not after waiting for a generation
    CHECK(*std::min_element(health_ms.begin(), health_ms.end()) >= 0);
    CHECK(percentile(health_ms, 0.99) < 250);
    CHECK(test::metric(s.port, "tb_queue_rejections_total") == busy);
}

TEST_CASE("documents are compressed once per ETag, in the coding the client accepts") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    auto c = s.client();
    c.set_decompress(false);
    const auto plain = c.Get("/hills/tileset.json");
    REQUIRE(plain);
    REQUIRE(plain->status == 200);
    REQUIRE(plain->body.size() >= 256);
    const std::vector<std::pair<std::string, std::string>> cases = {
        {"br", "br"},
        {"gzip, deflate, br", "br"},
        {"br;q=0, gzip", "gzip"},
        {"br;q=0", ""},
        {"gzip;q=0, br;q=0.5", "br"},
        {"gzip;q=0, br;q=0", ""},
        {"gzip;q=1.0, br;q=0.9", "gzip"},
        {"*;q=0.5, br;q=0", "gzip"},
        {"identity", ""},
        {"BR", "br"},
        {"br;q=bogus, gzip", "gzip"},
    };
    std::map<std::string, std::string> bodies;
    for (const auto& [accept, coding] : cases) {
        INFO(accept);
        auto res = c.Get("/hills/tileset.json", {{"Accept-Encoding", accept}});
        REQUIRE(res);
        CHECK(res->status == 200);
        CHECK(res->get_header_value("Content-Encoding") == coding);
        CHECK(res->get_header_value("Vary") == "Accept-Encoding");
        if (coding.empty()) {
            CHECK(res->body == plain->body);
        } else {
            // Every response in one coding is the same bytes (the one compressed copy).
            auto [it, fresh] = bodies.emplace(coding, res->body);
            CHECK(it->second == res->body);
            CHECK(res->body != plain->body);
        }
    }
    CHECK(labelled_metric(s.port, "tb_compressions_total{coding=\"br\"}") == 1);
    CHECK(labelled_metric(s.port, "tb_compressions_total{coding=\"gzip\"}") == 1);
    // And they decode to the document.
    auto decoding = s.client();
    for (const char* coding : {"br", "gzip"}) {
        auto res = decoding.Get("/hills/tileset.json", {{"Accept-Encoding", coding}});
        REQUIRE(res);
        CHECK(res->body == plain->body);
    }
}

TEST_CASE("nothing outside the viewer's directory is served, whatever links it holds") {
    auto& f = fixture();
    test::TempDir web, modules, outside;
    test::write_file(web / "index.html", "<!doctype html><title>viewer</title>");
    test::write_file(web / "app.js", "console.log('app');");
    test::write_file(modules / "lib.js", "export const lib = 1;");
    test::write_file(outside / "secret.txt", "the content of a file outside");
    namespace fs = std::filesystem;
    fs::create_directories(web.path / "sub");
    test::write_file(web / "sub/page.css", "body{}");
    fs::create_symlink(web.path / "app.js", web.path / "alias.js"); // stays inside: fine
    fs::create_symlink(modules.path, web.path / "node_modules");    // the shared install
    fs::create_symlink("/etc/passwd", web.path / "passwd");
    fs::create_symlink("/etc", web.path / "etc");
    fs::create_symlink(outside.path / "secret.txt", web.path / "secret.txt");
    fs::create_symlink(outside.path, web.path / "sub/out");
    fs::create_symlink("../../" + outside.path.filename().string() + "/secret.txt",
                       web.path / "sub/relative.txt");
    server::HttpOptions http;
    http.web_root = web.path.string();
    test::RunningServer s({f.served()}, {}, http);
    auto c = s.client();
    const std::vector<std::pair<std::string, int>> cases = {
        {"/web/app.js", 200},
        {"/web/alias.js", 200},
        {"/web/sub/page.css", 200},
        {"/web/node_modules/lib.js", 200},
        {"/web/", 200},
        {"/web/passwd", 404},
        {"/web/etc/passwd", 404},
        {"/web/secret.txt", 404},
        {"/web/sub/out/secret.txt", 404},
        {"/web/sub/relative.txt", 404},
        {"/web/node_modules/../passwd", 400},
        {"/web/sub/..%2f..%2fpasswd", 400},
        {"/web/missing.js", 404},
    };
    for (const auto& [url, status] : cases) {
        INFO(url);
        auto res = c.Get(url);
        REQUIRE(res);
        CHECK(res->status == status);
        CHECK(res->body.find("root:") == std::string::npos);
        CHECK(res->body.find("the content of a file outside") == std::string::npos);
    }
    auto js = c.Get("/web/app.js");
    REQUIRE(js);
    CHECK(js->get_header_value("Content-Type") == "text/javascript");
    CHECK(js->body == "console.log('app');");
}

TEST_CASE("terrabound serve on a port in use exits 2 with a clear message") {
    test::TempDir dir;
    test::write_dem(dir / "hills.asc", 65);
    // The port is held the way an earlier terrabound (or another server) would hold it, with
    // SO_REUSEPORT set, so a server that also sets it would start and share the port.
    const int holder = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    REQUIRE(holder >= 0);
    const int yes = 1;
    setsockopt(holder, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    setsockopt(holder, SOL_SOCKET, SO_REUSEPORT, &yes, sizeof yes);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    REQUIRE(bind(holder, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0);
    REQUIRE(listen(holder, 16) == 0);
    socklen_t len = sizeof addr;
    getsockname(holder, reinterpret_cast<sockaddr*>(&addr), &len);
    const std::string port = std::to_string(ntohs(addr.sin_port));

    const std::string log = dir / "serve.log";
    const pid_t pid = fork();
    REQUIRE(pid >= 0);
    if (pid == 0) {
        const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        dup2(fd, 2);
        const std::string dem = dir / "hills.asc";
        execl(TB_BINARY,
              TB_BINARY,
              "serve",
              dem.c_str(),
              "--port",
              port.c_str(),
              "--web",
              "none",
              static_cast<char*>(nullptr));
        _exit(127);
    }
    int status = 0;
    for (int i = 0; i < 3000 && waitpid(pid, &status, WNOHANG) == 0; ++i) {
        usleep(10000);
    }
    if (waitpid(pid, &status, WNOHANG) == 0) {
        kill(pid, SIGKILL);
        waitpid(pid, &status, 0);
        FAIL("terrabound serve kept running on a port in use: " << test::read_file(log));
    }
    close(holder);
    const std::string text = test::read_file(log);
    INFO(text);
    CHECK(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 2);
    CHECK(text.find("terrabound: cannot listen on 127.0.0.1:" + port + ": the port is in use") !=
          std::string::npos);
    CHECK(text.find("serving http") == std::string::npos);
}

TEST_CASE("request heads are framed exactly: where they end and how long the body is") {
    const server::HeadLimits limits;
    using State = server::RequestHead::State;
    const auto h1 = server::check_request_head("GET / HTTP/1.1\r\nHost: a\r\n\r\nGET", limits);
    CHECK(h1.state == State::Complete);
    CHECK(h1.head_bytes == 27);
    CHECK(h1.body_bytes == 0);
    const auto h2 = server::check_request_head(
        "POST /x HTTP/1.1\r\nhost: a\r\ncontent-length: 12\r\n\r\n", limits);
    CHECK(h2.state == State::Complete);
    CHECK(h2.body_bytes == 12);
    CHECK(server::check_request_head("GET / HTTP/1.1\r\nHost: a\r\n", limits).state ==
          State::Incomplete);
    CHECK(server::check_request_head("GET / HTTP/1.0\r\n\r\n", limits).state == State::Complete);
    CHECK(server::check_request_head("GET / HTTP/1.1\r", limits).state == State::Incomplete);
}

TEST_CASE("max_connections holds for every connection loop together, and a closed connection "
          "frees its slot") {
    auto& f = fixture();
    server::HttpOptions options;
    options.limits.max_connections = 6;
    test::RunningServer s({f.served()}, {}, options);
    const std::string health = "GET /health HTTP/1.1\r\nHost: x\r\n\r\n";
    // Six connections, each known to be open on its loop (the loops take them in turn).
    std::vector<std::unique_ptr<test::KeepAliveConn>> open;
    for (int i = 0; i < 6; ++i) {
        open.push_back(std::make_unique<test::KeepAliveConn>(s.port));
        INFO("connection ", i);
        REQUIRE(open.back()->send_all(health));
        REQUIRE(status_of(open.back()->response(false)) == 200);
    }
    // A seventh is refused, whichever loop it goes to.
    for (int k = 0; k < 3; ++k) {
        Raw extra(s.port);
        bool closed = false;
        const std::string answer = extra.read_until_close(std::chrono::seconds(10), closed);
        INFO(answer);
        CHECK(status_of(answer) == 503);
        CHECK(answer.find("too many connections") != std::string::npos);
        CHECK(closed);
    }
    // The six still answer.
    for (auto& c : open) {
        REQUIRE(c->send_all(health));
        CHECK(status_of(c->response(false)) == 200);
    }
    // Closing one frees a slot (once the server has seen the close).
    open.erase(open.begin());
    bool admitted = false;
    for (int attempt = 0; attempt < 250 && !admitted; ++attempt) {
        test::KeepAliveConn again(s.port);
        admitted = again.send_all(health) && status_of(again.response(false)) == 200;
        if (!admitted) {
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    }
    CHECK(admitted);
}
