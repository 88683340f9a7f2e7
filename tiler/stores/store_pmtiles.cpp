// The PMTiles v3 store (OUT.pmtiles): one layer's raster DEM tiles in one encoding, as one
// archive (tiler/stores/pmtiles_format.hpp) that web clients read with range requests.
//
// An archive is written once, so a build stages its tiles and documents in an MBTiles file
// beside it, OUT.pmtiles.staging (tiler/stores/store_mbtiles.hpp): every put is a transaction
// there, so a killed build resumes from it. finish() (the build's end) assembles the archive
// from it (temporary file, fsync, rename) and removes it. While the staging file exists it is
// the truth; otherwise the archive is. The build's documents (build-manifest.json and the like)
// travel in the archive's metadata JSON, under "terrabound", so --resume and serve find them.
//
// A finished archive is read-only: writing a tile or a different document throws IoError (a
// document equal to the one held is accepted, as a resumed build writes its documents again);
// remove_layer (build --force) starts a new staging file that replaces the archive at finish().
#include "core/error.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/pmtiles_format.hpp"
#include "tiler/stores/store.hpp"
#include "tiler/stores/store_mbtiles.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <memory>
#include <mutex>

namespace tb::tiler {
namespace {

// The archive file, read with pread from many threads.
class ArchiveFile {
public:
    explicit ArchiveFile(const std::string& path) : path_(path) {
        fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        struct stat st {};
        if (fd_ < 0 || ::fstat(fd_, &st) != 0) {
            const int err = errno;
            if (fd_ >= 0) {
                ::close(fd_);
            }
            throw IoError(path + ": cannot open (" + std::strerror(err) + ")");
        }
        size_ = static_cast<std::uint64_t>(st.st_size);
    }
    ~ArchiveFile() { ::close(fd_); }
    ArchiveFile(const ArchiveFile&) = delete;
    ArchiveFile& operator=(const ArchiveFile&) = delete;

    std::uint64_t size() const { return size_; }
    std::string read(std::uint64_t offset, std::uint64_t length) const {
        std::string out(length, '\0');
        std::uint64_t done = 0;
        while (done < length) {
            const ssize_t n =
                ::pread(fd_, out.data() + done, length - done, static_cast<off_t>(offset + done));
            if (n < 0 && errno == EINTR) {
                continue;
            }
            if (n <= 0) {
                throw IoError(path_ + ": cannot read " + std::to_string(length) +
                              " bytes at offset " + std::to_string(offset) + " (" +
                              (n < 0 ? std::strerror(errno) : "the file is shorter") + ")");
            }
            done += static_cast<std::uint64_t>(n);
        }
        return out;
    }

private:
    std::string path_;
    int fd_ = -1;
    std::uint64_t size_ = 0;
};

class PmtilesStore final : public TileStore {
public:
    explicit PmtilesStore(std::string path)
        : path_(std::move(path)), staging_path_(path_ + ".staging") {
        std::error_code ec;
        if (std::filesystem::exists(staging_path_, ec)) {
            staging_ = open_staging();
        } else if (std::filesystem::exists(path_, ec)) {
            open_archive();
        }
    }

    std::optional<std::string> get(const TileKey& key) const override {
        validate_key(key);
        std::lock_guard lock(mutex_);
        if (staging_) {
            return staging_->get(key);
        }
        if (!reader_ || key.layer != reader_->content().layer ||
            reader_->content().encoding != format_name(key.format)) {
            return std::nullopt;
        }
        return reader_->tile(key.id);
    }
    bool contains(const TileKey& key) const override { return get(key).has_value(); }
    bool keeps(const TileKey& key) const override {
        std::lock_guard lock(mutex_);
        return staging_ && staging_->keeps(key);
    }

    void put(const TileKey& key, std::string_view bytes) override {
        writable("write tile " + std::to_string(key.id.z) + "/" + std::to_string(key.id.x) + "/" +
                 std::to_string(key.id.y))
            .put(key, bytes);
    }
    void put_batch(std::span<const StoredTile> tiles) override {
        writable("write " + std::to_string(tiles.size()) + " tiles").put_batch(tiles);
    }

    std::optional<std::string> get_document(const std::string& layer,
                                            const std::string& name) const override {
        validate_layer_name(layer);
        validate_document_name(name);
        std::lock_guard lock(mutex_);
        if (staging_) {
            return staging_->get_document(layer, name);
        }
        if (!reader_ || reader_->content().layer != layer) {
            return std::nullopt;
        }
        const auto& docs = reader_->content().documents;
        const auto it = docs.find(name);
        return it == docs.end() ? std::nullopt : std::optional<std::string>(it->second);
    }

    void put_document(const std::string& layer,
                      const std::string& name,
                      std::string_view bytes) override {
        if (get_document(layer, name) == bytes && !has_staging()) {
            return; // a resumed build writing what the finished archive holds
        }
        writable("write document " + name).put_document(layer, name, bytes);
    }

    bool has_layer(const std::string& layer) const override {
        validate_layer_name(layer);
        std::lock_guard lock(mutex_);
        if (staging_) {
            return staging_->has_layer(layer);
        }
        return reader_ && reader_->content().layer == layer &&
               (reader_->header().addressed_tiles > 0 || !reader_->content().documents.empty());
    }

    // build --force: a new, empty staging file, which replaces the archive at finish().
    void remove_layer(const std::string& layer) override {
        validate_layer_name(layer);
        std::lock_guard lock(mutex_);
        if (staging_) {
            staging_->remove_layer(layer);
        } else if (reader_ && reader_->content().layer == layer) {
            staging_ = open_staging();
        }
    }

    void clean_up(const std::string& layer) override { validate_layer_name(layer); }

    void finish() override;

    std::string describe() const override { return "pmtiles " + path_; }
    bool written_by_terrabound_only() const override { return true; }

private:
    std::unique_ptr<MbtilesStore> open_staging() const {
        return std::make_unique<MbtilesStore>(staging_path_, path_, "PMTiles");
    }

    void open_archive() {
        archive_ = std::make_unique<ArchiveFile>(path_);
        const ArchiveFile* file = archive_.get();
        reader_ = std::make_unique<pmtiles::Reader>(
            path_, file->size(), [file](std::uint64_t offset, std::uint64_t length) {
                return file->read(offset, length);
            });
    }

    bool has_staging() const {
        std::lock_guard lock(mutex_);
        return staging_ != nullptr;
    }

    // The staging store, made now for an output with no archive yet; IoError for a finished
    // archive, which is read-only.
    MbtilesStore& writable(const std::string& action) {
        std::lock_guard lock(mutex_);
        if (!staging_ && reader_) {
            throw IoError(path_ + ": cannot " + action +
                          ": a finished PMTiles archive is read-only; rebuild it with terrabound "
                          "build --force (tiles made by serve are kept in memory only)");
        }
        if (!staging_) {
            staging_ = open_staging();
        }
        return *staging_;
    }

    std::string path_, staging_path_;
    mutable std::mutex mutex_;
    std::unique_ptr<MbtilesStore> staging_;
    std::unique_ptr<ArchiveFile> archive_;
    std::unique_ptr<pmtiles::Reader> reader_;
};

// Assembles the archive from the staging file, then removes the staging file: from then on the
// archive is the truth. A crash before the rename leaves the staging file for --resume.
void PmtilesStore::finish() {
    std::lock_guard lock(mutex_);
    if (!staging_) {
        return;
    }
    pmtiles::ArchiveContent content;
    content.layer = staging_->layer();
    const auto format = staging_->format();
    content.encoding = format ? format_name(*format) : "";
    content.documents = staging_->documents();
    std::vector<pmtiles::PlannedTile> tiles;
    std::uint64_t bytes = 0;
    staging_->for_each_tile([&](const TileId& id, const std::string& data) {
        pmtiles::PlannedTile t;
        t.id = id;
        t.tile_id = pmtiles::tile_id(id);
        pmtiles::hash_tile(data, t);
        bytes += data.size();
        tiles.push_back(t);
    });
    const std::size_t count = tiles.size();
    pmtiles::write_archive(path_, std::move(tiles), content, [&](const TileId& id) {
        return staging_->get(TileKey{content.layer, id, *format, -1}).value_or(std::string());
    });
    staging_.reset();
    for (const char* suffix : {"", "-wal", "-shm"}) {
        std::error_code ec;
        std::filesystem::remove(staging_path_ + suffix, ec);
    }
    reader_.reset();
    archive_.reset();
    open_archive();
    log::info("pmtiles: wrote " + path_ + ", " + std::to_string(count) + " tiles (" +
              std::to_string(reader_->header().tile_contents) + " distinct), " +
              std::to_string(archive_->size()) + " bytes");
}

} // namespace

std::unique_ptr<TileStore> open_pmtiles_store(const std::string& path) {
    return std::make_unique<PmtilesStore>(path);
}

} // namespace tb::tiler
