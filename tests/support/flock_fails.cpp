// A file system without locks, for the runner's tests: preloaded (LD_PRELOAD), this flock
// fails as flock does on a Lustre or NFS mount without lock support.
#include <cerrno>

extern "C" int flock(int /*fd*/, int /*operation*/) {
  errno = ENOLCK;
  return -1;
}
