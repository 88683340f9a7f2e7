#pragma once
// The subcommands of `terrabound`, one file each (server/cmd_NAME.cpp).
#include "server/cli.hpp"

#include <string>
#include <vector>

namespace tb::cli {

struct Command {
    CommandSpec spec;
    int (*run)(const Args& args); // returns the exit code; throws tb::Error on failure
};

// --summary-dir, as serve, build, tile and info take it (LayerOptions::summary_dir).
inline constexpr const char* kSummaryDirHelp =
    "where the DEM's multi-resolution summary is kept between runs, or 'off' (default: "
    "$XDG_CACHE_HOME/terrabound or ~/.cache/terrabound, for DEMs of 16 Mpixel and more)";

// --valid-range, as serve, build, tile and info take it (LayerOptions::valid_range).
inline constexpr const char* kValidRangeHelp =
    "heights outside MIN,MAX metres count as nodata (default -12000,9000)";

// --priority, as serve, build, tile and info take it (LayerOptions::priority).
inline constexpr const char* kPriorityHelp =
    "where DEMs overlap: 'finest' (default) lets the finer one win, 'listed' the first given; "
    "the others fill its voids";

const Command& serve_command();
const Command& build_command();
const Command& tile_command();
const Command& mesh_command();
const Command& info_command();

} // namespace tb::cli
