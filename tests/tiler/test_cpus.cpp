// The CPU count behind every default thread count: cgroup quotas parsed exactly, and the
// affinity mask honoured (checked by pinning the test's own thread).
#include <doctest/doctest.h>

#include "tiler/cpus.hpp"

#include <sched.h>

#include <thread>

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
