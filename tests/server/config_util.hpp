#pragma once
// Helpers of the config tests: the error parse_config gives, and a command's exit code and output.
#include "config/config.hpp"
#include "core/error.hpp"

#include <doctest/doctest.h>

#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace tb::test {

// The message of the InputError parse_config throws, or "" when it parses.
inline std::string config_error(const std::string& text, const std::string& path) {
    try {
        tb::config::parse_config(text, path);
    } catch (const tb::InputError& e) {
        return e.what();
    }
    return "";
}

// Runs a shell command, returns its exit code and fills `output` with stdout+stderr.
inline int run_command(const std::string& command, std::string& output) {
    output.clear();
    FILE* pipe = popen((command + " 2>&1").c_str(), "r");
    REQUIRE(pipe);
    char buf[4096];
    std::size_t n = 0;
    while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) {
        output.append(buf, n);
    }
    const int status = pclose(pipe);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

} // namespace tb::test
