// Keeping the memory one frame frees for the next: a process-wide malloc setting for programs that run the pipeline
// frame after frame (the node, the command-line tool, the benchmarks).
#pragma once

#include <cstddef>  // defines __GLIBC__ (through the C++ library's configuration) where the C library is glibc

namespace hpds {

/// Whether keepFreedFrameMemory can take in this build: glibc's malloc, not a sanitizer's, which replaces it (for
/// tests and bindings that must say what a build can do).
#if defined(__GLIBC__) && !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
inline constexpr bool kFreedFrameMemoryCanBeKept = true;
#else
inline constexpr bool kFreedFrameMemoryCanBeKept = false;
#endif

/// Makes glibc's malloc keep freed memory inside the process for later allocations instead of returning it to the
/// kernel (blocks up to 32 MB come from the heap; free memory at its top is given back beyond 64 MB). Without it,
/// glibc's adaptive thresholds handed part of each dense frame's scratch back and took it again on the next frame:
/// VLS-128 frames (209 k points) at the defaults cost ~5 400 page faults (21 MB zeroed by the kernel) per frame.
/// The peak resident size is the same. Process-wide: call it once, early, from a program's main(), not from a
/// library, and not where the process's own allocation policy matters more than hpds's speed. Returns false (and
/// does nothing) where malloc is not glibc's or refuses the setting. Not thread-safe against concurrent calls.
bool keepFreedFrameMemory();

}  // namespace hpds
