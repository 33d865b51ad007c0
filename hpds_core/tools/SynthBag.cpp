#include "SynthBag.hpp"

#include <rosbag/bag.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_msgs/TFMessage.h>

#include <stdexcept>

#include "hpds/io/AtomicFile.hpp"
#include "hpds_node/CloudConversion.hpp"

namespace hpds::cli {

namespace {

class RosSynthBag final : public SynthBagWriter {
 public:
  explicit RosSynthBag(const SynthBagOptions &options) : options_(options), file_(options.path) {
    try {
      bag_.open(file_.writingPath(), rosbag::bagmode::Write);
    } catch (const rosbag::BagException &e) {
      throw std::runtime_error("--bag: '" + options.path + "': " + e.what());
    }
  }

  void write(const Frame &frame) override {
    const ros::Time stamp = ros::Time(kSynthBagStart) + ros::Duration(frame.stamp);
    // The transform first, at the cloud's own stamp: a node that waits for it (tf_timeout) finds it at once.
    geometry_msgs::TransformStamped pose = tf2::eigenToTransform(frame.sensor_to_fixed);
    pose.header.frame_id = kSynthBagFixedFrame;
    pose.header.stamp = stamp;
    pose.child_frame_id = options_.frame_id;
    tf2_msgs::TFMessage tf;
    tf.transforms.push_back(pose);
    bag_.write("/tf", stamp, tf);

    // A driver numbers its messages: consecutive seqs tell the node that the recording lost nothing.
    std_msgs::Header header;
    header.seq = seq_++;
    header.stamp = stamp;
    header.frame_id = options_.frame_id;
    hpds_node::toRosCloud(frame.points, header, cloud_);
    bag_.write(options_.topic, stamp, cloud_);
  }

  void finish() override {
    bag_.close();
    file_.finish();
  }

  void commit() override { file_.commit(); }

 private:
  SynthBagOptions options_;
  AtomicFile file_;  // constructed before bag_, which writes into its temporary by name
  rosbag::Bag bag_;
  sensor_msgs::PointCloud2 cloud_;  // reused: a frame's bytes are allocated once
  std::uint32_t seq_ = 0;
};

}  // namespace

std::unique_ptr<SynthBagWriter> openSynthBag(const SynthBagOptions &options) {
  return std::make_unique<RosSynthBag>(options);
}

}  // namespace hpds::cli
