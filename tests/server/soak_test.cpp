// A short soak of `terrabound serve` as a child process: for 30 s, client threads ask for cached,
// uncached and bad tiles and documents while the layer's source is replaced under the server
// every few seconds (the watcher reloads it). Every answer is one a client should expect (200,
// 304, 400, 404, or 503 when busy), never another 5xx or a dropped connection; the server
// lives; and its resident memory levels off once its small tile cache has filled.
#include "serve_process.hpp"
#include "server_fixture.hpp"

#include <doctest/doctest.h>

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <thread>

namespace {

using namespace tb;
using Clock = std::chrono::steady_clock;

// The process's resident set, KiB, from /proc (0 when it cannot be read).
long rss_kib(pid_t pid) {
    std::ifstream in("/proc/" + std::to_string(pid) + "/status");
    std::string key;
    long value = 0;
    while (in >> key) {
        if (key == "VmRSS:") {
            in >> value;
            return value;
        }
        in.ignore(1 << 12, '\n');
    }
    return 0;
}

// A request of the mix: the same few tiles (cached after the first time), any tile of the
// pyramid (mostly cold), documents, and bad ones.
std::string pick(std::mt19937& rng) {
    const int kind = static_cast<int>(rng() % 10);
    const auto at = [&rng](int z) {
        const int n = 1 << z; // geodetic: 2n tiles across, n down
        return "/hills/" + std::to_string(z) + "/" +
               std::to_string(static_cast<int>(rng() % (2 * n))) + "/" +
               std::to_string(static_cast<int>(rng() % n));
    };
    switch (kind) {
    case 0:
    case 1:
    case 2:
        return "/hills/8/272/210.glb"; // hot
    case 3:
    case 4:
        return "/hills/8/" + std::to_string(270 + static_cast<int>(rng() % 4)) + "/" +
               std::to_string(208 + static_cast<int>(rng() % 4)) + ".terrain";
    case 5:
        return "/hills/" + std::to_string(5 + static_cast<int>(rng() % 4)) + "/" +
               std::to_string(34 * (1 << static_cast<int>(rng() % 3))) +
               "/26.glb?eps=" + std::to_string(static_cast<int>(rng() % 2));
    case 6:
        return rng() % 2 ? "/hills/tileset.json" : "/hills/layer.json";
    case 7:
        return at(static_cast<int>(rng() % 9)) + ".terrain";
    case 8:
        return rng() % 2 ? "/hills/99/0/0.glb" : "/hills/8/272/210.glb?eps=7";
    default:
        return rng() % 2 ? "/nope/1/2/3.glb" : "/hills/%2e%2e/etc/passwd";
    }
}

} // namespace

TEST_CASE("soak: 30 s of mixed requests while the source is replaced every few seconds: only "
          "expected statuses, no crash, memory levels off") {
    test::TempDir dir;
    test::write_dem(dir / "hills.asc", 257);
    test::write_file(dir / "serve.json", R"({
      "server": {"threads": 2, "cache_mb": 8, "watch_interval_s": 1},
      "layers": [{"name": "hills", "sources": ["hills.asc"], "tile_size": 64, "min_zoom": 5,
                  "max_zoom": 8, "eps_levels": [5, 20]}]})");
    test::Child child;
    const int port = test::start_server(child, {dir / "serve.json"}, dir / "serve.log");

    std::atomic<bool> stop{false};
    std::mutex mutex;
    std::map<int, long> statuses; // status -> count; -1: no answer
    std::vector<std::thread> clients;
    for (int t = 0; t < 6; ++t) {
        clients.emplace_back([&, t] {
            std::mt19937 rng(20261205 + t);
            httplib::Client c("127.0.0.1", port);
            c.set_read_timeout(30);
            std::map<int, long> mine;
            while (!stop) {
                const auto res = c.Get(pick(rng).c_str());
                ++mine[res ? res->status : -1];
            }
            std::lock_guard<std::mutex> lock(mutex);
            for (const auto& [status, n] : mine) {
                statuses[status] += n;
            }
        });
    }
    std::vector<long> rss; // KiB, one a second
    const auto start = Clock::now();
    for (int second = 1; Clock::now() - start < std::chrono::seconds(30); ++second) {
        std::this_thread::sleep_for(std::chrono::seconds(1));
        rss.push_back(rss_kib(child.pid));
        if (second % 4 == 0) { // a new source: 257 and 193 samples in turn
            test::write_dem(dir / "next.asc", second % 8 == 0 ? 257 : 193);
            std::filesystem::rename(dir / "next.asc", dir / "hills.asc");
        }
    }
    stop = true;
    for (auto& c : clients) {
        c.join();
    }
    std::string seen;
    long total = 0;
    for (const auto& [status, n] : statuses) {
        seen += ' ';
        seen += std::to_string(status) + ":" + std::to_string(n);
        total += n;
    }
    MESSAGE("statuses" << seen << "; RSS first/middle/last " << rss.front() << " / "
                       << rss[rss.size() / 2] << " / " << rss.back() << " KiB");
    INFO(test::read_file(dir / "serve.log"));
    CHECK(total > 300);
    for (const auto& [status, n] : statuses) {
        CAPTURE(status);
        CHECK((status == 200 || status == 304 || status == 400 || status == 404 || status == 503));
    }
    CHECK(statuses[200] > total / 4);
    CHECK(test::read_file(dir / "serve.log").find("now serves its new sources") !=
          std::string::npos);
    // Levelled off: the second half's peak within 25 % (and 16 MiB) of the first half's.
    REQUIRE(rss.size() >= 20);
    const long first = *std::max_element(rss.begin(), rss.begin() + rss.size() / 2);
    const long second = *std::max_element(rss.begin() + rss.size() / 2, rss.end());
    CHECK(second <= first + first / 4 + 16 * 1024);
    kill(child.pid, SIGTERM);
    CHECK(child.wait_exit() == 0);
}
