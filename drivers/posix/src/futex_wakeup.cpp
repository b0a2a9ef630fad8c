#include "agv/posix/futex_wakeup.hpp"

#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <ctime>

namespace agv::posix {

static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t) &&
                  std::atomic<std::uint32_t>::is_always_lock_free,
              "the futex word must be a plain 32-bit integer");

namespace {

std::uint32_t* futex_word(std::atomic<std::uint32_t>* w) {
  return reinterpret_cast<std::uint32_t*>(w);
}

}  // namespace

hal::WaitResult FutexWakeup::wait_until_ns(std::int64_t t_ns) {
  const std::int64_t mono_ns = clock_.to_monotonic_ns(t_ns);
  timespec deadline{};
  deadline.tv_sec = static_cast<time_t>(mono_ns / 1'000'000'000);
  deadline.tv_nsec = static_cast<long>(mono_ns % 1'000'000'000);
  while (true) {
    if (word_.exchange(0, std::memory_order_acquire) != 0) return hal::WaitResult::kWoken;
    if (clock_.now_ns() >= t_ns) return hal::WaitResult::kDeadline;
    // Sleeps only while the word is still 0: a wake() between the exchange and here makes the
    // kernel return EAGAIN at once.
    const long rc = syscall(SYS_futex, futex_word(&word_), FUTEX_WAIT_BITSET | FUTEX_PRIVATE_FLAG,
                            0u, &deadline, nullptr, FUTEX_BITSET_MATCH_ANY);
    if (rc == 0 || errno == EAGAIN || errno == EINTR) continue;
    if (errno == ETIMEDOUT) {
      return word_.exchange(0, std::memory_order_acquire) != 0 ? hal::WaitResult::kWoken
                                                               : hal::WaitResult::kDeadline;
    }
    return hal::WaitResult::kError;
  }
}

void FutexWakeup::wake() {
  if (word_.exchange(1, std::memory_order_release) == 0) {
    syscall(SYS_futex, futex_word(&word_), FUTEX_WAKE | FUTEX_PRIVATE_FLAG, 1, nullptr, nullptr, 0);
  }
}

}  // namespace agv::posix
