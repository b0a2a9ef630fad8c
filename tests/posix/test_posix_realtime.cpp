// Real-time helpers of drivers/posix: memory locking must not inflate the resident set.
#include <gtest/gtest.h>

#include <cerrno>
#include <fstream>
#include <string>
#include <thread>

#include "agv/posix/realtime.hpp"

// The sanitizer runtimes intercept mlockall and return 0 without locking anything (their shadow
// memory is terabytes of reserved address space), so VmLck stays 0 there.
#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define AGV_MLOCK_IGNORED_BY_SANITIZER 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define AGV_MLOCK_IGNORED_BY_SANITIZER 1
#endif

namespace {

// A field of /proc/self/status in kB ("VmRSS", "VmLck"); -1 when missing.
long status_kb(const std::string& field) {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind(field + ":", 0) == 0) return std::stol(line.substr(field.size() + 1));
  }
  return -1;
}

}  // namespace

TEST(PosixRealtime, LockAllMemoryDoesNotPrefaultNewThreadStacks) {
#ifdef AGV_MLOCK_IGNORED_BY_SANITIZER
  GTEST_SKIP() << "the sanitizer runtime ignores mlockall";
#endif
  const int err = agv::posix::lock_all_memory();
  if (err == EPERM || err == ENOMEM) GTEST_SKIP() << "mlockall not permitted here";
  ASSERT_EQ(err, 0);
  EXPECT_GT(status_kb("VmLck"), 0);  // what is resident is locked
  // A new thread maps an 8 MB stack (glibc default); locking must not fault it all in.
  const long rss_before_kb = status_kb("VmRSS");
  long rss_in_thread_kb = 0;
  std::thread t([&] { rss_in_thread_kb = status_kb("VmRSS"); });
  t.join();
  EXPECT_LT(rss_in_thread_kb - rss_before_kb, 2048) << "RSS grew by the thread's whole stack";
}
