// The build's lock on its output (see output_lock.hpp for the files and the modes).
//
// Invariant that makes removing the lock file safe: a lock only counts when it is held on the
// file that is at the path right now. A process removes the file only while holding it
// Exclusive; whoever opened the old file before the removal and then gets its lock sees that
// the path names another file (or none) and starts over on the new one.
#include "tiler/stores/output_lock.hpp"

#include "core/error.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/store.hpp"

#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstring>
#include <ctime>
#include <fcntl.h>
#include <filesystem>
#include <sstream>
#include <sys/file.h>
#include <sys/stat.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace tb::tiler {
namespace {

using Clock = std::chrono::steady_clock;

constexpr double kSetupWaitSeconds = 120; // a shard's manifest check takes well under that
constexpr auto kPoll = std::chrono::milliseconds(20);

[[noreturn]] void fail(const std::string& path, const std::string& what, int err) {
    throw IoError(path + ": cannot " + what + " (" + std::strerror(err) + ")");
}

// As TileStore::open: these suffixes make a single-file store, anything else a directory.
bool single_file(const std::string& output) {
    return is_single_file_store(output);
}

// As the stores: a missing parent is more likely a typo than a wish for a new tree.
void check_parent(const std::string& output) {
    std::string path = output;
    while (path.size() > 1 && path.back() == '/') {
        path.pop_back();
    }
    const std::filesystem::path parent =
        std::filesystem::path(path).lexically_normal().parent_path();
    std::error_code ec;
    if (!parent.empty() && !std::filesystem::exists(parent, ec)) {
        throw IoError(output + ": its parent directory " + parent.string() +
                      " does not exist; create it first or choose another output path");
    }
}

// Makes the store directory (only it, as the directory store does) so the lock can live in it.
void make_directory(const std::string& output) {
    struct stat st {};
    if (::stat(output.c_str(), &st) == 0) {
        if (!S_ISDIR(st.st_mode)) {
            throw IoError(output + ": exists and is not a directory; choose another output path "
                                   "(a path ending in .sqlite makes an SQLite store)");
        }
        return;
    }
    if (::mkdir(output.c_str(), 0755) != 0 && errno != EEXIST) {
        fail(output, "create directory", errno);
    }
}

std::string host_name() {
    char buf[256] = {};
    if (::gethostname(buf, sizeof buf - 1) != 0 || buf[0] == '\0') {
        return "unknown";
    }
    return buf;
}

std::string utc_now() {
    const std::time_t t = std::time(nullptr);
    std::tm tm{};
    ::gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf;
}

bool same_file(int fd, const std::string& path) {
    struct stat a {};
    struct stat b {};
    return ::fstat(fd, &a) == 0 && ::stat(path.c_str(), &b) == 0 && a.st_dev == b.st_dev &&
           a.st_ino == b.st_ino;
}

enum class Got { Held, Busy, NoLocks };

// Opens (creating) `path` and flocks it with `op` (LOCK_SH or LOCK_EX) without waiting. On Held,
// `fd` holds the lock on the file now at `path` (see the invariant at the top).
Got try_lock(const std::string& path, int op, int& fd) {
    for (;;) {
        fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
        if (fd < 0) {
            fail(path, "open the build lock file", errno);
        }
        if (::flock(fd, op | LOCK_NB) != 0) {
            const int err = errno;
            ::close(fd);
            fd = -1;
            if (err == EINTR) {
                continue;
            }
            if (err == EWOULDBLOCK) {
                return Got::Busy;
            }
            if (err == ENOLCK || err == EOPNOTSUPP || err == ENOSYS || err == EINVAL) {
                return Got::NoLocks;
            }
            fail(path, "lock the build lock file", err);
        }
        if (same_file(fd, path)) {
            return Got::Held;
        }
        ::close(fd); // removed (or replaced) by its last holder meanwhile: start over
    }
}

std::string read_text(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    std::string text;
    if (fd < 0) {
        return text;
    }
    char buf[4096];
    for (;;) {
        const ssize_t n = ::read(fd, buf, sizeof buf);
        if (n <= 0) {
            break;
        }
        text.append(buf, static_cast<std::size_t>(n));
    }
    ::close(fd);
    return text;
}

void write_at(int fd, const std::string& text, off_t offset, const std::string& path) {
    std::size_t done = 0;
    while (done < text.size()) {
        const ssize_t n =
            ::pwrite(fd, text.data() + done, text.size() - done, offset + static_cast<off_t>(done));
        if (n < 0 && errno != EINTR) {
            fail(path, "write the build lock file", errno);
        }
        done += n > 0 ? static_cast<std::size_t>(n) : 0;
    }
}

// The Exclusive holder's line replaces whatever the file held.
void replace_text(int fd, const std::string& text, const std::string& path) {
    if (::ftruncate(fd, 0) != 0) {
        fail(path, "write the build lock file", errno);
    }
    write_at(fd, text, 0, path);
}

// A shard adds its line at the end, in one write (O_APPEND), beside the other shards.
void append_line(const std::string& line, const std::string& path) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
    if (fd < 0) {
        fail(path, "open the build lock file", errno);
    }
    const ssize_t n = ::write(fd, line.data(), line.size());
    const int err = errno;
    ::close(fd); // another open file than the locked one: the lock stays
    if (n != static_cast<ssize_t>(line.size())) {
        fail(path, "write the build lock file", n < 0 ? err : EIO);
    }
}

// Overwrites with spaces each whole line that `drop` picks, in place: lines that other shards
// append meanwhile keep their bytes, so shards need no mutex to keep their lines.
void blank_lines(int fd,
                 const std::string& path,
                 const std::function<bool(const std::string&)>& drop) {
    const std::string text = read_text(path);
    for (std::size_t at = 0, end; (end = text.find('\n', at)) != std::string::npos; at = end + 1) {
        const std::string line = text.substr(at, end - at);
        if (line.find_first_not_of(' ') != std::string::npos && drop(line)) {
            write_at(fd, std::string(line.size(), ' '), static_cast<off_t>(at), path);
        }
    }
}

struct Holder {
    long pid = 0;
    std::string host, since, command;
};

// "pid=123 host=h since=T command=terrabound build ..." (the command last: it holds spaces).
std::string holder_line(const Holder& h) {
    return "pid=" + std::to_string(h.pid) + " host=" + h.host + " since=" + h.since +
           " command=" + h.command + "\n";
}

bool parse_holder(const std::string& line, Holder& h) {
    std::istringstream in(line);
    std::string pid, host, since;
    if (!(in >> pid >> host >> since) || pid.rfind("pid=", 0) != 0 || host.rfind("host=", 0) != 0 ||
        since.rfind("since=", 0) != 0) {
        return false;
    }
    h.pid = std::atol(pid.c_str() + 4);
    h.host = host.substr(5);
    h.since = since.substr(6);
    const auto at = line.find(" command=");
    h.command = at == std::string::npos ? "" : line.substr(at + 9);
    return h.pid > 0;
}

// A holder on another host may be alive for all this one can tell; on this host, a pid that no
// longer exists is a line left by a killed shard.
bool maybe_alive(const Holder& h, const std::string& here) {
    return h.host != here || ::kill(static_cast<pid_t>(h.pid), 0) == 0 || errno != ESRCH;
}

std::vector<Holder> live_holders(const std::string& text) {
    std::vector<Holder> out;
    const std::string here = host_name();
    std::istringstream in(text);
    std::string line;
    while (std::getline(in, line)) {
        Holder h;
        if (parse_holder(line, h) && maybe_alive(h, here)) {
            out.push_back(h);
        }
    }
    return out;
}

[[noreturn]] void refuse(const std::string& output, const std::string& path, LockMode mode) {
    // The holder may be writing its line this very moment: give it a little time.
    std::vector<Holder> holders;
    for (int i = 0; i < 10 && holders.empty(); ++i) {
        if (i > 0) {
            std::this_thread::sleep_for(kPoll);
        }
        holders = live_holders(read_text(path));
    }
    std::string who;
    for (const auto& h : holders) {
        who += (who.empty() ? "" : "; ") + std::string("pid ") + std::to_string(h.pid) +
               " on host " + h.host + " (" + h.command + ", since " + h.since + ")";
    }
    if (who.empty()) {
        who = "a process that has not written its pid and host into the lock file yet";
    }
    const std::string why =
        mode == LockMode::Shared
            ? "shards of one build may run together, but not beside an unsharded build, --force "
              "or --finalize"
            : "only the shards of one build (--shard I/N) may write an output together";
    throw IoError(output + ": another terrabound build is writing it: " + who +
                  "; wait for it to finish, or stop it and run again (with --resume to keep "
                  "what it wrote); " +
                  why + ". The lock (" + path +
                  ") goes when its holder exits or is killed: do not delete the file");
}

} // namespace

OutputLock::OutputLock(const std::string& output, LockMode mode, const std::string& command)
    : output_(output), mode_(mode) {
    check_parent(output);
    std::string base;
    if (single_file(output)) {
        base = output + ".build";
    } else {
        make_directory(output);
        base = output;
        while (base.size() > 1 && base.back() == '/') {
            base.pop_back();
        }
        base += "/.build";
    }
    path_ = base + ".lock";
    setup_path_ = base + "-setup.lock";
    line_ = holder_line(Holder{static_cast<long>(::getpid()), host_name(), utc_now(), command});
    const int op = mode == LockMode::Exclusive ? LOCK_EX : LOCK_SH;
    switch (try_lock(path_, op, fd_)) {
    case Got::Busy:
        refuse(output, path_, mode);
    case Got::NoLocks:
        log::warn("build: " + path_ +
                  ": the file system does not support locks, so nothing keeps another build "
                  "from writing " +
                  output + " at the same time; run one at a time");
        return;
    case Got::Held:
        break;
    }
    try {
        if (mode == LockMode::Exclusive) {
            replace_text(fd_, line_, path_);
        } else {
            // Lines of shards killed on this host go; they no longer hold anything.
            const std::string here = host_name();
            blank_lines(fd_, path_, [&](const std::string& line) {
                Holder h;
                return parse_holder(line, h) && !maybe_alive(h, here);
            });
            append_line(line_, path_);
        }
    } catch (...) {
        release();
        throw;
    }
}

OutputLock::~OutputLock() {
    release();
}

void OutputLock::setup(const std::function<void()>& fn) {
    if (fd_ < 0) {
        fn();
        return;
    }
    const auto deadline = Clock::now() + std::chrono::duration<double>(kSetupWaitSeconds);
    int fd = -1;
    for (;;) {
        const Got got = try_lock(setup_path_, LOCK_EX, fd);
        if (got == Got::NoLocks) {
            fn();
            return;
        }
        if (got == Got::Held) {
            break;
        }
        if (Clock::now() >= deadline) {
            throw IoError(output_ +
                          ": another build sharing it has been checking its settings "
                          "for " +
                          std::to_string(static_cast<int>(kSetupWaitSeconds)) +
                          " s without finishing (" + setup_path_ +
                          " is held); see that no shard is stopped or hung, then run again");
        }
        std::this_thread::sleep_for(kPoll);
    }
    // Removed while held Exclusive (the invariant at the top), so that no file stays behind.
    struct Leave {
        int fd;
        const std::string& path;
        ~Leave() {
            ::unlink(path.c_str());
            ::close(fd);
        }
    } leave{fd, setup_path_};
    fn();
}

void OutputLock::release() noexcept {
    if (fd_ < 0) {
        return;
    }
    if (mode_ == LockMode::Shared) {
        try {
            const std::string mine = line_.substr(0, line_.size() - 1);
            blank_lines(fd_, path_, [&](const std::string& line) { return line == mine; });
        } catch (...) {
            // Only the line stays, and the next shard on this host blanks it as dead.
        }
    }
    // The last holder gets the lock Exclusive (a shard's conversion may lose it to another
    // process instead: then that one is not the last) and removes the file.
    if (::flock(fd_, LOCK_EX | LOCK_NB) == 0 && same_file(fd_, path_)) {
        ::unlink(path_.c_str());
    }
    ::close(fd_);
    fd_ = -1;
}

} // namespace tb::tiler
