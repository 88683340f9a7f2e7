// The CPU count behind every default thread count: cgroup quotas parsed exactly, and the
// affinity mask honoured (checked by pinning the test's own thread).
#include <doctest/doctest.h>

#include "tiler/cpus.hpp"

#include <sched.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>

using tb::tiler::cgroup_quota_cpus;
using tb::tiler::cpus_of_cfs;
using tb::tiler::cpus_of_cpu_max;
using tb::tiler::usable_cpus;

TEST_CASE("cgroup CPU quotas give whole CPUs, rounded up, and no limit gives 0") {
    CHECK(cpus_of_cpu_max("200000 100000\n") == 2);
    CHECK(cpus_of_cpu_max("150000 100000") == 2); // --cpus 1.5
    CHECK(cpus_of_cpu_max("50000 100000") == 1);
    CHECK(cpus_of_cpu_max("max 100000\n") == 0);
    CHECK(cpus_of_cpu_max("") == 0);
    CHECK(cpus_of_cpu_max("garbage") == 0);
    CHECK(cpus_of_cpu_max("100000 0") == 0);
    CHECK(cpus_of_cpu_max("-5 100000") == 0);
    CHECK(cpus_of_cfs("400000\n", "100000\n") == 4);
    CHECK(cpus_of_cfs("-1\n", "100000\n") == 0);
    CHECK(cpus_of_cfs("", "100000") == 0);
}

TEST_CASE("usable_cpus counts the affinity mask, not the host") {
    const int n = usable_cpus();
    CHECK(n >= 1);
    const unsigned host = std::thread::hardware_concurrency();
    if (host > 0) {
        CHECK(n <= static_cast<int>(host));
    }
    cpu_set_t saved;
    CPU_ZERO(&saved);
    REQUIRE(sched_getaffinity(0, sizeof saved, &saved) == 0);
    int first = -1;
    for (int c = 0; c < CPU_SETSIZE && first < 0; ++c) {
        if (CPU_ISSET(c, &saved)) {
            first = c;
        }
    }
    REQUIRE(first >= 0);
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(first, &one);
    REQUIRE(sched_setaffinity(0, sizeof one, &one) == 0);
    const int pinned = usable_cpus();
    REQUIRE(sched_setaffinity(0, sizeof saved, &saved) == 0);
    CHECK(pinned == 1);
    CHECK(usable_cpus() == n);
}

namespace {

// A cgroup file system laid out under a temporary directory.
struct FakeCgroups {
    std::filesystem::path root;
    FakeCgroups() {
        std::random_device rd;
        root = std::filesystem::temp_directory_path() / ("tb_cgroup_test_" + std::to_string(rd()));
        std::filesystem::create_directories(root);
    }
    ~FakeCgroups() {
        std::error_code ec;
        std::filesystem::remove_all(root, ec);
    }
    void file(const std::string& rel, const std::string& text) const {
        std::filesystem::create_directories((root / rel).parent_path());
        std::ofstream(root / rel) << text;
    }
    void dir(const std::string& rel) const { std::filesystem::create_directories(root / rel); }
};

} // namespace

TEST_CASE("a cgroup quota is found on the process's cgroup or any ancestor, the tightest wins") {
    SUBCASE("cgroup v2: a systemd slice holds the quota, the service below it has none") {
        FakeCgroups fs;
        fs.file("cgroup.controllers", "cpu memory\n");
        fs.file("cpu.max", "max 100000\n");
        fs.file("capped.slice/cpu.max", "200000 100000\n");
        fs.dir("capped.slice/foo.service");
        CHECK(cgroup_quota_cpus("0::/capped.slice/foo.service\n", fs.root.string()) == 2);
        // A tighter one further down wins; none anywhere is 0.
        fs.file("capped.slice/foo.service/cpu.max", "50000 100000\n");
        CHECK(cgroup_quota_cpus("0::/capped.slice/foo.service\n", fs.root.string()) == 1);
        CHECK(cgroup_quota_cpus("0::/\n", fs.root.string()) == 0);
    }
    SUBCASE("cgroup v2 in a container: the host's path does not exist, the root's quota counts") {
        FakeCgroups fs;
        fs.file("cgroup.controllers", "cpu\n");
        fs.file("cpu.max", "300000 100000\n");
        CHECK(cgroup_quota_cpus("0::/docker/abc123\n", fs.root.string()) == 3);
    }
    SUBCASE("cgroup v1 beside a hybrid unified hierarchy") {
        FakeCgroups fs;
        fs.dir("unified");
        fs.file("cpu,cpuacct/a/cpu.cfs_quota_us", "300000\n");
        fs.file("cpu,cpuacct/a/cpu.cfs_period_us", "100000\n");
        fs.dir("cpu,cpuacct/a/b");
        const std::string text = "12:memory:/a/b\n4:cpu,cpuacct:/a/b\n0::/a/b\n";
        CHECK(cgroup_quota_cpus(text, fs.root.string()) == 3);
        fs.file("cpu,cpuacct/a/b/cpu.cfs_quota_us", "-1\n");
        fs.file("cpu,cpuacct/a/b/cpu.cfs_period_us", "100000\n");
        CHECK(cgroup_quota_cpus(text, fs.root.string()) == 3); // -1: no limit of its own
    }
    SUBCASE("nothing mounted or unreadable text: no quota") {
        FakeCgroups fs;
        CHECK(cgroup_quota_cpus("0::/x\n", fs.root.string()) == 0);
        CHECK(cgroup_quota_cpus("garbage", fs.root.string()) == 0);
        CHECK(cgroup_quota_cpus("", "/nonexistent") == 0);
    }
}
