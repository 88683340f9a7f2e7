#pragma once
// How many CPUs this process may really use. std::thread::hardware_concurrency() counts the
// host's CPUs; in a container started with `--cpus 2` (a cgroup CPU quota) or pinned with
// `taskset`/`--cpuset-cpus` (an affinity mask) that is more than the process gets, and threads
// beyond its share only take turns. Used for every default thread count: the server's generation
// threads and connection loops, and `build` without --threads.
#include <string>
#include <string_view>

namespace tb::tiler {

// The CPUs of the calling thread's affinity mask, capped by the tightest cgroup CPU quota of
// the process's cgroup and its ancestors (cgroup v2 cpu.max, or v1 cpu.cfs_quota_us over
// cpu.cfs_period_us), a fractional quota rounded up. At least 1.
int usable_cpus();

// The CPUs a cgroup v2 cpu.max value allows ("$QUOTA $PERIOD" in microseconds, rounded up), or
// 0 when it sets no limit ("max ...") or is not such a value.
int cpus_of_cpu_max(std::string_view cpu_max);

// The same for cgroup v1's cpu.cfs_quota_us and cpu.cfs_period_us (quota -1: no limit).
int cpus_of_cfs(std::string_view quota_us, std::string_view period_us);

// The tightest quota, in whole CPUs (0: none), of the cgroups a /proc/self/cgroup text names,
// read from the cgroup file systems mounted under cgroup_root (normally /sys/fs/cgroup): each
// cgroup's directory and its ancestors up to the mount's root.
int cgroup_quota_cpus(std::string_view proc_self_cgroup, const std::string& cgroup_root);

} // namespace tb::tiler
