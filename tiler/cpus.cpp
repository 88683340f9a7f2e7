#include "tiler/cpus.hpp"

#include <sched.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

namespace tb::tiler {
namespace {

// A decimal integer filling all of `text` (surrounding whitespace allowed).
bool parse_int(std::string_view text, std::int64_t& out) {
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front()))) {
        text.remove_prefix(1);
    }
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) {
        text.remove_suffix(1);
    }
    const char* end = text.data() + text.size();
    const auto [ptr, ec] = std::from_chars(text.data(), end, out);
    return ec == std::errc() && ptr == end && !text.empty();
}

// ceil(quota / period) when both are positive, else 0 (no limit).
int quota_cpus(std::int64_t quota, std::int64_t period) {
    if (quota <= 0 || period <= 0) {
        return 0;
    }
    return static_cast<int>(std::min<std::int64_t>((quota + period - 1) / period, 1 << 20));
}

std::string read_small(const std::string& path) {
    std::ifstream in(path);
    std::string text;
    std::getline(in, text, '\0');
    return text.substr(0, 256);
}

// The tightest limit (0: none) over `dir` and its ancestors up to `root`, of `limit(dir)`.
template <typename Limit>
int tightest(std::string dir, const std::string& root, const Limit& limit) {
    int best = 0;
    for (;;) {
        const int here = limit(dir);
        if (here > 0 && (best == 0 || here < best)) {
            best = here;
        }
        if (dir.size() <= root.size()) {
            return best;
        }
        dir.resize(dir.rfind('/'));
    }
}

} // namespace

int cpus_of_cpu_max(std::string_view cpu_max) {
    const std::size_t space = cpu_max.find(' ');
    if (space == std::string_view::npos) {
        return 0;
    }
    std::int64_t quota = 0, period = 0;
    if (!parse_int(cpu_max.substr(0, space), quota) ||
        !parse_int(cpu_max.substr(space + 1), period)) {
        return 0; // "max 100000" (no limit), or not a cpu.max value
    }
    return quota_cpus(quota, period);
}

int cpus_of_cfs(std::string_view quota_us, std::string_view period_us) {
    std::int64_t quota = 0, period = 0;
    if (!parse_int(quota_us, quota) || !parse_int(period_us, period)) {
        return 0;
    }
    return quota_cpus(quota, period);
}

int cgroup_quota_cpus(std::string_view proc_self_cgroup, const std::string& cgroup_root) {
    int best = 0;
    const auto take = [&best](int cpus) {
        if (cpus > 0 && (best == 0 || cpus < best)) {
            best = cpus;
        }
    };
    const auto is_dir = [](const std::string& d) {
        std::error_code ec;
        return std::filesystem::is_directory(d, ec);
    };
    std::stringstream lines{std::string(proc_self_cgroup)};
    for (std::string line; std::getline(lines, line);) {
        const std::size_t a = line.find(':');
        const std::size_t b = a == std::string::npos ? a : line.find(':', a + 1);
        if (b == std::string::npos) {
            continue;
        }
        const std::string controllers = line.substr(a + 1, b - a - 1);
        std::string path = line.substr(b + 1);
        if (path.empty() || path == "/") {
            path.clear();
        }
        // Inside a container the path may name the host's hierarchy while the container's own
        // cgroup is mounted at the root: a directory that does not exist falls back to the
        // mount's root. One that exists is walked up from, limit file or not (under systemd a
        // slice sets the quota and the service below it has no cpu.max of its own).
        const auto start = [&](const std::string& root) {
            return is_dir(root + path) ? root + path : root;
        };
        if (controllers.empty()) {
            // cgroup v2 alone is mounted at the root; beside v1 (hybrid) at unified/.
            const std::string root = std::ifstream(cgroup_root + "/cgroup.controllers")
                                         ? cgroup_root
                                         : cgroup_root + "/unified";
            take(tightest(start(root), root, [](const std::string& d) {
                return cpus_of_cpu_max(read_small(d + "/cpu.max"));
            }));
            continue;
        }
        std::stringstream list(controllers);
        for (std::string c; std::getline(list, c, ',');) {
            if (c != "cpu") {
                continue;
            }
            for (const char* mount : {"/cpu", "/cpu,cpuacct"}) {
                const std::string root = cgroup_root + mount;
                if (!is_dir(root)) {
                    continue;
                }
                take(tightest(start(root), root, [](const std::string& d) {
                    return cpus_of_cfs(read_small(d + "/cpu.cfs_quota_us"),
                                       read_small(d + "/cpu.cfs_period_us"));
                }));
            }
        }
    }
    return best;
}

int usable_cpus() {
    int cpus = static_cast<int>(std::thread::hardware_concurrency());
    cpu_set_t set;
    CPU_ZERO(&set);
    if (sched_getaffinity(0, sizeof set, &set) == 0) {
        const int mask = CPU_COUNT(&set);
        if (mask > 0) {
            cpus = cpus > 0 ? std::min(cpus, mask) : mask;
        }
    }
    std::ifstream in("/proc/self/cgroup");
    std::string text;
    std::getline(in, text, '\0');
    const int quota = cgroup_quota_cpus(text, "/sys/fs/cgroup");
    if (quota > 0) {
        cpus = cpus > 0 ? std::min(cpus, quota) : quota;
    }
    return std::max(1, cpus);
}

} // namespace tb::tiler
