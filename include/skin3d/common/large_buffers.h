#pragma once

namespace skin3d {

/**
 * Tunes the C library's allocator for full-resolution image buffers. Call it once, early (it is process-wide and
 * idempotent): the tools call it in main(), the dense stereo and induration nodelets in onInit().
 *
 * glibc serves every block above its mmap threshold (32 MB at most) with a fresh mmap() and unmaps it on free.
 * A 13-megapixel float image is 53 MB, and the matcher and the induration stage make and drop hundreds of them
 * per frame: each one was faulted in and zeroed by the kernel page by page, about a third of a frame's time
 * (skin seed 1: 23 s per frame, 11 s of it in the kernel). Here large blocks come from the heap and freed memory
 * stays there for the next buffer (16.6 s per frame, same peak memory: about 2.8 GB). The price: the process
 * keeps its peak memory between frames instead of returning it to the system.
 * Called late (a nodelet's onInit(), in a manager whose threads have allocated already), it only partly takes
 * effect: threads that have their own arena keep it. For the full effect in a nodelet manager, start it with
 * GLIBC_TUNABLES=glibc.malloc.arena_max=1:glibc.malloc.mmap_max=0 in its environment.
 * Returns false where this is not supported (a C library other than glibc); nothing else changes then.
 */
bool keepLargeBuffers();

}  // namespace skin3d
