// Timing and reporting shared by perf_benchmark's files: medians, paired alternating rounds against a peer, the
// table printed on stdout and its JSON copy. Never fails on timing: ratios are reported, not asserted.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

namespace bench {

using Clock = std::chrono::steady_clock;

inline double secondsOf(const std::function<void()> &fn) {
  const auto t0 = Clock::now();
  fn();
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

inline double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

/// Median wall time of `repeats` runs after one warm-up run.
inline double medianSeconds(int repeats, const std::function<void()> &fn) {
  fn();
  std::vector<double> t;
  for (int i = 0; i < repeats; ++i) t.push_back(secondsOf(fn));
  return median(t);
}

struct Paired {
  double hpds_s, peer_s, ratio;
};

/// hpds against its peer, timed in alternating rounds (hpds first in even rounds, the peer first in odd ones) after
/// one warm-up of each. Both sides of a round see the same state of this shared machine, whose speed drifts by tens
/// of percent within a minute, so each round's ratio compares like with like; the ratio reported is the median of
/// those, not a ratio of two medians taken at different times.
inline Paired pairedMedians(int repeats, const std::function<void()> &hpds, const std::function<void()> &peer) {
  hpds();
  peer();
  std::vector<double> h, p, r;
  for (int i = 0; i < repeats; ++i) {
    double th, tp;
    if (i % 2 == 0) {
      th = secondsOf(hpds);
      tp = secondsOf(peer);
    } else {
      tp = secondsOf(peer);
      th = secondsOf(hpds);
    }
    h.push_back(th);
    p.push_back(tp);
    r.push_back(th / tp);
  }
  return Paired{median(h), median(p), median(r)};
}

struct Row {
  std::string data, what;
  double hpds_s, peer_s, ratio;  // ratio: median of the paired rounds' ratios (0 without a peer)
  std::string peer;
  std::string note;
};

/// Every row reported so far, in order (written to JSON at the end).
inline std::vector<Row> &rows() {
  static std::vector<Row> all;
  return all;
}

inline void report(const std::string &data, const std::string &what, const Paired &t, const std::string &peer,
                   const std::string &note = "") {
  rows().push_back({data, what, t.hpds_s, t.peer_s, t.ratio, peer, note});
  std::printf("%-22s %-44s hpds %9.2f ms | %-34s %9.2f ms | ratio %6.2f %s\n", data.c_str(), what.c_str(),
              t.hpds_s * 1e3, peer.c_str(), t.peer_s * 1e3, t.ratio, note.c_str());
  std::fflush(stdout);
}

/// A row without a peer.
inline void report(const std::string &data, const std::string &what, double hpds_s, const std::string &note) {
  report(data, what, Paired{hpds_s, 0.0, 0.0}, "-", note);
}

inline std::string jsonEscaped(const std::string &s) {
  std::string out;
  for (const char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out;
}

inline void writeJson(const std::string &path) {
  if (std::filesystem::path(path).has_parent_path())
    std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  std::ofstream j(path);
  j << "{\n  \"rows\": [\n";
  const std::vector<Row> &all = rows();
  for (std::size_t i = 0; i < all.size(); ++i) {
    const Row &r = all[i];
    j << "    {\"data\": \"" << jsonEscaped(r.data) << "\", \"what\": \"" << jsonEscaped(r.what)
      << "\", \"hpds_s\": " << r.hpds_s << ", \"peer\": \"" << jsonEscaped(r.peer) << "\", \"peer_s\": " << r.peer_s
      << ", \"ratio\": " << r.ratio << ", \"note\": \"" << jsonEscaped(r.note) << "\"}"
      << (i + 1 < all.size() ? "," : "") << "\n";
  }
  j << "  ]\n}\n";
}

}  // namespace bench
