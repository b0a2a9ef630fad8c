#pragma once
// Where this process's threads may run, read from /proc (the tests of loop.*_cpus).
#include <pthread.h>
#include <sched.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace agv::test {

// Cpus_allowed_list ("1", "0-3") of every thread of this process named `name`.
inline std::vector<std::string> cpus_of_threads_named(const std::string& name) {
  std::vector<std::string> out;
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream comm(task.path() / "comm");
    std::string n;
    std::getline(comm, n);
    if (n != name) continue;
    std::ifstream status(task.path() / "status");
    std::string line;
    while (std::getline(status, line)) {
      if (line.rfind("Cpus_allowed_list:", 0) == 0) {
        const auto b = line.find_first_not_of(" \t", 18);
        out.push_back(b == std::string::npos ? "" : line.substr(b));
      }
    }
  }
  return out;
}

// The CPUs the calling thread may run on, ascending (empty if unknown).
inline std::vector<int> allowed_cpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  std::vector<int> cpus;
  if (pthread_getaffinity_np(pthread_self(), sizeof set, &set) != 0) return cpus;
  for (int c = 0; c < CPU_SETSIZE; ++c)
    if (CPU_ISSET(c, &set)) cpus.push_back(c);
  return cpus;
}

// The lowest CPU the calling thread may run on (-1 if unknown).
inline int lowest_allowed_cpu() {
  const std::vector<int> cpus = allowed_cpus();
  return cpus.empty() ? -1 : cpus.front();
}

}  // namespace agv::test
