#pragma once
// `terrabound` (TB_BINARY) as a child process of a server test: started with its stderr in a
// log file, its port read from the startup line, killed when the test ends.
#include "server_fixture.hpp"

#include <doctest/doctest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <regex>
#include <string>
#include <vector>

namespace tb::test {

struct Child {
    pid_t pid = -1;
    ~Child() {
        if (pid > 0) {
            kill(pid, SIGKILL);
            waitpid(pid, nullptr, 0);
        }
    }
    int wait_exit() {
        int status = 0;
        waitpid(pid, &status, 0);
        pid = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    }
};

// Starts `terrabound ARGS...` with stderr to `log`.
inline void spawn(Child& child, std::vector<std::string> args, const std::string& log) {
    args.insert(args.begin(), TB_BINARY);
    child.pid = fork();
    REQUIRE(child.pid >= 0);
    if (child.pid == 0) {
        const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        dup2(fd, 2);
        std::vector<char*> argv;
        for (auto& a : args) {
            argv.push_back(a.data());
        }
        argv.push_back(nullptr);
        execv(TB_BINARY, argv.data());
        _exit(127);
    }
}

// Starts TB_BINARY serve ARGS... --port 0 with stderr to `log`; returns the port from its
// startup line.
inline int start_server(Child& child, std::vector<std::string> args, const std::string& log) {
    args.insert(args.begin(), "serve");
    args.insert(args.end(), {"--port", "0"});
    spawn(child, args, log);
    const std::regex serving(R"(serving http://127\.0\.0\.1:(\d+)/)");
    for (int i = 0; i < 1000; ++i) {
        std::smatch m;
        const std::string text = test::read_file(log);
        if (std::regex_search(text, m, serving)) {
            return std::stoi(m[1].str());
        }
        int status = 0;
        if (waitpid(child.pid, &status, WNOHANG) == child.pid) {
            child.pid = -1;
            FAIL("terrabound serve exited early: " << text);
        }
        usleep(10000);
    }
    FAIL("terrabound serve did not start: " << test::read_file(log));
    return -1;
}

// Runs `terrabound ARGS...` to its end with stderr to `log`; returns its exit code.
inline int run_to_exit(const std::vector<std::string>& args, const std::string& log) {
    Child child;
    spawn(child, args, log);
    return child.wait_exit();
}

} // namespace tb::test
