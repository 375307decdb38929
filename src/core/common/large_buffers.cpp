#include "skin3d/common/large_buffers.h"

#include <cstddef>  // first: through it the C library's <features.h> defines __GLIBC__

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace skin3d {

bool keepLargeBuffers() {
#if defined(__GLIBC__)
  // no mmap() for large blocks (they come from the heap), and the heap's top is never trimmed: the next frame's
  // buffers reuse the pages the last one freed
  const bool a = mallopt(M_MMAP_MAX, 0) == 1;
  const bool b = mallopt(M_TRIM_THRESHOLD, -1) == 1;  // -1: never trim (a large value still trims above it)
  // one arena: a worker thread's image buffer would otherwise come from a per-thread heap (64 MB), which is
  // unmapped when it empties and faulted in again by the next task
  const bool c = mallopt(M_ARENA_MAX, 1) == 1;
  return a && b && c;
#else
  return false;
#endif
}

}  // namespace skin3d
