// Helpers of the ROS tests (the rostest nodes and the master-less unit tests): frames as PointCloud2, collecting
// messages, checks on output clouds, reading the node's diagnostics, whole files as bytes.
#pragma once

#include <diagnostic_msgs/DiagnosticArray.h>
#include <rosgraph_msgs/Log.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>

#include <Eigen/Core>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "hpds/points/PointBuffer.hpp"
#include "hpds/eval/SyntheticLidar.hpp"

namespace hpds_test {

/// A test node's main: GoogleTest and ROS initialised (node `node_name`), an AsyncSpinner for the subscriptions,
/// then every test.
int runRosTests(int argc, char **argv, const std::string &node_name);

/// The shared lidar folder from the test node's ~data_dir parameter, or empty when it is absent.
std::string sharedDataDir();

/// A real frame from the shared data as a PointCloud2 (every field of the file kept).
sensor_msgs::PointCloud2Ptr loadFrame(const std::string &path, const std::string &frame_id, const ros::Time &stamp);

/// `points` as a PointCloud2 with that header (every field kept).
sensor_msgs::PointCloud2 toMsg(const hpds::PointBuffer &points, const std::string &frame_id, const ros::Time &stamp);

/// Frame i of `lidar` with its points moved into the fixed frame (so its sensor pose is the identity).
sensor_msgs::PointCloud2Ptr fixedFrameMsg(const hpds::SyntheticLidar &lidar, int i, const std::string &frame_id,
                                          const ros::Time &stamp);

/// Spins (the caller runs an AsyncSpinner) until pred() or the wall-clock timeout; returns pred().
bool waitFor(const std::function<bool()> &pred, double timeout_s);

/// Subscribes and keeps every message of one topic.
template <typename Msg>
class Collector {
 public:
  Collector(ros::NodeHandle &nh, const std::string &topic) {
    sub_ = nh.subscribe<Msg>(topic, 100, [this](const typename Msg::ConstPtr &m) {
      std::lock_guard<std::mutex> lock(mutex_);
      messages_.push_back(m);
    });
  }
  // The subscription goes first: its shutdown waits for a callback running on the spinner's thread, which would
  // otherwise write into members already destroyed (members go in reverse order, sub_ last).
  ~Collector() { sub_.shutdown(); }
  Collector(const Collector &) = delete;
  Collector &operator=(const Collector &) = delete;
  std::size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return messages_.size();
  }
  std::vector<typename Msg::ConstPtr> messages() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return messages_;
  }
  bool connected() const { return sub_.getNumPublishers() > 0; }
  void clear() {
    std::lock_guard<std::mutex> lock(mutex_);
    messages_.clear();
  }

 private:
  ros::Subscriber sub_;
  mutable std::mutex mutex_;
  std::vector<typename Msg::ConstPtr> messages_;
};

/// Output cloud as a PointBuffer; fails the current test (ADD_FAILURE) and returns an empty buffer when the
/// message does not convert.
hpds::PointBuffer toBuffer(const sensor_msgs::PointCloud2 &msg);

/// x/y/z of every point, as double.
std::vector<Eigen::Vector3d> positions(const hpds::PointBuffer &cloud);

/// Smallest distance between two of `points` that is below `limit` (searched with a grid of edge `limit`), or
/// `limit` when no pair is that close.
double minDistanceBelow(const std::vector<Eigen::Vector3d> &points, double limit);

/// Latest key/value pairs of the diagnostics status whose name contains `node_name`.
class DiagnosticsReader {
 public:
  DiagnosticsReader(ros::NodeHandle &nh, const std::string &node_name);
  // As Collector's: the subscription is shut down (waiting for a callback in progress) before values_ goes.
  ~DiagnosticsReader() { sub_.shutdown(); }
  DiagnosticsReader(const DiagnosticsReader &) = delete;
  DiagnosticsReader &operator=(const DiagnosticsReader &) = delete;
  /// Value of `key` as a number, or -1 when not reported yet.
  double value(const std::string &key) const;
  std::size_t updates() const;
  /// hardware_id of the latest status.
  std::string hardwareId() const;
  /// The highest level (diagnostic_msgs::DiagnosticStatus::OK, WARN, ERROR) of any status seen, -1 before the first.
  int highestLevel() const;

 private:
  std::string node_name_;
  ros::Subscriber sub_;
  mutable std::mutex mutex_;
  std::map<std::string, std::string> values_;
  std::string hardware_id_;
  std::size_t updates_ = 0;
  int highest_level_ = -1;
};

/// Checks that x y z are float32 at offsets 0, 4, 8, every field sits at a multiple of its element size without
/// overlapping another, and point_step is a multiple of 4 and of every element size.
void expectAlignedFields(const sensor_msgs::PointCloud2 &cloud,
                         std::uint8_t xyz_datatype = sensor_msgs::PointField::FLOAT32);

/// Checks the layout of an hpds output cloud: x y z float32, level uint8, normals when `normals`, every field of
/// `input` except x/y/z (and PCL padding "_") with the same name, datatype and count, nothing else, all aligned (expectAlignedFields).
void expectOutputLayout(const sensor_msgs::PointCloud2 &out, const sensor_msgs::PointCloud2 &input, bool normals);

/// The whole file (empty when it cannot be read) / replaces the file with `bytes`.
std::vector<std::uint8_t> readBytes(const std::filesystem::path &p);
void writeBytes(const std::filesystem::path &p, const std::vector<std::uint8_t> &bytes);

inline bool contains(const std::string &text, const std::string &part) { return text.find(part) != std::string::npos; }

// Every message one node logs, from /rosout (every node publishes its log there; rostest runs no rosout node, so
// there is no /rosout_agg).
class LogCollector {
 public:
  LogCollector(ros::NodeHandle &nh, const std::string &node) : node_(node) {
    sub_ = nh.subscribe<rosgraph_msgs::Log>("/rosout", 1000, [this](const rosgraph_msgs::Log::ConstPtr &m) {
      if (m->name != node_) return;
      std::lock_guard<std::mutex> lock(mutex_);
      lines_.push_back(*m);
    });
  }
  // The subscription goes before lines_: its shutdown waits for a callback in progress on the spinner's thread.
  ~LogCollector() { sub_.shutdown(); }
  LogCollector(const LogCollector &) = delete;
  LogCollector &operator=(const LogCollector &) = delete;
  /// True when a line of `level` holding every one of `parts` has arrived.
  bool has(std::uint8_t level, const std::vector<std::string> &parts) const { return count(level, parts) > 0; }
  /// How many lines of `level` holding every one of `parts` have arrived.
  std::size_t count(std::uint8_t level, const std::vector<std::string> &parts) const {
    std::lock_guard<std::mutex> lock(mutex_);
    std::size_t n = 0;
    for (const rosgraph_msgs::Log &l : lines_) {
      if (l.level != level) continue;
      bool all = true;
      for (const std::string &p : parts) all = all && l.msg.find(p) != std::string::npos;
      n += all;
    }
    return n;
  }
  std::string dump() const {
    std::lock_guard<std::mutex> lock(mutex_);
    std::string s;
    for (const rosgraph_msgs::Log &l : lines_) s += "[" + std::to_string(l.level) + "] " + l.msg + "\n";
    return s;
  }
  bool connected() const { return sub_.getNumPublishers() > 0; }

 private:
  std::string node_;
  ros::Subscriber sub_;
  mutable std::mutex mutex_;
  std::vector<rosgraph_msgs::Log> lines_;
};

}  // namespace hpds_test
