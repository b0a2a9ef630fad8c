#pragma once
// CPU lists in the kernel's own syntax (the one of /sys/devices/system/cpu/online, taskset -c and
// systemd's CPUAffinity=): "2", "2-3", "0,2-3". Used by loop.realtime_cpus, loop.vision_cpus and
// loop.service_cpus, which keep the output thread and the network services (MQTT, diagnostics
// page) on separate cores (docs/guide/deployment.md, "Real time").
#include <string>
#include <vector>

namespace agv::config {

// The highest CPU number accepted (CPU_SETSIZE - 1 on Linux).
inline constexpr int kMaxCpu = 1023;

// Parses `text` into ascending, distinct CPU numbers. Empty or all-space text gives an empty
// list, which means "not pinned". Returns false and sets *error (one line, says what is wrong)
// on anything else that is not a list of N or N-M items with 0 <= N <= M <= kMaxCpu.
bool parse_cpu_list(const std::string& text, std::vector<int>* cpus, std::string* error);

}  // namespace agv::config
