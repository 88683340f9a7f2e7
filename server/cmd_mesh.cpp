// terrabound mesh: not available yet.
#include "server/commands.hpp"

#include <cstdio>

namespace tb::cli {
namespace {

int run(const Args&) {
    std::fprintf(stderr, "terrabound mesh: not implemented yet; it arrives with the core mesher (issue 3)\n");
    return 1;
}

}  // namespace

const Command& mesh_command() {
    static const Command command{{"mesh", "INPUT --eps E -o OUT.{obj,json}", "Mesh one raster with a guaranteed vertical error.", {}, ""}, run};
    return command;
}

}  // namespace tb::cli
