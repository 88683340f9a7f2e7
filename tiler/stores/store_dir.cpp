// The directory store: one file per tile and per document, for static hosting.
//   OUT/{layer}/{z}/{x}/{y}.{ext}            ladder eps (eps_level -1)
//   OUT/{layer}/eps{k}/{z}/{x}/{y}.{ext}     eps variant k
//   OUT/{layer}/{name}                       documents (tileset.json, build-manifest.json, ...)
// A write goes to a hidden temporary file in the target's directory
// (".{file}.tmp-{pid}-{n}"), is fsynced and renamed over the target: rename(2) within one
// directory is atomic, so a reader sees the old file or the new one, never a part.
#include "core/error.hpp"
#include "tiler/stores/store.hpp"

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <string>
#include <sys/stat.h>
#include <unistd.h>

namespace tb::tiler {
namespace {

namespace fs = std::filesystem;

std::atomic<std::uint64_t> g_temp_counter{0};

// What to do about a failed write, by errno.
std::string advice(int err) {
    switch (err) {
    case ENOSPC:
    case EDQUOT:
        return "the disk is full; free space and try again";
    case EACCES:
    case EPERM:
        return "permission denied; fix the permissions or choose another output path";
    case EROFS:
        return "the file system is read-only; choose another output path";
    case ENOTDIR:
        return "a part of the path is a file, not a directory; choose another output path";
    default:
        return "check the disk and the path, then try again";
    }
}

[[noreturn]] void fail(const std::string& path, const char* what, int err) {
    throw IoError(path + ": cannot " + what + " (" + std::strerror(err) + "); " + advice(err));
}

struct Fd {
    int fd = -1;
    ~Fd() {
        if (fd >= 0) {
            ::close(fd);
        }
    }
};

// Writes `bytes` to `path` atomically. Parent directories are created as needed.
void write_atomic(const std::string& path, std::string_view bytes) {
    const fs::path target(path);
    std::error_code ec;
    fs::create_directories(target.parent_path(), ec);
    if (ec) {
        fail(target.parent_path().string(), "create directory", ec.value());
    }
    const std::string temp = (target.parent_path() /
                              ("." + target.filename().string() + ".tmp-" +
                               std::to_string(::getpid()) + "-" + std::to_string(++g_temp_counter)))
                                 .string();
    Fd out;
    out.fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (out.fd < 0) {
        fail(path, "create a temporary file", errno);
    }
    auto abandon = [&](const char* what, int err) {
        ::close(out.fd);
        out.fd = -1;
        ::unlink(temp.c_str());
        fail(path, what, err);
    };
    const char* p = bytes.data();
    std::size_t left = bytes.size();
    while (left > 0) {
        const ssize_t n = ::write(out.fd, p, left);
        if (n < 0) {
            if (errno == EINTR) {
                continue;
            }
            abandon("write", errno);
        }
        p += n;
        left -= static_cast<std::size_t>(n);
    }
    if (::fsync(out.fd) != 0) {
        abandon("write (fsync)", errno);
    }
    const int fd = out.fd;
    out.fd = -1;
    if (::close(fd) != 0) {
        const int err = errno;
        ::unlink(temp.c_str());
        fail(path, "write (close)", err);
    }
    if (::rename(temp.c_str(), path.c_str()) != 0) {
        const int err = errno;
        ::unlink(temp.c_str());
        fail(path, "rename the temporary file into place", err);
    }
}

std::optional<std::string> read_file(const std::string& path) {
    Fd in;
    in.fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (in.fd < 0) {
        if (errno == ENOENT || errno == ENOTDIR) {
            return std::nullopt;
        }
        fail(path, "open", errno);
    }
    struct stat st {};
    if (::fstat(in.fd, &st) != 0) {
        fail(path, "stat", errno);
    }
    if (!S_ISREG(st.st_mode)) {
        throw IoError(path + ": not a regular file; remove it or choose another output path");
    }
    std::string bytes;
    bytes.reserve(static_cast<std::size_t>(st.st_size));
    char buffer[65536];
    for (;;) {
        const ssize_t n = ::read(in.fd, buffer, sizeof buffer);
        if (n < 0) {
            if (errno == EINTR) {
                continue;
            }
            fail(path, "read", errno);
        }
        if (n == 0) {
            break;
        }
        bytes.append(buffer, static_cast<std::size_t>(n));
    }
    return bytes;
}

bool is_temp_name(const std::string& name) {
    return name.size() > 1 && name.front() == '.' && name.find(".tmp-") != std::string::npos;
}

class DirectoryStore final : public TileStore {
public:
    explicit DirectoryStore(std::string root) : root_(std::move(root)) {}

    std::optional<std::string> get(const TileKey& key) const override {
        return read_file(tile_path(key));
    }

    bool contains(const TileKey& key) const override {
        struct stat st {};
        const std::string path = tile_path(key);
        if (::stat(path.c_str(), &st) == 0) {
            return S_ISREG(st.st_mode);
        }
        if (errno == ENOENT || errno == ENOTDIR) {
            return false;
        }
        fail(path, "stat", errno);
    }

    void put(const TileKey& key, std::string_view bytes) override {
        write_atomic(tile_path(key), bytes);
    }

    std::optional<std::string> get_document(const std::string& layer,
                                            const std::string& name) const override {
        return read_file(document_path(layer, name));
    }

    void put_document(const std::string& layer,
                      const std::string& name,
                      std::string_view bytes) override {
        write_atomic(document_path(layer, name), bytes);
    }

    bool has_layer(const std::string& layer) const override {
        validate_layer_name(layer);
        std::error_code ec;
        const fs::path dir = fs::path(root_) / layer;
        if (!fs::exists(dir, ec)) {
            return false;
        }
        return !fs::is_directory(dir, ec) || !fs::is_empty(dir, ec);
    }

    void remove_layer(const std::string& layer) override {
        validate_layer_name(layer);
        std::error_code ec;
        fs::remove_all(fs::path(root_) / layer, ec);
        if (ec) {
            fail((fs::path(root_) / layer).string(), "remove", ec.value());
        }
    }

    void clean_up(const std::string& layer) override {
        validate_layer_name(layer);
        const fs::path dir = fs::path(root_) / layer;
        std::error_code ec;
        if (!fs::is_directory(dir, ec)) {
            return;
        }
        for (auto it = fs::recursive_directory_iterator(dir, ec);
             !ec && it != fs::recursive_directory_iterator();
             it.increment(ec)) {
            if (it->is_regular_file(ec) && is_temp_name(it->path().filename().string())) {
                std::error_code ignored;
                fs::remove(it->path(), ignored);
            }
        }
        if (ec) {
            fail(dir.string(), "scan for temporary files", ec.value());
        }
    }

    std::string describe() const override { return "directory " + root_; }

private:
    std::string tile_path(const TileKey& key) const {
        validate_key(key);
        std::string path = root_ + "/" + key.layer + "/";
        if (key.format == Format::Terrarium) {
            path += "dem/"; // the server's URL without ?encoding
        } else if (key.format == Format::Mapbox) {
            path += "dem/mapbox/";
        }
        if (key.eps_level >= 0) {
            path += "eps" + std::to_string(key.eps_level) + "/";
        }
        path += std::to_string(key.id.z) + "/" + std::to_string(key.id.x) + "/" +
                std::to_string(key.id.y) + "." + extension(key.format);
        return path;
    }

    std::string document_path(const std::string& layer, const std::string& name) const {
        validate_layer_name(layer);
        validate_document_name(name);
        return root_ + "/" + layer + "/" + name;
    }

    std::string root_;
};

} // namespace

std::unique_ptr<TileStore> open_directory_store(const std::string& path) {
    std::error_code ec;
    if (fs::exists(path, ec) && !fs::is_directory(path, ec)) {
        throw IoError(path + ": exists and is not a directory; choose another output path (a "
                             "path ending in .sqlite makes an SQLite store)");
    }
    fs::create_directories(path, ec);
    if (ec) {
        fail(path, "create directory", ec.value());
    }
    std::string root = path;
    while (root.size() > 1 && root.back() == '/') {
        root.pop_back();
    }
    return std::make_unique<DirectoryStore>(root);
}

} // namespace tb::tiler
