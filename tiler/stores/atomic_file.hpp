#pragma once
// One file written so that a reader never sees it half-written: a temporary next to it, then a
// rename over it.
#include <string>
#include <string_view>

namespace tb::tiler {

// Writes `bytes` to a temporary file next to `path` (PATH.tmp-PID-N, one per call), fsyncs it,
// then renames it over `path`, so a reader never sees a half-written file and two writers never
// write one temporary file. Throws IoError naming the path.
void write_file_atomically(const std::string& path, std::string_view bytes);
// The last step of such a write: renames the finished `temp` over `path`, removing `temp` and
// throwing IoError naming `path` if that fails.
void move_into_place(const std::string& temp, const std::string& path);

} // namespace tb::tiler
