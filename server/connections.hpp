#pragma once
// The connection loops of the HTTP server: each epoll thread owns the sockets given to it (in
// turn, one loop per core), reads requests without blocking, and hands each complete request
// (head and body, framing checked) to a fixed pool of worker threads they share; responses go
// back to the loop, which writes them out. A request
// the `quick` handler can answer without blocking (a tile already in memory) is answered on the
// loop's thread instead, with no handoff.
//
// So a connection costs a thread only while its request is being answered: idle keep-alive
// connections and clients that send slowly hold a file descriptor and a buffer, nothing more.
// Requests on one connection are answered one at a time, in order (pipelining); the loop reads
// no further while a request is being answered or written, so a client cannot queue up work.
// Deadlines: a request head must arrive within head_timeout of its first byte, its body within
// body_timeout after the head, a response must make progress every write_timeout, and an idle
// connection is closed after idle_timeout.
#include "server/metrics.hpp"
#include "server/request_head.hpp"

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace tb::server {

class ThreadPool;

struct ConnectionLimits {
    HeadLimits head;
    std::chrono::milliseconds head_timeout{10000};
    std::chrono::milliseconds body_timeout{10000};
    std::chrono::milliseconds idle_timeout{5000};
    std::chrono::milliseconds write_timeout{10000};
    std::size_t max_connections = 10000; // past it new connections get 503 and are closed
    int max_requests = 1000;             // per connection, then it is closed
};

struct Peer {
    std::string ip;
    int port = 0;
};

// What a worker makes of one request: the response bytes, and whether to close afterwards.
struct Reply {
    std::string bytes;
    // Sent after `bytes`, not copied: the immutable body of a cached tile. May be null.
    std::shared_ptr<const std::string> body;
    bool close = false;
};

struct ConnectionHandlers {
    // Answers one complete request (its head and body bytes). `last`: the connection closes
    // after this response (say so in it). Runs on a worker thread; must not throw.
    std::function<Reply(std::string_view request, const Peer& peer, bool last)> answer;
    // Tried first, on the loop's thread: fills `reply` and returns true when it can answer the
    // request at once, or returns false to leave it to `answer`. Must never block (no store, no
    // generation), and not throw; may be empty.
    std::function<bool(std::string_view request, const Peer& peer, bool last, Reply& reply)> quick;
    // The response to a request that cannot be framed or did not arrive in time (the
    // connection closes after it). Runs on the loop's thread; must be quick and not throw.
    std::function<std::string(int status, const std::string& why, const Peer& peer)> refuse;
};

class Connections {
public:
    // `loops` connection loops (at least 1), each on its own thread, sharing `workers` worker
    // threads; new connections go to the loops in turn, and max_connections holds for all of
    // them together (when connections race for the last slots, which of them is refused
    // depends on the loops' timing).
    Connections(const ConnectionLimits& limits,
                int workers,
                ConnectionHandlers handlers,
                Metrics& metrics,
                int loops = 1);
    ~Connections(); // drain() and join, if not done yet
    Connections(const Connections&) = delete;
    Connections& operator=(const Connections&) = delete;

    // Takes over an accepted socket (any thread). After drain() began, closes it at once.
    void adopt(int fd);
    // Stops taking requests: closes idle and half-received connections at once, lets every
    // request already complete finish and its response be written, then returns once no
    // connection is left. Safe to call more than once.
    void drain();

private:
    struct Impl;
    std::unique_ptr<ThreadPool> pool_; // outlives the loops' drains (see ~Connections)
    std::vector<std::unique_ptr<Impl>> loops_;
    std::atomic<std::size_t> next_loop_{0};
};

} // namespace tb::server
