#include "hpds/util/FrameMemory.hpp"

#include <cstdlib>  // defines __GLIBC__ where malloc is glibc's

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace hpds {

bool keepFreedFrameMemory() {
#if defined(__GLIBC__)
  // Setting either threshold also turns off glibc's adaptation of both, which is what released the memory: it
  // raises them only as far as the largest block freed so far, so a frame's mix of sizes kept crossing them.
  // 32 MB is glibc's own ceiling for the adaptive mmap threshold; larger blocks are still mapped and unmapped.
  const bool mmap_ok = mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024) == 1;
  const bool trim_ok = mallopt(M_TRIM_THRESHOLD, 64 * 1024 * 1024) == 1;
  return mmap_ok && trim_ok;
#else
  return false;
#endif
}

}  // namespace hpds
