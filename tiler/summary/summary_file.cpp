// The DEM summary on disk: key, atomic write, verified read (see summary_file.hpp).
#include "tiler/summary/summary_file.hpp"

#include "core/error.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/atomic_file.hpp"
#include "tiler/stores/checksum.hpp"

#include <sys/stat.h>

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>

namespace tb::tiler {
namespace {

constexpr char kMagic[8] = {'T', 'B', 'S', 'U', 'M', 'M', '0', '1'};
constexpr std::size_t kBlockBytes = 5 * sizeof(float);

// FNV-1a, 64 bits: names the file; the key inside it is what is trusted.
std::uint64_t fnv1a(const std::string& text) {
    std::uint64_t h = 1469598103934665603ULL;
    for (const unsigned char c : text) {
        h = (h ^ c) * 1099511628211ULL;
    }
    return h;
}

template <typename T> void put(std::string& out, T value) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    out.append(bytes, sizeof(T));
}

// Reads a T at `at` and advances; false when the bytes run out.
template <typename T> bool take(const std::string& in, std::size_t& at, T& value) {
    if (in.size() - at < sizeof(T)) {
        return false;
    }
    std::memcpy(&value, in.data() + at, sizeof(T));
    at += sizeof(T);
    return true;
}

std::string encode(const std::string& key, const DemSummary& summary) {
    std::string out(kMagic, sizeof(kMagic));
    put(out, static_cast<std::uint32_t>(key.size()));
    out += key;
    put(out, static_cast<std::int32_t>(summary.width()));
    put(out, static_cast<std::int32_t>(summary.height()));
    put(out, static_cast<std::uint32_t>(summary.levels().size()));
    for (const auto& level : summary.levels()) {
        put(out, static_cast<std::uint64_t>(level.size()));
        for (const SummaryBlock& b : level) {
            for (const float f : {b.height, b.per_column, b.per_row, b.low, b.high}) {
                put(out, f);
            }
        }
    }
    put(out, store_checksum(out));
    return out;
}

// The levels after the header, or a description of what is wrong.
std::optional<DemSummary> decode_levels(const std::string& in, std::size_t at, std::string& why) {
    std::int32_t width = 0, height = 0;
    std::uint32_t count = 0;
    if (!take(in, at, width) || !take(in, at, height) || !take(in, at, count) || count > 64) {
        why = "its header is cut short or damaged";
        return std::nullopt;
    }
    std::vector<std::vector<SummaryBlock>> levels(count);
    for (auto& level : levels) {
        std::uint64_t blocks = 0;
        if (!take(in, at, blocks) || blocks > (in.size() - at) / kBlockBytes) {
            why = "it is cut short";
            return std::nullopt;
        }
        level.resize(static_cast<std::size_t>(blocks));
        for (SummaryBlock& b : level) {
            take(in, at, b.height), take(in, at, b.per_column), take(in, at, b.per_row);
            take(in, at, b.low), take(in, at, b.high);
        }
    }
    if (at != in.size()) {
        why = "it holds bytes after its last level";
        return std::nullopt;
    }
    auto summary = DemSummary::from_levels(width, height, std::move(levels));
    if (!summary) {
        why = "its levels do not fit its size";
    }
    return summary;
}

} // namespace

std::optional<std::string> summary_key(const std::vector<std::string>& sources,
                                       std::optional<double> nodata,
                                       VerticalDatum datum,
                                       const PixelPlace& place,
                                       const ValidRange& range) {
    std::ostringstream key;
    key.precision(17);
    // 2: heights in feet read as metres (DemInfo::metres_per_unit), so a summary made before
    // of such a DEM holds feet.
    key << "terrabound summary 2";
    for (const std::string& source : sources) {
        std::error_code ec;
        const auto path = std::filesystem::absolute(source, ec);
        struct stat st {};
        if (ec || ::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) {
            return std::nullopt;
        }
        key << "\nsource " << path.string() << " " << st.st_size << " "
            << st.st_mtim.tv_sec * 1000000000LL + st.st_mtim.tv_nsec;
    }
    key << "\nnodata " << (nodata ? std::to_string(*nodata) : "file");
    key << "\ndatum " << static_cast<int>(datum);
    if (!range.is_default()) {
        key << "\nvalid " << range.low << " " << range.high;
    }
    key << "\ngrid " << place.key();
    return key.str();
}

std::filesystem::path summary_path(const std::filesystem::path& dir,
                                   const std::string& first_source,
                                   const std::string& key) {
    std::string stem = std::filesystem::path(first_source).stem().string();
    for (char& c : stem) {
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') {
            c = '_';
        }
    }
    char hash[17];
    std::snprintf(hash, sizeof(hash), "%016llx", static_cast<unsigned long long>(fnv1a(key)));
    return dir / (stem.substr(0, 64) + "-" + hash + ".tbsum");
}

std::optional<DemSummary> load_summary(const std::filesystem::path& path, const std::string& key) {
    std::ifstream file(path, std::ios::binary);
    if (!file) {
        return std::nullopt;
    }
    const std::string in((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
    std::string why;
    std::uint32_t key_size = 0, crc = 0;
    std::size_t at = sizeof(kMagic);
    if (in.size() < sizeof(kMagic) + 8 || std::memcmp(in.data(), kMagic, sizeof(kMagic)) != 0) {
        why = "it is not a Terrabound summary (or is cut short)";
    } else if (std::memcpy(&crc, in.data() + in.size() - 4, 4),
               crc != store_checksum(std::string_view(in).substr(0, in.size() - 4))) {
        why = "its checksum does not match (damaged or cut short)";
    } else if (!take(in, at, key_size) || in.compare(at, key_size, key) != 0 ||
               key_size != key.size()) {
        why = "it was made from other sources or settings";
    } else {
        auto summary = decode_levels(in.substr(0, in.size() - 4), at + key_size, why);
        if (summary) {
            log::info(path.string() + ": summary read from disk");
            return summary;
        }
    }
    log::warn(path.string() + ": not used, " + why + "; making the summary again");
    return std::nullopt;
}

void remove_stale_temporaries(const std::filesystem::path& dir) {
    namespace fs = std::filesystem;
    const auto now = fs::file_time_type::clock::now();
    std::size_t removed = 0;
    std::error_code ec;
    for (auto it = fs::directory_iterator(dir, ec); !ec && it != fs::directory_iterator();
         it.increment(ec)) {
        std::error_code e;
        const std::string name = it->path().filename().string();
        if (name.find(".tbsum.tmp-") == std::string::npos || !it->is_regular_file(e) ||
            now - fs::last_write_time(it->path(), e) < kStaleTemporaryAge || e) {
            continue;
        }
        removed += fs::remove(it->path(), e) ? 1 : 0;
    }
    if (removed > 0) {
        log::info(dir.string() + ": removed " + std::to_string(removed) +
                  " summary file(s) a killed process left half-written");
    }
}

void save_summary(const std::filesystem::path& path,
                  const std::string& key,
                  const DemSummary& summary) {
    const std::string bytes = encode(key, summary);
    std::error_code ec;
    std::filesystem::create_directories(path.parent_path(), ec);
    remove_stale_temporaries(path.parent_path());
    const auto space = std::filesystem::space(path.parent_path(), ec);
    if (!ec && space.available < bytes.size() * 2) {
        log::warn(path.string() + ": not saved, the disk has " +
                  std::to_string(space.available >> 20) + " MiB free for " +
                  std::to_string(bytes.size() >> 20) + " MiB; it will be made again next time");
        return;
    }
    try {
        write_file_atomically(path.string(), bytes);
    } catch (const IoError& e) {
        log::warn(std::string(e.what()) +
                  "; the summary will be made again next time (set summary_dir to a writable "
                  "directory, or \"off\")");
        return;
    }
    log::info(path.string() + ": summary saved (" + std::to_string(bytes.size() >> 10) + " KiB)");
}

std::optional<std::filesystem::path> default_summary_dir() {
    if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg != nullptr && *xdg == '/') {
        return std::filesystem::path(xdg) / "terrabound";
    }
    if (const char* home = std::getenv("HOME"); home != nullptr && *home == '/') {
        return std::filesystem::path(home) / ".cache" / "terrabound";
    }
    return std::nullopt;
}

std::optional<std::filesystem::path> summary_dir_for(const std::string& setting,
                                                     std::int64_t pixels) {
    if (setting == "off") {
        return std::nullopt;
    }
    if (!setting.empty()) {
        return std::filesystem::path(setting);
    }
    return pixels >= kSummaryFilePixels ? default_summary_dir() : std::nullopt;
}

} // namespace tb::tiler
