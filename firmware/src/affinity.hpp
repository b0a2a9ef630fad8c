#pragma once
// Thread placement from loop.realtime_cpus / vision_cpus / service_cpus (docs/guide/deployment.md,
// "Real time"): each thread pins itself as it starts, so no thread inherits another's set by
// accident.
#include <string>

namespace agv::app {

// Pins the calling thread to `cpu_list` (kernel list syntax, validated by the config parser); an
// empty list does nothing. A refusal (a CPU this machine does not have online) is reported on
// stderr once per thread, naming `which`, and the thread stays unpinned: the loop still runs, as
// it does when SCHED_FIFO is refused.
void pin_this_thread(const std::string& cpu_list, const char* which);

}  // namespace agv::app
