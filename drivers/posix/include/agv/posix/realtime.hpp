// Optional real-time setup for the loop threads. Each returns 0 or an errno value; the caller
// decides whether a refusal (EPERM without CAP_SYS_NICE / CAP_IPC_LOCK) is fatal.
#pragma once

#include <string>
#include <vector>

namespace agv::posix {

// SCHED_FIFO at `priority` (1..99) for the calling thread.
int set_fifo_priority(int priority);
// mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT) so pages the loop has touched cannot be
// reclaimed and fault again; falls back to MCL_CURRENT | MCL_FUTURE (prefaults everything mapped)
// on kernels without MCL_ONFAULT.
int lock_all_memory();
// Restricts the calling thread to `cpus` (CPU numbers, as config::parse_cpu_list gives them);
// an empty list leaves it as it is and returns 0. EINVAL when none of them is online here.
// Threads the caller creates afterwards inherit the set.
int set_cpu_affinity(const std::vector<int>& cpus);
// A one-line explanation of a failure above, naming the capability or limit to change.
std::string explain_realtime_error(const char* what, int err);
// Names the calling thread (visible in top -H, gdb). Truncated to 15 characters.
void set_thread_name(const char* name);

}  // namespace agv::posix
