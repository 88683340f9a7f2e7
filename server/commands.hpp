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

const Command& serve_command();
const Command& build_command();
const Command& tile_command();
const Command& mesh_command();
const Command& info_command();

} // namespace tb::cli
