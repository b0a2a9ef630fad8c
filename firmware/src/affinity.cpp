#include "affinity.hpp"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <vector>

#include "agv/config/cpu_list.hpp"
#include "agv/posix/realtime.hpp"

namespace agv::app {

void pin_this_thread(const std::string& cpu_list, const char* which) {
  std::vector<int> cpus;
  std::string why;
  if (!config::parse_cpu_list(cpu_list, &cpus, &why)) {
    std::fprintf(stderr, "agvloc: CPU affinity (%s): %s; not pinned\n", which, why.c_str());
    return;
  }
  const int err = posix::set_cpu_affinity(cpus);
  if (err) {
    std::fprintf(stderr, "agvloc: CPU affinity (%s): CPUs %s: %s%s; not pinned\n", which,
                 cpu_list.c_str(), std::strerror(err),
                 err == EINVAL ? " (none of them online here: see `nproc`, lscpu)" : "");
  }
}

}  // namespace agv::app
