// Atomic file writes (atomic_file.hpp).
#include "tiler/stores/atomic_file.hpp"

#include "core/error.hpp"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace tb::tiler {

namespace {

std::atomic<unsigned> g_temp_counter{0};

} // namespace

void write_file_atomically(const std::string& path, std::string_view bytes) {
    // Unique per call, so that two writers of one path (threads or processes) never share one.
    const std::string temp = path + ".tmp-" + std::to_string(::getpid()) + "-" +
                             std::to_string(g_temp_counter.fetch_add(1));
    std::FILE* f = std::fopen(temp.c_str(), "wb");
    if (f == nullptr) {
        throw IoError(path + ": cannot create a temporary file next to it (" +
                      std::strerror(errno) + ")");
    }
    int err = 0;
    if (std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size() || std::fflush(f) != 0 ||
        ::fsync(::fileno(f)) != 0) {
        err = errno;
    }
    if (std::fclose(f) != 0 && err == 0) {
        err = errno;
    }
    if (err != 0) {
        std::remove(temp.c_str());
        throw IoError(path + ": write failed (" + std::strerror(err) + ")");
    }
    move_into_place(temp, path);
}

void move_into_place(const std::string& temp, const std::string& path) {
    std::error_code ec;
    std::filesystem::rename(temp, path, ec);
    if (ec) {
        std::remove(temp.c_str());
        throw IoError(path + ": cannot rename the temporary file into place (" + ec.message() +
                      ")");
    }
}

} // namespace tb::tiler
