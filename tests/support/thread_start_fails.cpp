// A process limit on threads, for the programs' tests: preloaded (LD_PRELOAD), this
// pthread_create starts the first SBPTT_THREADS_ALLOWED threads (0 when unset) and then fails
// with EAGAIN, as it does under ulimit -u, a container's pids limit or ulimit -v.
#include <dlfcn.h>
#include <pthread.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>

namespace {
std::atomic<long> started{0};
}

extern "C" int pthread_create(pthread_t* thread, const pthread_attr_t* attributes,
                              void* (*start)(void*), void* argument) {
  using Create = int (*)(pthread_t*, const pthread_attr_t*, void* (*)(void*), void*);
  static const auto real = reinterpret_cast<Create>(dlsym(RTLD_NEXT, "pthread_create"));
  if (real == nullptr) return ENOSYS;
  // One count for the process: the programs tested start no thread but the pools'.
  const char* allowed = std::getenv("SBPTT_THREADS_ALLOWED");
  if (started.fetch_add(1) >= (allowed != nullptr ? std::atol(allowed) : 0)) return EAGAIN;
  return real(thread, attributes, start, argument);
}
