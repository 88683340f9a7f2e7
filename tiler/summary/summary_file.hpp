#pragma once
// The DEM summary on disk (dem_summary.hpp), so that serve, build and tile make it once per
// source instead of once per process: DIR/{first source's name}-{16 hex digits}.tbsum.
//
// The file's name and its first record hold a key made of everything the summary depends on:
// each source's absolute path, size and modification time (nanoseconds), the nodata override,
// the vertical datum, where the pixels lie (PixelPlace::key) and the format's version. A changed
// source gives a new key, so a stale summary is never read: its file is simply not the one looked
// for (or, on a hash collision, its key does not match). The file ends with a CRC-32 of everything
// before it; a damaged, truncated or foreign file is reported and made again.
//
// Layout (little-endian, as written by the machines Terrabound runs on): "TBSUMM01", u32 key
// size, the key, i32 width, i32 height, u32 level count, per level a u64 block count and its
// blocks (5 float32 each: height, per_column, per_row, low, high), then u32 CRC-32.
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/summary/dem_summary.hpp"

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace tb::tiler {

// Sources at least this large keep their summary on disk by default (smaller ones are made in
// well under a second; their files would only litter the directory).
inline constexpr std::int64_t kSummaryFilePixels = std::int64_t{16} << 20;

// The key of a summary of `sources` (nullopt when one of them is not a local file whose size
// and time can be read, such as /vsicurl/: such a summary is not kept).
std::optional<std::string> summary_key(const std::vector<std::string>& sources,
                                       std::optional<double> nodata,
                                       VerticalDatum datum,
                                       const PixelPlace& place,
                                       const ValidRange& range = {});

// DIR/{stem of the first source}-{hash of key}.tbsum
std::filesystem::path summary_path(const std::filesystem::path& dir,
                                   const std::string& first_source,
                                   const std::string& key);

// The summary stored at `path` under `key`; nullopt when there is none, and nullopt with a
// warning naming the problem when the file is damaged, truncated or holds another key.
std::optional<DemSummary> load_summary(const std::filesystem::path& path, const std::string& key);

// Writes the summary atomically (a temporary file of this process, then a rename), so that
// readers and other writers never see half a file. A failure (no space, no permission) is a
// warning: the summary in memory serves this process all the same.
void save_summary(const std::filesystem::path& path,
                  const std::string& key,
                  const DemSummary& summary);

// Temporary summary files (*.tbsum.tmp-PID-N) this old are left by a killed process: no write
// of a summary takes an hour.
inline constexpr std::chrono::hours kStaleTemporaryAge{1};

// Removes the temporary summary files in `dir` older than kStaleTemporaryAge (save_summary
// calls it), logging how many; errors are ignored (the next save tries again).
void remove_stale_temporaries(const std::filesystem::path& dir);

// $XDG_CACHE_HOME/terrabound, else $HOME/.cache/terrabound; nullopt when neither is set.
std::optional<std::filesystem::path> default_summary_dir();

// Where a layer keeps its summary: nowhere for "off"; `setting` when given; else the default
// directory for sources of at least kSummaryFilePixels.
std::optional<std::filesystem::path> summary_dir_for(const std::string& setting,
                                                     std::int64_t pixels);

} // namespace tb::tiler
