// Atomic file writes (atomic_file.hpp).
#include "tiler/stores/atomic_file.hpp"

#include "core/error.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace tb::tiler {

void write_file_atomically(const std::string& path, std::string_view bytes) {
    const std::string temp = path + ".tmp" + std::to_string(::getpid());
    {
        std::ofstream out(temp, std::ios::binary | std::ios::trunc);
        if (!out) {
            throw IoError(path + ": cannot create a temporary file next to it (" +
                          std::strerror(errno) + ")");
        }
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
        out.flush();
        if (!out) {
            std::remove(temp.c_str());
            throw IoError(path + ": write failed (" + std::strerror(errno) + ")");
        }
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
