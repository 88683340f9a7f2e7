// terrabound tile: not available yet.
#include "server/commands.hpp"

#include <cstdio>

namespace tb::cli {
namespace {

int run(const Args&) {
    std::fprintf(stderr, "terrabound tile: not implemented yet; it arrives with the tiler (issue 4)\n");
    return 1;
}

}  // namespace

const Command& tile_command() {
    static const Command command{{"tile", "INPUT Z X Y -o OUT", "Make one tile (tile raster, mesh, or encoded tile) to a file.", {}, ""}, run};
    return command;
}

}  // namespace tb::cli
