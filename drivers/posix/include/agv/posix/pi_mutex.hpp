// Mutex with priority inheritance (PTHREAD_PRIO_INHERIT): when the real-time output thread waits
// for a lock held by a normal-priority thread, the holder runs at the waiter's priority, so the
// wait is bounded by the (short) critical section instead of by whatever else is runnable.
#pragma once

#include <pthread.h>

namespace agv::posix {

class PiMutex {
 public:
  PiMutex() {
    pthread_mutexattr_t a;
    pthread_mutexattr_init(&a);
    pthread_mutexattr_setprotocol(&a, PTHREAD_PRIO_INHERIT);
    pthread_mutex_init(&m_, &a);
    pthread_mutexattr_destroy(&a);
  }
  ~PiMutex() { pthread_mutex_destroy(&m_); }
  PiMutex(const PiMutex&) = delete;
  PiMutex& operator=(const PiMutex&) = delete;
  void lock() { pthread_mutex_lock(&m_); }
  void unlock() { pthread_mutex_unlock(&m_); }
  bool try_lock() { return pthread_mutex_trylock(&m_) == 0; }

 private:
  pthread_mutex_t m_;
};

}  // namespace agv::posix
