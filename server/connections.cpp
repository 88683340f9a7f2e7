// The epoll connection loop and its worker pool (see connections.hpp).
#include "server/connections.hpp"
#include "server/thread_pool.hpp"

#include "tiler/log.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <vector>

namespace tb::server {
namespace {

using Clock = std::chrono::steady_clock;

constexpr std::uint64_t kWakeId = 0;      // epoll data of the eventfd
constexpr std::size_t kReadChunk = 16384; // bytes per recv
constexpr auto kSweepEvery = std::chrono::milliseconds(50);
// Requests one connection may have answered in a row before the loop turns to the others.
constexpr int kAnswersPerTurn = 16;

enum class Phase {
    Idle,  // between requests (nothing buffered)
    Head,  // part of a request head received
    Body,  // head complete, body not yet
    Busy,  // a worker is answering the request
    Write, // the response is being written
};

struct Conn {
    int fd = -1;
    Peer peer;
    Phase phase = Phase::Idle;
    Clock::time_point since;                     // start of the phase (Write: last progress)
    std::string in;                              // received, not yet answered
    std::string out;                             // the response (or its head)
    std::shared_ptr<const std::string> out_body; // then this, when not null
    std::size_t out_pos = 0;                     // bytes of out + out_body written
    std::uint32_t events = 0;                    // epoll interest; 0 when not registered
    int served = 0;
    bool peer_done = false;   // the client will send nothing more
    bool close_after = false; // close once the response is written
};

Peer peer_of(int fd) {
    Peer p;
    sockaddr_storage addr{};
    socklen_t len = sizeof addr;
    if (getpeername(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
        return p;
    }
    char text[INET6_ADDRSTRLEN] = {};
    if (addr.ss_family == AF_INET) {
        const auto* a = reinterpret_cast<const sockaddr_in*>(&addr);
        inet_ntop(AF_INET, &a->sin_addr, text, sizeof text);
        p.port = ntohs(a->sin_port);
    } else if (addr.ss_family == AF_INET6) {
        const auto* a = reinterpret_cast<const sockaddr_in6*>(&addr);
        inet_ntop(AF_INET6, &a->sin6_addr, text, sizeof text);
        p.port = ntohs(a->sin6_port);
    }
    p.ip = text;
    return p;
}

} // namespace

struct Connections::Impl {
    ConnectionLimits limits;
    ConnectionHandlers handlers;
    Metrics& metrics;
    // Connections open on every loop together, against limits.max_connections.
    std::shared_ptr<std::atomic<std::size_t>> open;
    int epoll_fd = -1;
    int wake_fd = -1;

    // Shared with other threads, under `mutex`.
    std::mutex mutex;
    std::vector<int> adopted;
    std::vector<std::pair<std::uint64_t, Reply>> replies;
    bool draining = false;

    ThreadPool& pool; // the workers, shared by every loop; each job posts its reply here

    // Owned by the loop thread.
    std::unordered_map<std::uint64_t, Conn> conns;
    std::vector<std::uint64_t> ready; // answered kAnswersPerTurn in a row, more may be buffered
    std::uint64_t next_id = 1;
    std::thread loop_thread;
    bool loop_done = false; // under `mutex`

    Impl(const ConnectionLimits& l,
         ThreadPool& workers,
         ConnectionHandlers h,
         Metrics& m,
         std::shared_ptr<std::atomic<std::size_t>> shared_open)
        : limits(l), handlers(std::move(h)), metrics(m), open(std::move(shared_open)),
          pool(workers) {
        epoll_fd = epoll_create1(EPOLL_CLOEXEC);
        wake_fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
        if (epoll_fd < 0 || wake_fd < 0) {
            throw std::runtime_error(std::string("cannot set up the connection loop: ") +
                                     std::strerror(errno));
        }
        epoll_event ev{};
        ev.events = EPOLLIN;
        ev.data.u64 = kWakeId;
        epoll_ctl(epoll_fd, EPOLL_CTL_ADD, wake_fd, &ev);
        loop_thread = std::thread([this] { loop(); });
    }

    // After the pool is joined (~Connections): a job may still wake this loop after posting
    // its reply, so the descriptors must outlive every job.
    ~Impl() {
        start_drain();
        join_loop();
        close(wake_fd);
        close(epoll_fd);
    }

    void join_loop() {
        if (loop_thread.joinable()) {
            loop_thread.join();
        }
    }

    void wake() {
        const std::uint64_t one = 1;
        [[maybe_unused]] const auto n = write(wake_fd, &one, sizeof one);
    }

    void start_drain() {
        {
            std::lock_guard<std::mutex> lock(mutex);
            draining = true;
        }
        wake();
    }

    // ---- the loop thread ----

    void set_events(std::uint64_t id, Conn& c, std::uint32_t events) {
        if (events == c.events) {
            return;
        }
        epoll_event ev{};
        ev.events = events;
        ev.data.u64 = id;
        if (events == 0) {
            epoll_ctl(epoll_fd, EPOLL_CTL_DEL, c.fd, &ev);
        } else {
            epoll_ctl(epoll_fd, c.events == 0 ? EPOLL_CTL_ADD : EPOLL_CTL_MOD, c.fd, &ev);
        }
        c.events = events;
    }

    void close_conn(std::uint64_t id) {
        const auto it = conns.find(id);
        if (it == conns.end()) {
            return;
        }
        set_events(id, it->second, 0);
        close(it->second.fd);
        conns.erase(it);
        --*open;
        --metrics.open_connections;
    }

    void add(int fd, bool refuse_all) {
        ++metrics.accepted_connections;
        const int flags = fcntl(fd, F_GETFL, 0);
        fcntl(fd, F_SETFL, flags | O_NONBLOCK);
        const int one = 1;
        setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        // Counted in before the test, so that two loops adopting at once cannot both pass it.
        if (refuse_all || open->fetch_add(1) >= limits.max_connections) {
            if (!refuse_all) {
                --*open;
            }
            // Over the limit (or stopping): a short 503, best effort, and close.
            ++metrics.refused_connections;
            const std::string text =
                handlers.refuse(503, "too many connections; retry shortly", peer_of(fd));
            [[maybe_unused]] const auto n = send(fd, text.data(), text.size(), MSG_NOSIGNAL);
            close(fd);
            return;
        }
        const std::uint64_t id = next_id++;
        Conn& c = conns[id];
        c.fd = fd;
        c.peer = peer_of(fd);
        c.since = Clock::now();
        ++metrics.open_connections;
        set_events(id, c, EPOLLIN | EPOLLRDHUP);
    }

    void refuse(std::uint64_t id, Conn& c, int status, const std::string& why) {
        c.in.clear();
        Reply reply;
        reply.bytes = handlers.refuse(status, why, c.peer);
        reply.close = true;
        start_write(c, std::move(reply));
        write_out(id, c);
    }

    static void start_write(Conn& c, Reply reply) {
        c.out = std::move(reply.bytes);
        c.out_body = std::move(reply.body);
        c.out_pos = 0;
        c.close_after = reply.close;
        c.phase = Phase::Write;
        c.since = Clock::now();
    }

    // Reads what is there, up to what one request may hold.
    bool read_some(Conn& c) {
        const std::size_t cap = limits.head.head_bytes + limits.head.body_bytes + kReadChunk;
        char buf[kReadChunk];
        while (c.in.size() < cap) {
            const ssize_t n = recv(c.fd, buf, sizeof buf, 0);
            if (n > 0) {
                c.in.append(buf, static_cast<std::size_t>(n));
                continue;
            }
            if (n == 0) {
                c.peer_done = true;
                return true;
            }
            if (errno == EINTR) {
                continue;
            }
            return errno == EAGAIN || errno == EWOULDBLOCK;
        }
        return true;
    }

    // Moves a reading connection on: waits, refuses, answers complete requests that `quick`
    // can answer (as many as are pipelined, while their responses go out at once), or hands a
    // complete request to a worker.
    void advance(std::uint64_t id, Conn& c) {
        // A loop, not recursion through write_out: a client may pipeline hundreds of requests.
        // After kAnswersPerTurn answers in a row the connection waits in `ready` for the next
        // turn of the loop, so one pipelining client cannot hold up the loop's other ones.
        for (int answered = 0; advance_one(id, c);) {
            if (++answered == kAnswersPerTurn) {
                ready.push_back(id);
                return;
            }
        }
    }

    // One step of advance(); true when a response was written in full and the connection waits
    // for its next request.
    bool advance_one(std::uint64_t id, Conn& c) {
        // RFC 9112 section 2.2: empty lines before a request line are ignored.
        std::size_t skip = 0;
        while (skip < c.in.size() && (c.in[skip] == '\r' || c.in[skip] == '\n')) {
            ++skip;
        }
        if (skip > 0 && skip <= 8) {
            c.in.erase(0, skip);
        } else if (skip > 8) {
            refuse(id, c, 400, "the request starts with too many empty lines");
            return false;
        }
        bool draining_now;
        {
            std::lock_guard<std::mutex> lock(mutex);
            draining_now = draining;
        }
        if (c.in.empty()) {
            if (c.peer_done || draining_now) {
                close_conn(id);
                return false;
            }
            if (c.phase != Phase::Idle) {
                c.phase = Phase::Idle;
                c.since = Clock::now();
            }
            set_events(id, c, EPOLLIN | EPOLLRDHUP);
            return false;
        }
        if (c.phase == Phase::Idle) {
            c.phase = Phase::Head;
            c.since = Clock::now();
        }
        const RequestHead head = check_request_head(c.in, limits.head);
        if (head.state == RequestHead::State::Bad) {
            refuse(id, c, head.status, head.error);
            return false;
        }
        if (head.state == RequestHead::State::Incomplete) {
            if (c.peer_done || draining_now) {
                close_conn(id);
                return false;
            }
            set_events(id, c, EPOLLIN | EPOLLRDHUP);
            return false;
        }
        const std::size_t need = head.head_bytes + head.body_bytes;
        if (c.in.size() < need) {
            if (c.phase != Phase::Body) {
                c.phase = Phase::Body;
                c.since = Clock::now();
            }
            if (c.peer_done || draining_now) {
                close_conn(id);
                return false;
            }
            set_events(id, c, EPOLLIN | EPOLLRDHUP);
            return false;
        }
        ++c.served;
        const bool last = c.served >= limits.max_requests || c.peer_done || draining_now;
        if (handlers.quick) {
            Reply reply;
            if (handlers.quick(std::string_view(c.in).substr(0, need), c.peer, last, reply)) {
                c.in.erase(0, need);
                reply.close = reply.close || last;
                start_write(c, std::move(reply));
                return write_out(id, c);
            }
        }
        std::string request = c.in.substr(0, need);
        c.in.erase(0, need);
        c.phase = Phase::Busy;
        set_events(id, c, 0); // nothing more is read until this request is answered
        Peer peer = c.peer;
        pool.submit([this, id, last, request = std::move(request), peer] {
            Reply reply = handlers.answer(request, peer, last);
            reply.close = reply.close || last;
            {
                std::lock_guard<std::mutex> lock(mutex);
                replies.emplace_back(id, std::move(reply));
            }
            wake();
        });
        return false;
    }

    // Writes what is left of the response without blocking. True when all of it is written and
    // the connection is kept, now Idle; false when it waits for EPOLLOUT or has been closed.
    bool write_out(std::uint64_t id, Conn& c) {
        const std::size_t head = c.out.size();
        const std::size_t total = head + (c.out_body ? c.out_body->size() : 0);
        while (c.out_pos < total) {
            iovec parts[2];
            int n_parts = 0;
            if (c.out_pos < head) {
                parts[n_parts++] = {c.out.data() + c.out_pos, head - c.out_pos};
            }
            if (c.out_body && !c.out_body->empty()) {
                const std::size_t from = c.out_pos > head ? c.out_pos - head : 0;
                parts[n_parts++] = {const_cast<char*>(c.out_body->data()) + from,
                                    c.out_body->size() - from};
            }
            msghdr msg{};
            msg.msg_iov = parts;
            msg.msg_iovlen = static_cast<std::size_t>(n_parts);
            const ssize_t n = sendmsg(c.fd, &msg, MSG_NOSIGNAL);
            if (n > 0) {
                c.out_pos += static_cast<std::size_t>(n);
                c.since = Clock::now();
                continue;
            }
            if (n < 0 && errno == EINTR) {
                continue;
            }
            if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
                set_events(id, c, EPOLLOUT);
                return false;
            }
            close_conn(id); // the client is gone
            return false;
        }
        c.out.clear();
        c.out_body.reset();
        c.out_pos = 0;
        if (c.close_after) {
            close_conn(id);
            return false;
        }
        c.phase = Phase::Idle;
        c.since = Clock::now();
        return true;
    }

    void flush(std::uint64_t id, Conn& c) {
        if (write_out(id, c)) {
            advance(id, c); // a pipelined request may be waiting in `in`
        }
    }

    void on_event(std::uint64_t id, std::uint32_t events) {
        const auto it = conns.find(id);
        if (it == conns.end()) {
            return;
        }
        Conn& c = it->second;
        if (c.phase == Phase::Write) {
            if (events & (EPOLLOUT | EPOLLERR | EPOLLHUP)) {
                flush(id, c);
            }
            return;
        }
        if (c.phase == Phase::Busy) {
            return;
        }
        if (!read_some(c)) {
            close_conn(id);
            return;
        }
        advance(id, c);
    }

    void sweep(Clock::time_point now, bool draining_now) {
        std::vector<std::uint64_t> idle, slow, stalled, reading;
        for (auto& [id, c] : conns) {
            const auto age = now - c.since;
            switch (c.phase) {
            case Phase::Idle:
            case Phase::Head:
            case Phase::Body:
                if (draining_now) {
                    reading.push_back(id);
                } else if (c.phase == Phase::Idle && age > limits.idle_timeout) {
                    idle.push_back(id);
                } else if ((c.phase == Phase::Head && age > limits.head_timeout) ||
                           (c.phase == Phase::Body && age > limits.body_timeout)) {
                    slow.push_back(id);
                }
                break;
            case Phase::Write:
                if (age > limits.write_timeout) {
                    stalled.push_back(id);
                }
                break;
            case Phase::Busy:
                break;
            }
        }
        // Stopping: a request that has fully arrived is still answered; anything else closes.
        for (auto id : reading) {
            const auto it = conns.find(id);
            if (it != conns.end() && read_some(it->second)) {
                advance(id, it->second);
            } else {
                close_conn(id);
            }
        }
        for (auto id : idle) {
            close_conn(id);
        }
        for (auto id : slow) {
            const auto it = conns.find(id);
            if (it == conns.end()) {
                continue;
            }
            ++metrics.request_timeouts;
            refuse(id,
                   it->second,
                   408,
                   it->second.phase == Phase::Head ? "the request head did not arrive in time"
                                                   : "the request body did not arrive in time");
        }
        for (auto id : stalled) {
            ++metrics.request_timeouts;
            close_conn(id);
        }
    }

    void loop() {
        std::vector<epoll_event> events(256);
        auto last_sweep = Clock::now();
        for (;;) {
            const int n = epoll_wait(epoll_fd,
                                     events.data(),
                                     static_cast<int>(events.size()),
                                     ready.empty() ? static_cast<int>(kSweepEvery.count()) : 0);
            std::vector<int> fds;
            std::vector<std::pair<std::uint64_t, Reply>> done;
            bool draining_now;
            {
                std::lock_guard<std::mutex> lock(mutex);
                fds.swap(adopted);
                done.swap(replies);
                draining_now = draining;
            }
            for (int i = 0; i < n; ++i) {
                if (events[i].data.u64 == kWakeId) {
                    std::uint64_t count;
                    [[maybe_unused]] const auto r = read(wake_fd, &count, sizeof count);
                    continue;
                }
                on_event(events[i].data.u64, events[i].events);
            }
            for (int fd : fds) {
                add(fd, draining_now);
            }
            for (auto& [id, reply] : done) {
                const auto it = conns.find(id);
                if (it == conns.end()) {
                    continue;
                }
                Conn& c = it->second;
                reply.close = reply.close || draining_now;
                start_write(c, std::move(reply));
                flush(id, c);
            }
            std::vector<std::uint64_t> turn;
            turn.swap(ready);
            for (auto id : turn) {
                const auto it = conns.find(id);
                if (it != conns.end() && (it->second.phase == Phase::Idle ||
                                          it->second.phase == Phase::Head)) {
                    advance(id, it->second);
                }
            }
            const auto now = Clock::now();
            if (draining_now || now - last_sweep >= kSweepEvery) {
                sweep(now, draining_now);
                last_sweep = now;
            }
            if (draining_now && conns.empty()) {
                std::lock_guard<std::mutex> lock(mutex);
                if (adopted.empty() && replies.empty()) {
                    loop_done = true; // adopt() closes what still comes in
                    break;
                }
            }
        }
    }
};

Connections::Connections(const ConnectionLimits& limits,
                         int workers,
                         ConnectionHandlers handlers,
                         Metrics& metrics,
                         int loops)
    : pool_(std::make_unique<ThreadPool>(workers)) {
    const auto open = std::make_shared<std::atomic<std::size_t>>(0);
    for (int i = 0; i < std::max(1, loops); ++i) {
        loops_.push_back(std::make_unique<Impl>(limits, *pool_, handlers, metrics, open));
    }
}

Connections::~Connections() {
    // Every loop drains (each waits for the replies its workers still owe it), then the
    // workers are joined, and only then do the loops close their descriptors.
    drain();
    pool_->join();
    loops_.clear();
}

void Connections::adopt(int fd) {
    Impl& impl = *loops_[next_loop_.fetch_add(1) % loops_.size()];
    {
        std::lock_guard<std::mutex> lock(impl.mutex);
        if (impl.loop_done) {
            close(fd);
            return;
        }
        impl.adopted.push_back(fd);
    }
    impl.wake();
}

void Connections::drain() {
    for (auto& loop : loops_) {
        loop->start_drain();
    }
    for (auto& loop : loops_) {
        loop->join_loop();
    }
}

} // namespace tb::server
