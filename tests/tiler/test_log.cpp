// The logger: queued lines (the HTTP access log) come out whole, in order, and before any
// later direct line; flush() writes them at once. Checked on stderr itself, redirected to a
// file for the test.
#include <doctest/doctest.h>

#include "tiler/log.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

// Sends stderr to a temporary file while alive; text() reads what was written so far.
class StderrToFile {
public:
    StderrToFile() {
        std::random_device rd;
        path_ = std::filesystem::temp_directory_path() /
                ("tb_log_test_" + std::to_string(rd()) + ".txt");
        std::fflush(stderr);
        saved_ = dup(2);
        const int fd = open(path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        REQUIRE(fd >= 0);
        REQUIRE(dup2(fd, 2) == 2);
        close(fd);
    }
    ~StderrToFile() {
        std::fflush(stderr);
        dup2(saved_, 2);
        close(saved_);
        std::error_code ec;
        std::filesystem::remove(path_, ec);
    }
    StderrToFile(const StderrToFile&) = delete;
    StderrToFile& operator=(const StderrToFile&) = delete;

    std::string text() const {
        std::ifstream in(path_);
        std::ostringstream s;
        s << in.rdbuf();
        return s.str();
    }

private:
    std::filesystem::path path_;
    int saved_ = -1;
};

std::vector<std::string> lines_of(const std::string& text) {
    std::vector<std::string> out;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) {
        out.push_back(line);
    }
    return out;
}

} // namespace

TEST_CASE("queued log lines come out whole and in order, before any later direct line") {
    namespace log = tb::log;
    const log::Level before = log::level();
    log::set_level(log::Level::Info);
    {
        StderrToFile capture;
        // Four threads queue 500 lines each while the main thread writes directly.
        std::vector<std::thread> threads;
        for (int t = 0; t < 4; ++t) {
            threads.emplace_back([t] {
                for (int i = 0; i < 500; ++i) {
                    log::write_queued(log::Level::Info,
                                      "queued " + std::to_string(t) + " " + std::to_string(i));
                }
            });
        }
        for (auto& th : threads) {
            th.join();
        }
        log::write_queued(log::Level::Debug, "below the level");
        log::write_queued(log::Level::Info, "last queued\nwith a newline");
        log::warn("direct");
        const auto lines = lines_of(capture.text());
        REQUIRE(lines.size() == 2002);
        std::vector<int> next(4, 0);
        for (std::size_t k = 0; k + 2 < lines.size(); ++k) {
            INFO(lines[k]);
            REQUIRE(lines[k].find(" info  queued ") != std::string::npos);
            std::istringstream fields(lines[k].substr(lines[k].find("queued ") + 7));
            int t = -1, i = -1;
            fields >> t >> i;
            REQUIRE(t >= 0);
            REQUIRE(t < 4);
            CHECK(i == next[static_cast<std::size_t>(t)]); // each thread's lines in its order
            ++next[static_cast<std::size_t>(t)];
        }
        CHECK(lines[2000].find(" info  last queued with a newline") != std::string::npos);
        CHECK(lines[2001].find(" warn  direct") != std::string::npos);

        log::write_queued(log::Level::Info, "flushed");
        log::flush();
        const auto after = lines_of(capture.text());
        REQUIRE(after.size() == 2003);
        CHECK(after.back().find(" info  flushed") != std::string::npos);
    }
    log::set_level(before);
}
