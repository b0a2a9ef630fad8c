// Real-time helpers of drivers/posix: memory locking must not inflate the resident set.
#include <gtest/gtest.h>

#include <cerrno>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "../support/thread_cpus.hpp"
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

using agv::test::allowed_cpus;

TEST(PosixRealtime, CpuAffinityPinsTheCallingThreadOnly) {
  const std::vector<int> process_cpus = allowed_cpus();
  ASSERT_FALSE(process_cpus.empty());
  const int target = process_cpus.back();
  std::vector<int> in_thread, in_child;
  int err = -1;
  std::thread t([&] {
    err = agv::posix::set_cpu_affinity({target});
    in_thread = allowed_cpus();
    std::thread child([&] { in_child = allowed_cpus(); });  // inherits the set
    child.join();
  });
  t.join();
  EXPECT_EQ(err, 0);
  EXPECT_EQ(in_thread, std::vector<int>({target}));
  EXPECT_EQ(in_child, std::vector<int>({target}));
  EXPECT_EQ(allowed_cpus(), process_cpus);  // the caller's thread is untouched
}

TEST(PosixRealtime, CpuAffinityEmptyListAndAbsentCpu) {
  const std::vector<int> before = allowed_cpus();
  EXPECT_EQ(agv::posix::set_cpu_affinity({}), 0);
  EXPECT_EQ(allowed_cpus(), before);
  // CPU 1023 is not online on any machine this runs on; the set stays as it was.
  std::vector<int> after;
  int err = 0;
  std::thread t([&] {
    err = agv::posix::set_cpu_affinity({1023});
    after = allowed_cpus();
  });
  t.join();
  EXPECT_EQ(err, EINVAL);
  EXPECT_EQ(after, before);
  EXPECT_EQ(agv::posix::set_cpu_affinity({-1}), EINVAL);
  EXPECT_EQ(agv::posix::set_cpu_affinity({CPU_SETSIZE}), EINVAL);
}
