// One writer per output (tiler/stores/output_lock.hpp): the lock on its own, with holders in
// real processes (fork), and `terrabound build` processes (TB_BINARY) racing on one output.
#include "core/error.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/pyramid/build.hpp"
#include "tiler/stores/output_lock.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <fcntl.h>
#include <fstream>
#include <sstream>
#include <sys/file.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

using namespace tb::tiler;
using tb_test::ScratchDir;

namespace {

std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

std::string host() {
    char buf[256] = {};
    REQUIRE(::gethostname(buf, sizeof buf - 1) == 0);
    return buf;
}

// The lock file of an output, as output_lock.hpp places it.
std::string lock_file(const std::string& output) {
    const bool file = output.size() > 7 && output.compare(output.size() - 7, 7, ".sqlite") == 0;
    return file ? output + ".build.lock" : output + "/.build.lock";
}

// A process holding the lock until told to go (or killed).
struct Holder {
    pid_t pid = -1;
    int go = -1; // a byte written there lets the holder exit (not EOF: later children hold
                 // copies of this end)
};

Holder hold_in_child(const std::string& output, LockMode mode) {
    int ready[2], go[2];
    REQUIRE(::pipe(ready) == 0);
    REQUIRE(::pipe(go) == 0);
    const pid_t pid = ::fork();
    REQUIRE(pid >= 0);
    if (pid == 0) {
        ::close(ready[0]);
        ::close(go[1]);
        char c = 'x';
        try {
            OutputLock lock(output, mode, "test holder");
            c = 'r';
            (void)!::write(ready[1], &c, 1);
            (void)!::read(go[0], &c, 1);
        } catch (...) {
            (void)!::write(ready[1], &c, 1);
        }
        ::_exit(c == 'x' ? 1 : 0);
    }
    ::close(ready[1]);
    ::close(go[0]);
    char c = 0;
    REQUIRE(::read(ready[0], &c, 1) == 1);
    ::close(ready[0]);
    REQUIRE(c == 'r');
    return Holder{pid, go[1]};
}

int wait_exit(pid_t pid) {
    int status = 0;
    REQUIRE(::waitpid(pid, &status, 0) == pid);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
}

int let_go(Holder& h) {
    const char c = 'g';
    REQUIRE(::write(h.go, &c, 1) == 1);
    ::close(h.go);
    return wait_exit(h.pid);
}

std::string refusal(const std::string& output, LockMode mode) {
    try {
        OutputLock lock(output, mode, "test second writer");
    } catch (const tb::IoError& e) {
        return e.what();
    }
    return "";
}

std::string holder_text(pid_t pid) {
    return "pid " + std::to_string(pid) + " on host " + host();
}

// 65 x 65 heights over a quarter degree in the Alps: a hill on a slope.
std::string write_hill(const std::string& path) {
    tb_test::Fixture f;
    f.width = f.height = 65;
    f.epsg = 4326;
    f.geotransform = std::array<double, 6>{7.0, 0.25 / 64, 0, 46.25, 0, -0.25 / 64};
    for (int r = 0; r < 65; ++r) {
        for (int c = 0; c < 65; ++c) {
            const double x = c / 64.0 - 0.5, y = r / 64.0 - 0.5;
            f.values.push_back(900 + 3 * c + 500 * std::exp(-(x * x + y * y) * 12));
        }
    }
    return tb_test::write_fixture(path, f);
}

const char* const kBuildArgs[] = {"--size",
                                  "32",
                                  "--min-zoom",
                                  "8",
                                  "--max-zoom",
                                  "9",
                                  "--threads",
                                  "1",
                                  "--layer",
                                  "terrain",
                                  "--formats",
                                  "glb"};

// `terrabound build DEM -o OUT <kBuildArgs> <extra>`, started in the background; stderr to `err`.
pid_t spawn_build(const std::string& dem,
                  const std::string& out,
                  const std::vector<std::string>& extra,
                  const std::string& err) {
    std::vector<std::string> args{TB_BINARY, "build", dem, "-o", out};
    args.insert(args.end(), std::begin(kBuildArgs), std::end(kBuildArgs));
    args.insert(args.end(), extra.begin(), extra.end());
    std::vector<char*> argv;
    for (auto& a : args) {
        argv.push_back(a.data());
    }
    argv.push_back(nullptr);
    const pid_t pid = ::fork();
    REQUIRE(pid >= 0);
    if (pid == 0) {
        const int fd = ::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        ::dup2(fd, STDERR_FILENO);
        const int null = ::open("/dev/null", O_WRONLY);
        ::dup2(null, STDOUT_FILENO);
        ::execv(argv[0], argv.data());
        ::_exit(127);
    }
    return pid;
}

int run_build(const std::string& dem,
              const std::string& out,
              const std::vector<std::string>& extra,
              const std::string& err) {
    return wait_exit(spawn_build(dem, out, extra, err));
}

// Waits (up to 60 s) until the lock file names `pid`.
void wait_for_holder(const std::string& output, pid_t pid) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    const std::string mark = "pid=" + std::to_string(pid) + " ";
    while (slurp(lock_file(output)).find(mark) == std::string::npos) {
        REQUIRE(std::chrono::steady_clock::now() < deadline);
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
}

// Holds the output's setup lock, which parks every build of it inside its manifest step (with
// its output lock held) until released: what makes "while one runs" deterministic here.
struct SetupGate {
    int fd = -1;
    explicit SetupGate(const std::string& output) {
        const std::string lock = lock_file(output);
        const std::string path = lock.substr(0, lock.size() - 5) + "-setup.lock";
        fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
        REQUIRE(fd >= 0);
        REQUIRE(::flock(fd, LOCK_EX) == 0);
    }
    void open_gate() {
        if (fd >= 0) {
            ::close(fd);
            fd = -1;
        }
    }
    ~SetupGate() { open_gate(); }
};

std::vector<std::string> outputs(const ScratchDir& dir) {
    return {dir.file("tiles"), dir.file("tiles.sqlite")};
}

} // namespace

TEST_CASE("output lock: a second writer is refused at once, naming the holder's pid and host") {
    ScratchDir dir;
    for (const auto& out : outputs(dir)) {
        INFO(out);
        Holder holder = hold_in_child(out, LockMode::Exclusive);
        CHECK(slurp(lock_file(out)).find("pid=" + std::to_string(holder.pid) + " host=" + host()) !=
              std::string::npos);
        const auto start = std::chrono::steady_clock::now();
        const std::string exclusive = refusal(out, LockMode::Exclusive);
        CHECK(std::chrono::steady_clock::now() - start < std::chrono::seconds(2));
        CHECK(exclusive.find(holder_text(holder.pid) + " (test holder, since ") !=
              std::string::npos);
        CHECK(exclusive.find("another terrabound build is writing it") != std::string::npos);
        CHECK(exclusive.find("wait for it to finish") != std::string::npos);
        // A shard beside an unsharded build is a conflict too.
        CHECK(refusal(out, LockMode::Shared).find(holder_text(holder.pid)) != std::string::npos);
        CHECK(let_go(holder) == 0);
        // The holder gone, its file is too, and the lock is free.
        CHECK_FALSE(std::filesystem::exists(lock_file(out)));
        {
            OutputLock lock(out, LockMode::Exclusive, "test");
            CHECK(std::filesystem::exists(lock.path()));
            CHECK(lock.path() == lock_file(out));
        }
        CHECK_FALSE(std::filesystem::exists(lock_file(out)));
    }
}

TEST_CASE("output lock: shards share the output, and an exclusive writer beside them is refused") {
    ScratchDir dir;
    for (const auto& out : outputs(dir)) {
        INFO(out);
        Holder a = hold_in_child(out, LockMode::Shared);
        Holder b = hold_in_child(out, LockMode::Shared);
        const std::string message = refusal(out, LockMode::Exclusive);
        CHECK(message.find(holder_text(a.pid)) != std::string::npos);
        CHECK(message.find(holder_text(b.pid)) != std::string::npos);
        CHECK(message.find("only the shards of one build") != std::string::npos);
        {
            OutputLock mine(out, LockMode::Shared, "test shard");
            CHECK(let_go(a) == 0);
            // A shard leaving takes its line out; the others stay.
            const std::string text = slurp(lock_file(out));
            CHECK(text.find("pid=" + std::to_string(a.pid) + " ") == std::string::npos);
            CHECK(text.find("pid=" + std::to_string(b.pid) + " ") != std::string::npos);
            CHECK(text.find("pid=" + std::to_string(::getpid()) + " ") != std::string::npos);
            CHECK(let_go(b) == 0);
            CHECK(std::filesystem::exists(lock_file(out)));
        }
        // The last shard out removed the file.
        CHECK_FALSE(std::filesystem::exists(lock_file(out)));
    }
}

TEST_CASE("output lock: the lock of a holder killed with SIGKILL is taken over") {
    ScratchDir dir;
    for (const auto& out : outputs(dir)) {
        INFO(out);
        Holder holder = hold_in_child(out, LockMode::Exclusive);
        REQUIRE(::kill(holder.pid, SIGKILL) == 0);
        CHECK(wait_exit(holder.pid) == -SIGKILL);
        ::close(holder.go);
        // The file stays, naming a dead process, but does not block.
        REQUIRE(slurp(lock_file(out)).find("pid=" + std::to_string(holder.pid) + " ") !=
                std::string::npos);
        {
            OutputLock lock(out, LockMode::Exclusive, "test taker");
            const std::string text = slurp(lock_file(out));
            CHECK(text.find("pid=" + std::to_string(holder.pid) + " ") == std::string::npos);
            CHECK(text.find("pid=" + std::to_string(::getpid()) + " ") != std::string::npos);
        }
        // A killed shard: the next shard drops its line, the live shard's stays.
        Holder killed = hold_in_child(out, LockMode::Shared);
        Holder alive = hold_in_child(out, LockMode::Shared);
        REQUIRE(::kill(killed.pid, SIGKILL) == 0);
        CHECK(wait_exit(killed.pid) == -SIGKILL);
        ::close(killed.go);
        {
            OutputLock lock(out, LockMode::Shared, "test shard");
            const std::string text = slurp(lock_file(out));
            CHECK(text.find("pid=" + std::to_string(killed.pid) + " ") == std::string::npos);
            CHECK(text.find("pid=" + std::to_string(alive.pid) + " ") != std::string::npos);
            // The refusal names the live holders only.
            const std::string message = refusal(out, LockMode::Exclusive);
            CHECK(message.find(holder_text(alive.pid)) != std::string::npos);
            CHECK(message.find("pid " + std::to_string(killed.pid) + " ") == std::string::npos);
        }
        CHECK(let_go(alive) == 0);
        CHECK_FALSE(std::filesystem::exists(lock_file(out)));
    }
}

TEST_CASE("output lock: shards run their setup one at a time") {
    ScratchDir dir;
    const std::string out = dir.file("tiles");
    OutputLock first(out, LockMode::Shared, "test shard 0");
    OutputLock second(out, LockMode::Shared, "test shard 1");
    std::atomic<int> inside{0};
    std::atomic<int> most{0};
    auto run = [&](OutputLock& lock) {
        for (int i = 0; i < 5; ++i) {
            lock.setup([&] {
                const int now = ++inside;
                most = std::max(most.load(), now);
                std::this_thread::sleep_for(std::chrono::milliseconds(20));
                --inside;
            });
        }
    };
    std::thread t(run, std::ref(first));
    run(second);
    t.join();
    CHECK(most == 1);
    // Setup leaves no file behind.
    CHECK_FALSE(std::filesystem::exists(out + "/.build-setup.lock"));
}

TEST_CASE("build lock: a second terrabound build into an output being built is refused at once, "
          "and the first completes") {
    ScratchDir dir;
    const std::string dem = write_hill(dir.file("hill.tif"));
    std::filesystem::create_directory(dir.file("tiles"));
    for (const auto& out : outputs(dir)) {
        INFO(out);
        SetupGate gate(out);
        const pid_t first = spawn_build(dem, out, {}, dir.file("first.err"));
        wait_for_holder(out, first);
        for (const std::vector<std::string>& mode :
             {std::vector<std::string>{}, {"--force"}, {"--resume"}, {"--shard", "1/2"}}) {
            INFO((mode.empty() ? "fresh" : mode[0]));
            CHECK(run_build(dem, out, mode, dir.file("second.err")) == 3);
            const std::string err = slurp(dir.file("second.err"));
            CHECK(err.find("terrabound: " + out +
                           ": another terrabound build is writing it: " + holder_text(first) +
                           " (terrabound build -o " + out) != std::string::npos);
        }
        // The library refuses the same way.
        BuildOptions b;
        b.layer.sources = {dem};
        b.output = out;
        b.resume = true;
        b.progress = ProgressMode::Off;
        const std::atomic<bool> stop{false};
        CHECK_THROWS_WITH_AS(
            build_pyramid(b, stop), doctest::Contains(holder_text(first).c_str()), tb::IoError);
        gate.open_gate();
        CHECK(wait_exit(first) == 0);
        CHECK(TileStore::open(out)->get_document("terrain", "tileset.json"));
        CHECK_FALSE(std::filesystem::exists(lock_file(out)));
        // Free again: a --resume after it runs.
        CHECK(run_build(dem, out, {"--resume"}, dir.file("third.err")) == 0);
    }
}

TEST_CASE("build lock: the shards of one build run together, and --force beside them is "
          "refused") {
    ScratchDir dir;
    const std::string dem = write_hill(dir.file("hill.tif"));
    std::filesystem::create_directory(dir.file("tiles"));
    for (const auto& out : outputs(dir)) {
        INFO(out);
        SetupGate gate(out);
        const pid_t s0 = spawn_build(dem, out, {"--shard", "0/2"}, dir.file("s0.err"));
        const pid_t s1 = spawn_build(dem, out, {"--shard", "1/2"}, dir.file("s1.err"));
        wait_for_holder(out, s0);
        wait_for_holder(out, s1);
        CHECK(run_build(dem, out, {"--force"}, dir.file("force.err")) == 3);
        const std::string err = slurp(dir.file("force.err"));
        CHECK(err.find(holder_text(s0)) != std::string::npos);
        CHECK(err.find(holder_text(s1)) != std::string::npos);
        CHECK(run_build(dem, out, {"--finalize"}, dir.file("finalize.err")) == 3);
        gate.open_gate();
        CHECK(wait_exit(s0) == 0);
        CHECK(wait_exit(s1) == 0);
        CHECK(run_build(dem, out, {"--finalize"}, dir.file("finalize.err")) == 0);
        CHECK(TileStore::open(out)->get_document("terrain", "tileset.json"));
        CHECK_FALSE(std::filesystem::exists(lock_file(out)));
    }
}
