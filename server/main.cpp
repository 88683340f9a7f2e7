// terrabound: the command-line entry point. Subcommands live in server/cmd_*.cpp.
#include "core/error.hpp"
#include "server/commands.hpp"
#include "tiler/log.hpp"

#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#ifndef TB_VERSION
#define TB_VERSION "0.0.0"
#endif

namespace {

const tb::cli::Command* const* all_commands() {
    static const tb::cli::Command* commands[] = {
        &tb::cli::serve_command(),
        &tb::cli::build_command(),
        &tb::cli::tile_command(),
        &tb::cli::mesh_command(),
        &tb::cli::info_command(),
        nullptr,
    };
    return commands;
}

void print_usage(std::FILE* to) {
    std::fprintf(to,
                 "usage: terrabound COMMAND [ARGS...]\n\n"
                 "Terrain tiles with a guaranteed vertical error, from any DEM GDAL reads.\n\n"
                 "commands:\n");
    for (auto c = all_commands(); *c; ++c) {
        std::fprintf(to, "  %-8s %s\n", (*c)->spec.name.c_str(), (*c)->spec.summary.c_str());
    }
    std::fprintf(to,
                 "\n'terrabound COMMAND --help' describes a command; 'terrabound --version' "
                 "prints the version.\n");
}

} // namespace

int main(int argc, char** argv) {
    std::vector<std::string> words(argv + 1, argv + argc);
    if (words.empty() || words[0] == "--help" || words[0] == "-h" || words[0] == "help") {
        print_usage(words.empty() ? stderr : stdout);
        return words.empty() ? 1 : 0;
    }
    if (words[0] == "--version" || words[0] == "version") {
        std::printf("terrabound %s\n", TB_VERSION);
        return 0;
    }
    const tb::cli::Command* command = nullptr;
    for (auto c = all_commands(); *c; ++c) {
        if ((*c)->spec.name == words[0]) {
            command = *c;
        }
    }
    if (!command) {
        std::fprintf(stderr, "terrabound: unknown command '%s'\n\n", words[0].c_str());
        print_usage(stderr);
        return 1;
    }
    try {
        words.erase(words.begin());
        const tb::cli::Args args = tb::cli::parse(command->spec, words);
        if (args.help) {
            std::fputs(tb::cli::help_text(command->spec).c_str(), stdout);
            return 0;
        }
        return command->run(args);
    } catch (const tb::InputError& e) {
        tb::log::flush();
        std::fprintf(stderr, "terrabound: %s\n", e.what());
        return 2;
    } catch (const tb::NotFound& e) {
        tb::log::flush();
        std::fprintf(stderr, "terrabound: %s\n", e.what());
        return 2;
    } catch (const tb::IoError& e) {
        tb::log::flush();
        std::fprintf(stderr, "terrabound: %s\n", e.what());
        return 3;
    } catch (const std::exception& e) {
        tb::log::flush();
        std::fprintf(stderr, "terrabound: %s\n", e.what());
        return 1;
    }
}
