#pragma once
// One writer per output: the advisory lock `terrabound build` holds on its output from before it
// reads or writes anything there until it returns, so that two builds never mix their tiles.
//
// Where: for a directory OUT, the file OUT/.build.lock; for a single-file store OUT.sqlite (or
// .db, .mbtiles, .pmtiles), the sibling OUT.sqlite.build.lock, next to SQLite's own -wal and -shm.
// Neither is a tile or a document: `serve` never answers it (document names cannot start with '.',
// and nothing outside OUT/{layer}/ is served), and the last holder removes it on its way out, so a
// finished output holds no lock file for static hosting to publish. A process killed with SIGKILL
// leaves the file behind, but not the lock.
//
// How: flock(2) on that file. The kernel drops the lock when its holder exits or dies (kill -9
// included), so a file left by a dead process never blocks the next build, which takes it over.
// The file's text (one line per holder: pid, host, start time, command) only serves the message
// of whoever is refused; shards append their lines and blank them (spaces) on their way out. On
// NFS, Linux maps flock onto the server's byte-range locks, which hold across machines; where the
// file system has no locks at all, a warning says the output is not protected and the build goes
// on.
//
// Modes: an unsharded build (fresh, --resume, --force, --finalize) holds the lock Exclusive, and
// every shard run (--shard I/N) Shared, so the shards of one build write side by side while
// anything else is refused, a shard beside a --force run included. Shards must also agree on
// their settings: each checks (or, first, writes) the build manifest inside setup(), which
// admits one holder at a time, so two shards starting together cannot both find no manifest and
// each write their own.
#include <functional>
#include <string>

namespace tb::tiler {

enum class LockMode { Exclusive, Shared };

class OutputLock {
public:
    // Takes the lock on `output` (a store path as TileStore::open takes it; a missing directory
    // is created) without waiting. `command` says what holds it ("terrabound build --shard
    // 1/4") and goes into the lock file with this process's pid, host and start time.
    // Throws IoError at once when another process holds a conflicting lock, naming each
    // holder's pid, host and command and what to do; IoError when the file cannot be made.
    OutputLock(const std::string& output, LockMode mode, const std::string& command);
    // Releases the lock; the last holder removes the lock file.
    ~OutputLock();
    OutputLock(const OutputLock&) = delete;
    OutputLock& operator=(const OutputLock&) = delete;

    // Runs `fn` while no other holder of this output's lock runs its own setup (waiting up to
    // two minutes for one that does; IoError past that). The builder checks and writes the
    // build manifest in it. Exceptions from `fn` pass through, with setup left.
    void setup(const std::function<void()>& fn);

    // The lock file's path.
    const std::string& path() const { return path_; }

private:
    void release() noexcept;

    std::string output_;
    std::string path_;       // the lock file
    std::string setup_path_; // the setup lock's file, beside it (there only during a setup)
    std::string line_;       // this holder's line in the lock file
    LockMode mode_;
    int fd_ = -1; // -1: not locked (released, or a file system without locks)
};

} // namespace tb::tiler
