#include "server/metrics.hpp"

#include <sstream>

namespace tb::server {

void Metrics::record_request(const std::string& route, int status, double seconds) {
    std::lock_guard<std::mutex> lock(mutex_);
    ++requests_[{route, status}];
    Histogram& h = latency_[route];
    std::size_t b = 0;
    while (b < kBuckets.size() && seconds > kBuckets[b]) {
        ++b;
    }
    if (b < kBuckets.size()) {
        ++h.buckets[b];
    }
    ++h.count;
    h.sum += seconds;
}

std::string Metrics::render() const {
    std::ostringstream out;
    out.precision(9);
    const auto counter = [&](const char* name, const char* help, std::uint64_t value) {
        out << "# HELP " << name << ' ' << help << "\n# TYPE " << name << " counter\n"
            << name << ' ' << value << '\n';
    };
    const auto gauge = [&](const char* name, const char* help, double value) {
        out << "# HELP " << name << ' ' << help << "\n# TYPE " << name << " gauge\n"
            << name << ' ' << value << '\n';
    };
    {
        std::lock_guard<std::mutex> lock(mutex_);
        out << "# HELP tb_http_requests_total HTTP requests by route and status.\n"
               "# TYPE tb_http_requests_total counter\n";
        for (const auto& [key, n] : requests_) {
            out << "tb_http_requests_total{route=\"" << key.first << "\",status=\"" << key.second
                << "\"} " << n << '\n';
        }
        out << "# HELP tb_http_request_duration_seconds HTTP request latency by route.\n"
               "# TYPE tb_http_request_duration_seconds histogram\n";
        for (const auto& [route, h] : latency_) {
            std::uint64_t cumulative = 0;
            for (std::size_t b = 0; b < kBuckets.size(); ++b) {
                cumulative += h.buckets[b];
                out << "tb_http_request_duration_seconds_bucket{route=\"" << route << "\",le=\""
                    << kBuckets[b] << "\"} " << cumulative << '\n';
            }
            out << "tb_http_request_duration_seconds_bucket{route=\"" << route << "\",le=\"+Inf\"} "
                << h.count << '\n';
            out << "tb_http_request_duration_seconds_sum{route=\"" << route << "\"} " << h.sum
                << '\n';
            out << "tb_http_request_duration_seconds_count{route=\"" << route << "\"} " << h.count
                << '\n';
        }
    }
    counter("tb_cache_hits_total", "Tile and document requests served from memory.", cache_hits);
    counter("tb_cache_misses_total", "Tile and document requests not in memory.", cache_misses);
    counter("tb_store_hits_total", "Tiles read from a layer's store.", store_hits);
    counter("tb_tiles_generated_total", "Tiles meshed and encoded on demand.", tiles_generated);
    counter("tb_tiles_empty_total", "On-demand generations that found no data (404).", tiles_empty);
    out << "# HELP tb_tile_generation_seconds_total Time spent generating tiles.\n"
           "# TYPE tb_tile_generation_seconds_total counter\n"
        << "tb_tile_generation_seconds_total " << static_cast<double>(generation_micros) * 1e-6
        << '\n';
    counter("tb_single_flight_waits_total",
            "Requests that waited for a generation already running for the same tile.",
            single_flight_waits);
    counter("tb_queue_rejections_total",
            "Requests answered 503 because the queue was full.",
            queue_rejections);
    counter("tb_deadline_expiries_total",
            "Tile requests answered 503 because their tile was not ready by their deadline.",
            deadline_expiries);
    counter("tb_generations_cancelled_total",
            "Generations stopped at a checkpoint because every request for them had given up.",
            generations_cancelled);
    counter("tb_store_write_failures_total",
            "Generated tiles that could not be stored.",
            store_write_failures);
    counter("tb_http_connections_total", "TCP connections accepted.", accepted_connections);
    counter("tb_http_connections_refused_total",
            "Connections answered 503 and closed because too many were open.",
            refused_connections);
    counter("tb_http_timeouts_total",
            "Connections closed because a request head, body or response stalled.",
            request_timeouts);
    counter("tb_http_quick_answers_total",
            "Requests for tiles in memory answered by the connection loop itself, without a "
            "worker or cpp-httplib.",
            quick_answers);
    out << "# HELP tb_compressions_total Documents compressed, by coding (once per ETag while "
           "cached).\n# TYPE tb_compressions_total counter\n"
        << "tb_compressions_total{coding=\"gzip\"} " << gzip_compressions << '\n'
        << "tb_compressions_total{coding=\"br\"} " << brotli_compressions << '\n';
    gauge("tb_http_connections", "Open HTTP connections.", static_cast<double>(open_connections));
    gauge("tb_http_in_flight_requests",
          "HTTP requests being handled.",
          static_cast<double>(in_flight_requests));
    gauge("tb_generations_in_flight",
          "Tile generations running.",
          static_cast<double>(in_flight_generations));
    gauge("tb_generations_queued",
          "Tile generations waiting for a thread.",
          static_cast<double>(queued_generations));
    gauge("tb_cache_bytes", "Bytes held by the memory cache.", static_cast<double>(cache_bytes));
    gauge("tb_cache_entries",
          "Entries held by the memory cache.",
          static_cast<double>(cache_entries));
    return out.str();
}

} // namespace tb::server
