// The directory store: one file per tile and per document, for static hosting.
//   OUT/{layer}/{z}/{x}/{y}.{ext}            ladder eps (eps_level -1); .terrain files hold
//                                            gzip-compressed tiles (get and put see them raw)
//   OUT/{layer}/eps{k}/{z}/{x}/{y}.{ext}     eps variant k
//   OUT/{layer}/{name}                       documents (tileset.json, build-manifest.json, ...)
// A write goes to a hidden temporary file in the target's directory
// (".{file}.tmp-{pid}-{n}"), is fsynced and renamed over the target: rename(2) within one
// directory is atomic, so a reader sees the old file or the new one, never a part.
// Every file has a hidden checksum sidecar ".{file}.crc32" next to it (tiler/stores/checksum.hpp),
// written just before it; a file that does not match its sidecar is damaged and reads as
// missing (with a warning), so it is made again. Paths are opened one directory at a time with
// O_NOFOLLOW: a symbolic link inside the store is never followed, for reading or writing.
#include "core/error.hpp"
#include "tiler/gzip.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/checksum.hpp"
#include "tiler/stores/store.hpp"

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <string>
#include <sys/stat.h>
#include <unistd.h>
#include <utility>
#include <vector>

namespace tb::tiler {
namespace {

namespace fs = std::filesystem;

std::atomic<std::uint64_t> g_temp_counter{0};

// Globe terrain tiles are stored gzip-compressed (what static hosts and CesiumJS expect of a
// .terrain file, sent with Content-Encoding: gzip), at zlib's default level.
constexpr int kTerrainGzipLevel = 6;
// Inflating a stored terrain tile stops past this size, far above any tile's: a damaged or
// hostile file cannot make a read take the memory of a gzip bomb.
constexpr std::size_t kMaxTerrainBytes = std::size_t{256} << 20;

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
    Fd() = default;
    explicit Fd(int f) : fd(f) {}
    Fd(Fd&& o) noexcept : fd(o.fd) { o.fd = -1; }
    Fd& operator=(Fd&& o) noexcept {
        std::swap(fd, o.fd);
        return *this;
    }
    ~Fd() {
        if (fd >= 0) {
            ::close(fd);
        }
    }
};

// A path inside the store, as the directories leading to it and its file name.
struct StorePath {
    std::vector<std::string> dirs; // below the root
    std::string name;
    std::string shown; // root/dirs.../name, for messages
};

std::string sidecar_name(const std::string& name) {
    return "." + name + ".crc32";
}

// Opens the directory `path.dirs` below `root` one part at a time without following a symbolic
// link (O_NOFOLLOW), so nothing outside the root is ever reached, whatever links a store holds.
// With `create`, missing parts are made. Returns an empty Fd when a part is missing (reads), or
// is a link or a file (reads: logged; writes throw IoError).
Fd open_dirs(const std::string& root, const StorePath& path, bool create) {
    Fd dir(::open(root.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
    if (dir.fd < 0) {
        if (!create && (errno == ENOENT || errno == ENOTDIR)) {
            return Fd();
        }
        fail(root, "open the store directory", errno);
    }
    std::string reached = root;
    for (const auto& part : path.dirs) {
        reached += "/" + part;
        if (create && ::mkdirat(dir.fd, part.c_str(), 0755) != 0 && errno != EEXIST) {
            fail(reached, "create directory", errno);
        }
        Fd next(::openat(dir.fd, part.c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC));
        if (next.fd < 0) {
            const int err = errno;
            struct stat st {};
            const bool link = ::fstatat(dir.fd, part.c_str(), &st, AT_SYMLINK_NOFOLLOW) == 0 &&
                              S_ISLNK(st.st_mode);
            if (link) {
                if (create) {
                    throw IoError(reached + ": is a symbolic link; a store never follows links, "
                                            "so remove it");
                }
                log::warn(reached + ": is a symbolic link inside the store; not followed, so " +
                          path.shown + " counts as missing");
                return Fd();
            }
            if (!create && (err == ENOENT || err == ENOTDIR)) {
                return Fd();
            }
            fail(reached, "open directory", err);
        }
        dir = std::move(next);
    }
    return dir;
}

// Writes `bytes` as `name` in the directory `dir` atomically: a temporary file, fsync, rename.
void write_in(const Fd& dir,
              const std::string& name,
              const std::string& shown,
              std::string_view bytes) {
    const std::string temp =
        "." + name + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(++g_temp_counter);
    Fd out(
        ::openat(dir.fd, temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644));
    if (out.fd < 0) {
        fail(shown, "create a temporary file", errno);
    }
    auto abandon = [&](const char* what, int err) {
        ::close(out.fd);
        out.fd = -1;
        ::unlinkat(dir.fd, temp.c_str(), 0);
        fail(shown, what, err);
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
        ::unlinkat(dir.fd, temp.c_str(), 0);
        fail(shown, "write (close)", err);
    }
    // renameat replaces a link at `name` itself, never what it points to.
    if (::renameat(dir.fd, temp.c_str(), dir.fd, name.c_str()) != 0) {
        const int err = errno;
        ::unlinkat(dir.fd, temp.c_str(), 0);
        fail(shown, "rename the temporary file into place", err);
    }
}

// Writes the checksum sidecar, then the file, each atomically. A crash between the two leaves
// a pair that does not match, which reads as damaged and is made again.
void write_verified(const std::string& root, const StorePath& path, std::string_view bytes) {
    const Fd dir = open_dirs(root, path, true);
    write_in(dir, sidecar_name(path.name), path.shown, checksum_sidecar(bytes));
    write_in(dir, path.name, path.shown, bytes);
}

// Removes a file and then its checksum sidecar (a sidecar alone reads as a missing file); a
// file already absent is no error.
void remove_verified(const std::string& root, const StorePath& path) {
    const Fd dir = open_dirs(root, path, false);
    if (dir.fd < 0) {
        return;
    }
    for (const std::string& name : {path.name, sidecar_name(path.name)}) {
        if (::unlinkat(dir.fd, name.c_str(), 0) != 0 && errno != ENOENT) {
            fail(path.shown, "remove", errno);
        }
    }
    // Directories left empty go too (never the layer's own), as a build would not make them.
    for (std::size_t k = path.dirs.size(); k-- > 1;) {
        std::string dir_path = root;
        for (std::size_t i = 0; i <= k; ++i) {
            dir_path += "/" + path.dirs[i];
        }
        if (::rmdir(dir_path.c_str()) != 0) {
            break; // not empty (or already gone): the ones above are not either
        }
    }
}

// The whole file `name` in `dir`, or nullopt when it is absent or a symbolic link (logged).
std::optional<std::string>
read_in(const Fd& dir, const std::string& name, const std::string& shown) {
    Fd in(::openat(dir.fd, name.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC));
    if (in.fd < 0) {
        if (errno == ENOENT || errno == ENOTDIR) {
            return std::nullopt;
        }
        if (errno == ELOOP) {
            log::warn(shown + ": is a symbolic link inside the store; not followed, so it counts "
                              "as missing");
            return std::nullopt;
        }
        fail(shown, "open", errno);
    }
    struct stat st {};
    if (::fstat(in.fd, &st) != 0) {
        fail(shown, "stat", errno);
    }
    if (!S_ISREG(st.st_mode)) {
        throw IoError(shown + ": not a regular file; remove it or choose another output path");
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
            fail(shown, "read", errno);
        }
        if (n == 0) {
            break;
        }
        bytes.append(buffer, static_cast<std::size_t>(n));
    }
    return bytes;
}

// The file's bytes when they match their sidecar checksum; nullopt when absent, and also
// (with a warning) when damaged: empty, truncated, overwritten, flipped, or without a sidecar.
std::optional<std::string> read_verified(const std::string& root, const StorePath& path) {
    const Fd dir = open_dirs(root, path, false);
    if (dir.fd < 0) {
        return std::nullopt;
    }
    auto bytes = read_in(dir, path.name, path.shown);
    if (!bytes) {
        return std::nullopt;
    }
    const auto sidecar = read_in(dir, sidecar_name(path.name), path.shown + " (checksum)");
    if (!sidecar) {
        log::warn(path.shown + ": stored without its checksum file " + sidecar_name(path.name) +
                  " (damaged, or written by an older terrabound); not served, it is made again");
        return std::nullopt;
    }
    if (*sidecar != checksum_sidecar(*bytes)) {
        log::warn(path.shown + ": damaged (" + std::to_string(bytes->size()) +
                  " bytes that do not match their checksum); not served, it is made again");
        return std::nullopt;
    }
    return bytes;
}

// A stored globe terrain tile's bytes: gzip-compressed since they are (the checksum has been
// checked), as they are when an older store kept them raw. A quantized-mesh tile starts with
// the tile centre's ECEF x as a double, so raw bytes that look gzipped but do not inflate are
// taken as they are.
std::optional<std::string> unzip_terrain(const StorePath& path, std::string bytes) {
    if (!looks_gzipped(bytes)) {
        return bytes;
    }
    if (auto tile = gzip_decompress(bytes, kMaxTerrainBytes)) {
        return tile;
    }
    log::warn(path.shown + ": matches its checksum but is not a whole gzip member; served as "
                           "it is stored");
    return bytes;
}

bool is_temp_name(const std::string& name) {
    return name.size() > 1 && name.front() == '.' && name.find(".tmp-") != std::string::npos;
}

class DirectoryStore final : public TileStore {
public:
    explicit DirectoryStore(std::string root) : root_(std::move(root)) {}

    std::optional<std::string> get(const TileKey& key) const override {
        const StorePath path = tile_path(key);
        auto bytes = read_verified(root_, path);
        if (!bytes || key.format != Format::Terrain) {
            return bytes;
        }
        return unzip_terrain(path, std::move(*bytes));
    }

    // A tile counts only when it is whole: --resume re-makes damaged ones.
    bool contains(const TileKey& key) const override { return get(key).has_value(); }

    void put(const TileKey& key, std::string_view bytes) override {
        if (key.format == Format::Terrain) {
            write_verified(root_, tile_path(key), gzip_compress(bytes, kTerrainGzipLevel));
            return;
        }
        write_verified(root_, tile_path(key), bytes);
    }

    std::optional<std::string> get_document(const std::string& layer,
                                            const std::string& name) const override {
        return read_verified(root_, document_path(layer, name));
    }

    void put_document(const std::string& layer,
                      const std::string& name,
                      std::string_view bytes) override {
        write_verified(root_, document_path(layer, name), bytes);
    }

    void remove(const TileKey& key) override { remove_verified(root_, tile_path(key)); }

    void remove_document(const std::string& layer, const std::string& name) override {
        remove_verified(root_, document_path(layer, name));
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
    bool written_by_terrabound_only() const override { return false; }

private:
    StorePath tile_path(const TileKey& key) const {
        validate_key(key);
        StorePath p;
        p.dirs.push_back(key.layer);
        if (key.format == Format::Terrarium) {
            p.dirs.push_back("dem"); // the server's URL without ?encoding
        } else if (key.format == Format::Mapbox) {
            p.dirs.push_back("dem");
            p.dirs.push_back("mapbox");
        }
        if (key.eps_level >= 0) {
            p.dirs.push_back("eps" + std::to_string(key.eps_level));
        }
        if (key.format == Format::Terrain3d) {
            // Beside terrain/tileset.json, as its content URI template says:
            // terrain/{root}/{level}/{x within the root}/{y}.glb.
            const std::int64_t side = std::int64_t{1} << key.id.z;
            p.dirs.push_back("terrain");
            p.dirs.push_back(std::to_string(key.id.x / side));
            p.dirs.push_back(std::to_string(key.id.z));
            p.dirs.push_back(std::to_string(key.id.x % side));
        } else {
            p.dirs.push_back(std::to_string(key.id.z));
            p.dirs.push_back(std::to_string(key.id.x));
        }
        p.name = std::to_string(key.id.y) + "." + extension(key.format);
        p.shown = shown(p);
        return p;
    }

    StorePath document_path(const std::string& layer, const std::string& name) const {
        validate_layer_name(layer);
        validate_document_name(name);
        StorePath p;
        p.dirs.push_back(layer);
        std::size_t start = 0;
        for (std::size_t slash; (slash = name.find('/', start)) != std::string::npos;
             start = slash + 1) {
            p.dirs.push_back(name.substr(start, slash - start));
        }
        p.name = name.substr(start);
        p.shown = shown(p);
        return p;
    }

    std::string shown(const StorePath& p) const {
        std::string s = root_;
        for (const auto& d : p.dirs) {
            s += "/" + d;
        }
        return s + "/" + p.name;
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
    // Only the store directory itself is made: a missing parent is more likely a typo than a
    // wish for a new tree of directories.
    const fs::path parent = fs::path(path).lexically_normal().parent_path();
    if (!parent.empty() && !fs::exists(parent, ec)) {
        throw IoError(path + ": its parent directory " + parent.string() +
                      " does not exist; create it first or choose another output path");
    }
    if (::mkdir(path.c_str(), 0755) != 0 && errno != EEXIST) {
        fail(path, "create directory", errno);
    }
    std::string root = path;
    while (root.size() > 1 && root.back() == '/') {
        root.pop_back();
    }
    return std::make_unique<DirectoryStore>(root);
}

} // namespace tb::tiler
