// SIGINT/SIGTERM -> a flag the loops poll, so every command stops cleanly and prints its
// final statistics.
#pragma once

#include <atomic>

namespace agv::cmd {

std::atomic<bool>& stop_requested();
void install_stop_signals();

}  // namespace agv::cmd
