#pragma once
// Server counters, rendered in the Prometheus text exposition format for GET /metrics.
// Every method is thread-safe; the counters are monotonic except the gauges (in_flight_*).
#include <array>
#include <atomic>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <utility>

namespace tb::server {

class Metrics {
public:
    // Upper bounds (seconds) of the latency histogram buckets; +Inf is implicit.
    static constexpr std::array<double, 12> kBuckets = {
        0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5};

    // One finished HTTP request. `route` is a fixed label ("tile", "document", ...).
    void record_request(const std::string& route, int status, double seconds);

    std::atomic<std::uint64_t> cache_hits{0}; // served from the memory LRU
    std::atomic<std::uint64_t> cache_misses{0};
    std::atomic<std::uint64_t> store_hits{0};            // read from a layer's store
    std::atomic<std::uint64_t> tiles_generated{0};       // make_tile calls that returned a tile
    std::atomic<std::uint64_t> tiles_empty{0};           // make_tile calls that found no data
    std::atomic<std::uint64_t> generation_micros{0};     // total time in make_tile
    std::atomic<std::uint64_t> single_flight_waits{0};   // requests that joined a generation
    std::atomic<std::uint64_t> queue_rejections{0};      // 503s for a full generation queue
    std::atomic<std::uint64_t> deadline_expiries{0};     // 503s at the request's deadline
    std::atomic<std::uint64_t> generations_cancelled{0}; // stopped: nobody waited any more
    std::atomic<std::uint64_t> store_write_failures{0};
    std::atomic<std::uint64_t> accepted_connections{0};
    std::atomic<std::uint64_t> refused_connections{0}; // over the connection limit: 503, closed
    std::atomic<std::uint64_t> request_timeouts{0};    // 408s and stalled responses, closed
    std::atomic<std::uint64_t> quick_answers{0};     // cached tiles answered on the connection loop
    std::atomic<std::uint64_t> gzip_compressions{0}; // documents compressed (once per ETag)
    std::atomic<std::uint64_t> brotli_compressions{0};
    std::atomic<std::int64_t> open_connections{0};
    std::atomic<std::int64_t> in_flight_requests{0};
    std::atomic<std::int64_t> in_flight_generations{0}; // running make_tile calls
    std::atomic<std::int64_t> queued_generations{0};    // waiting for a pool thread

    // Values the cache owns, sampled when rendering.
    std::atomic<std::uint64_t> cache_bytes{0};
    std::atomic<std::uint64_t> cache_entries{0};

    std::string render() const;

private:
    struct Histogram {
        std::array<std::uint64_t, kBuckets.size()> buckets{}; // non-cumulative
        std::uint64_t count = 0;
        double sum = 0;
    };
    mutable std::mutex mutex_;
    std::map<std::pair<std::string, int>, std::uint64_t> requests_; // (route, status)
    std::map<std::string, Histogram> latency_;                      // by route
};

} // namespace tb::server
