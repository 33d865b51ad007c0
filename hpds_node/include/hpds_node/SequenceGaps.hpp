// SequenceGaps: frames lost before they reached hpds, counted from gaps in header.seq.
//
// Contract
// - roscpp numbers the messages of a publisher 0, 1, 2 ... in header.seq (and rosbag keeps the recorded numbers), so
//   a jump from s to s + 1 + n means n messages of that publisher never arrived: dropped by its queue, the network,
//   or this node's subscriber queue. They are counted per publisher (the connection's caller id), since two
//   publishers on one topic number independently.
// - The first message of a publisher only sets its baseline. A seq that does not advance (publishers in the same
//   process, which roscpp does not renumber, often leave it 0) or goes back (a restarted publisher, a looped bag)
//   resets the baseline and counts nothing; 2^32 wraps around.
// - Not thread-safe: one thread observes (the subscriber callback, or the replay loop).
#pragma once

#include <cstdint>
#include <map>
#include <string>

namespace hpds_node {

class SequenceGaps {
 public:
  /// Messages of `publisher` missing between its previous message and this one with `seq`.
  std::uint64_t observe(const std::string &publisher, std::uint32_t seq);

 private:
  std::map<std::string, std::uint32_t> last_;
};

}  // namespace hpds_node
