#pragma once
// A mutex with priority inheritance, for data shared between the real-time NDI polling
// thread (SCHED_FIFO, docs/appliance.md) and normally scheduled threads (camera): while a
// normal thread holds the lock, it runs at the waiting real-time thread's priority, so the
// real-time thread never waits behind unrelated work (priority inversion). std::mutex cannot
// be configured for this. Satisfies Lockable (std::lock_guard, std::unique_lock).
#include <pthread.h>

#include <cerrno>
#include <system_error>

namespace arnav::frames {

class PiMutex {
 public:
  PiMutex() {
    pthread_mutexattr_t attr;
    pthread_mutexattr_init(&attr);
    pthread_mutexattr_setprotocol(&attr, PTHREAD_PRIO_INHERIT);
    const int rc = pthread_mutex_init(&mutex_, &attr);
    pthread_mutexattr_destroy(&attr);
    if (rc != 0) throw std::system_error(rc, std::generic_category(), "pthread_mutex_init (priority inheritance)");
  }
  ~PiMutex() { pthread_mutex_destroy(&mutex_); }
  PiMutex(const PiMutex&) = delete;
  PiMutex& operator=(const PiMutex&) = delete;

  void lock() {
    if (const int rc = pthread_mutex_lock(&mutex_); rc != 0) throw std::system_error(rc, std::generic_category(), "pthread_mutex_lock");
  }
  bool try_lock() { return pthread_mutex_trylock(&mutex_) == 0; }
  void unlock() { pthread_mutex_unlock(&mutex_); }

 private:
  pthread_mutex_t mutex_;
};

}  // namespace arnav::frames
