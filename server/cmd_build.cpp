// terrabound build: not available yet.
#include "server/commands.hpp"

#include <cstdio>

namespace tb::cli {
namespace {

int run(const Args&) {
    std::fprintf(stderr, "terrabound build: not implemented yet; it arrives with the offline pyramid (issue 5)\n");
    return 1;
}

}  // namespace

const Command& build_command() {
    static const Command command{{"build", "build INPUT... -o OUT", "Pre-generate a tile pyramid into a directory or an SQLite file.", {}, ""}, run};
    return command;
}

}  // namespace tb::cli
