// Interrupting a long call from another thread: a flag the caller sets (from a signal handler's thread, a cancel
// button, a Python binding that saw Ctrl-C) and the library reads between its stages.
//
// Contract
// - The flag is read with relaxed loads at stage boundaries (before the insertion order, every 2^18 points of an
//   insertion pass, before the normals): on millions of points the call returns within about a second of the flag
//   being set (3 M points: at most 1.1 s, the normals' stage), by throwing Interrupted.
// - What was interrupted is left valid but unfinished (a scan-mode frame half inserted, a map holding part of a
//   frame): discard the Pipeline, or call it again only with frames whose result no longer matters.
#pragma once

#include <atomic>
#include <stdexcept>
#include <string>

namespace hpds {

/// Thrown by a call whose interrupt flag was set while it ran.
struct Interrupted : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Throws Interrupted naming `stage` when `flag` is set; nothing when it is null or clear.
inline void throwIfInterrupted(const std::atomic<bool> *flag, const char *stage) {
  if (flag && flag->load(std::memory_order_relaxed))
    throw Interrupted(std::string("interrupted (") + stage + ")");
}

}  // namespace hpds
