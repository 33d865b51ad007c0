#include "ReplayCommand.hpp"

#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <tf2/buffer_core.h>
#include <tf2_msgs/TFMessage.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>

#include "CliOptions.hpp"
#include "OutputPaths.hpp"
#include "RunReport.hpp"
#include "hpds/config/ConfigYaml.hpp"
#include "hpds/io/AtomicFile.hpp"
#include "hpds/io/PlyWriter.hpp"
#include "hpds/pipeline/OutputCloud.hpp"
#include "hpds_node/FrameProcessor.hpp"
#include "hpds_node/SequenceGaps.hpp"

namespace hpds::cli {

namespace {

// countInvalidNormals of an output message, read in place: the output's normal_x is float32 (OutputCloud), and
// converting each message back to a PointBuffer only to count would copy every frame's output once more.
std::uint64_t invalidNormalsOf(const sensor_msgs::PointCloud2 &cloud) {
  for (const sensor_msgs::PointField &f : cloud.fields) {
    if (f.name != "normal_x") continue;
    if (f.datatype != sensor_msgs::PointField::FLOAT32)
      throw std::logic_error("replay: an output's normal_x is not float32");
    std::uint64_t n = 0;
    for (sensor_msgs::PointCloud2ConstIterator<float> it(cloud, "normal_x"); it != it.end(); ++it)
      n += std::isnan(*it) ? 1 : 0;
    return n;
  }
  return 0;
}

struct ReplayArgs {
  std::string bag;
  std::string topic;
  std::string output;
  std::string stats;
  std::string ns = "/hpds";
  std::optional<std::string> fixed_frame, output_frame, sensor_frame;
  std::optional<double> local_map_radius, local_map_rate;
  std::optional<std::vector<int>> publish_levels;
  SamplingOptions sampling;
};

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

bool endsWith(const std::string &s, const std::string &suffix) {
  if (s.size() < suffix.size()) return false;
  std::string tail = s.substr(s.size() - suffix.size());
  for (char &c : tail) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return tail == suffix;
}

// The node's YAML gives the ros: settings; the config keys and the sampling flags go through the same path as
// `hpds sample` (the core loader skips `ros:`); then the ROS flags.
hpds_node::NodeConfig resolveNodeConfig(const ReplayArgs &a) {
  hpds_node::NodeConfig config;
  // Validated below with the flags over it, as `hpds sample` does.
  if (!a.sampling.config_file.empty())
    config = hpds_node::loadNodeConfigFile(a.sampling.config_file, hpds::ConfigValidation::kByCaller);
  config.hpds = resolveConfig(a.sampling);
  if (a.fixed_frame) config.ros.fixed_frame = *a.fixed_frame;
  if (a.output_frame) config.ros.output_frame = *a.output_frame;
  if (a.sensor_frame) config.ros.sensor_frame = *a.sensor_frame;
  if (a.local_map_radius) config.ros.local_map_radius = *a.local_map_radius;
  if (a.local_map_rate) config.ros.local_map_rate = *a.local_map_rate;
  if (a.publish_levels) config.ros.publish_levels = *a.publish_levels;
  // The flags bypass the YAML parser, which is where leading slashes are dropped.
  for (std::string *id : {&config.ros.fixed_frame, &config.ros.output_frame, &config.ros.sensor_frame})
    while (!id->empty() && id->front() == '/') id->erase(id->begin());
  try {
    hpds_node::validateRosConfig(config.ros, config.hpds);
  } catch (const std::invalid_argument &e) {
    if (a.sampling.config_file.empty()) throw;
    throw std::invalid_argument(std::string(e.what()) + " (in " + a.sampling.config_file + ", with the flags over it)");
  }
  return config;
}

void appendCloud(PointBuffer &all, const PointBuffer &part) {
  if (all.layout().point_step == 0) {
    all = PointBuffer(part.layout());
  } else if (all.layout() != part.layout()) {
    throw std::invalid_argument("scan mode writes every frame into one PLY, but the clouds on the topic change "
                                "their point fields; write a .bag instead");
  }
  all.bytes().insert(all.bytes().end(), part.bytes().begin(), part.bytes().end());
  all.setOrganization(static_cast<std::uint32_t>(all.size()), 1);
}

/// `part` (one frame's output, as the node publishes it) with the `frame` field `hpds sample` writes for several
/// scan-mode frames, so that one PLY still tells its frames apart (`hpds verify`, --frame): the layout
/// makeCloud(ids, true) gives, every other field copied by name.
PointBuffer withFrameIndex(const PointBuffer &part, std::uint32_t frame, const hpds::NormalConfig &normals) {
  const bool with_normals = normals.enabled, with_covariances = normals.enabled && normals.covariances;
  PointBuffer out =
      withLayout(part, hpds::outputLayout(part.layout(), with_normals, /*with_frame=*/true, with_covariances));
  const PointField *frame_field = out.layout().find("frame");
  for (const PointField &f : out.layout().fields)
    if (&f != frame_field && !part.layout().find(f.name))
      throw std::logic_error("replay: output field '" + f.name + "' has no counterpart in the frame's output");
  for (std::size_t i = 0; i < out.size(); ++i) std::memcpy(out.record(i) + frame_field->offset, &frame, sizeof frame);
  return out;
}

std::string messagesJson(const hpds_node::ProcessorStats &s, std::uint64_t wrong_type) {
  std::ostringstream j;
  j << "{\"received\": " << s.received << ", \"processed\": " << s.processed << ", \"empty\": " << s.empty
    << ", \"not_pointcloud2\": " << wrong_type << ", \"dropped\": {";
  j << "\"malformed\": {";
  for (int e = 1; e < hpds_node::kCloudErrorCount; ++e)
    j << (e > 1 ? ", " : "") << "\"" << hpds_node::toString(hpds_node::CloudError(e)) << "\": " << s.malformed[e];
  j << "}";
  for (int r = 0; r < hpds_node::kDropReasonCount; ++r)
    j << ", \"" << hpds_node::toString(hpds_node::DropReason(r)) << "\": " << s.dropped[r];
  j << "}, \"pose_jumps\": " << s.pose_jumps << "}";
  return j.str();
}

std::string messageSummary(std::size_t messages, const std::string &topic, const hpds_node::ProcessorStats &s,
                           std::uint64_t wrong_type, const std::string &target, bool map_mode) {
  std::ostringstream m;
  m << messages << " on " << topic << ", " << s.processed << " processed, " << s.malformedTotal() << " malformed, ";
  // Transforms are looked up only toward a target frame (map mode's fixed frame, scan mode's --output-frame), and
  // only a map has fields of its own: a summary naming what the run never did would read as a misconfiguration.
  if (!target.empty())
    m << s.dropped[int(hpds_node::DropReason::NoTransform)] << " without transform to '" << target << "', ";
  if (map_mode) m << s.dropped[int(hpds_node::DropReason::LayoutChanged)] << " with other fields than the map, ";
  m << wrong_type << " not PointCloud2";
  if (const std::uint64_t lost = s.dropped[int(hpds_node::DropReason::LostUpstream)])
    m << ", " << lost << " missing from the recording (gaps in header.seq)";
  return m.str();
}

int runReplay(const ReplayArgs &a) {
  // Before anything is read or opened: the bag is never its own output, and a run never ends on an unwritable path.
  checkPaths({{"input", a.bag}, {"--config", a.sampling.config_file}},
             {{"-o", a.output, {".bag", ".ply"}, "a bag or a PLY"}, {"--stats", a.stats, {".json"}, "JSON"}});
  const hpds_node::NodeConfig config = resolveNodeConfig(a);
  const bool to_bag = endsWith(a.output, ".bag");
  const bool scan = config.hpds.mode == Mode::Scan;

  rosbag::Bag in;
  try {
    in.open(a.bag, rosbag::bagmode::Read);
  } catch (const rosbag::BagException &e) {
    throw std::runtime_error("'" + a.bag + "': " + e.what());
  }

  hpds_node::FrameProcessor processor(config);
  const std::string target = processor.targetFrame();
  if (const std::string w = hpds::ignoredRosKeysWarning(config.ros, config.hpds.mode); !w.empty())
    std::cerr << "hpds: warning: " << w << "\n";

  // 1. Every transform of the bag, before any cloud (see the contract).
  const std::vector<std::string> tf_topics = {"/tf", "/tf_static"};
  rosbag::View tf_view(in, rosbag::TopicQuery(tf_topics));
  const double span = tf_view.size() ? (tf_view.getEndTime() - tf_view.getBeginTime()).toSec() : 0.0;
  tf2::BufferCore tf_buffer(ros::Duration(std::max(10.0, span + 10.0)));
  if (!target.empty()) {
    for (const rosbag::MessageInstance &m : tf_view) {
      const auto tf = m.instantiate<tf2_msgs::TFMessage>();
      if (!tf) continue;
      for (const auto &t : tf->transforms) tf_buffer.setTransform(t, "bag", m.getTopic() == "/tf_static");
    }
  }

  rosbag::View clouds(in, rosbag::TopicQuery(a.topic));
  if (clouds.size() == 0) throw std::invalid_argument("'" + a.bag + "' has no messages on --topic " + a.topic);

  // Written under a temporary name and put in place only after a run that processed frames (AtomicFile).
  std::optional<AtomicFile> bag_file;
  rosbag::Bag out;
  if (to_bag) {
    bag_file.emplace(a.output);
    try {
      out.open(bag_file->writingPath(), rosbag::bagmode::Write);
    } catch (const rosbag::BagException &e) {
      throw std::runtime_error("'" + a.output + "': " + e.what());
    }
    // With each message's connection header: /tf_static must stay latched for `rosbag play` of the output.
    for (const rosbag::MessageInstance &m : tf_view) out.write(m.getTopic(), m.getTime(), m, m.getConnectionHeader());
  }

  RunReport report = reportFor("replay", processor.pipeline());
  std::map<std::string, std::uint32_t> next_seq;  // per output topic
  PointBuffer ply;
  std::uint64_t wrong_type = 0;
  hpds_node::SequenceGaps gaps;
  std::set<std::string> not_carried;
  double input_rounding = 0.0;  // the clouds' own float32 rounding, where the outputs' matters (ProcessedFrame)
  bool sensor_at_origin = false;  // a cloud in the fixed frame without ros.sensor_frame (sensorAtMapOrigin)
  Progress progress(clouds.size());
  std::size_t index = 0;
  const auto t_run = std::chrono::steady_clock::now();
  for (const rosbag::MessageInstance &m : clouds) {
    progress.step(++index, a.topic);
    const auto msg = m.instantiate<sensor_msgs::PointCloud2>();
    if (!msg) {
      ++wrong_type;
      continue;
    }
    // 2. The node's steps: count what the recording lost, validate, transform at the stamp, shared processing.
    const std::uint64_t lost = gaps.observe(m.getCallerId(), msg->header.seq);
    if (lost > 0) processor.countDrop(hpds_node::DropReason::LostUpstream, lost);
    if (processor.check(*msg) != hpds_node::CloudError::None) continue;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();
    if ((!target.empty() &&
         !hpds_node::lookupSensorPose(tf_buffer, target, msg->header.frame_id, msg->header.stamp, pose)) ||
        !hpds_node::lookupViewpoint(tf_buffer, msg->header.frame_id, config.ros.sensor_frame, msg->header.stamp,
                                    viewpoint)) {
      processor.countDrop(hpds_node::DropReason::NoTransform);
      continue;
    }
    sensor_at_origin |= hpds_node::sensorAtMapOrigin(config, msg->header.frame_id);
    hpds_node::ProcessedFrame frame = processor.process(*msg, pose, hpds_node::OutputRequest::all(), viewpoint);
    if (!frame.processed) continue;
    report.seconds.normals += frame.seconds_normals;
    input_rounding = std::max(input_rounding, frame.input_rounding);
    not_carried.insert(frame.fields_not_carried.begin(), frame.fields_not_carried.end());
    if (frame.pose_jump)
      std::cerr << "hpds: warning: at " << msg->header.stamp << ": "
                << hpds::poseJumpWarning(*frame.pose_jump, "check the bag's tf, or replay its parts on their own")
                << "\n";
    if (scan)
      for (std::size_t d = 0; d < report.samples_per_level.size(); ++d)
        report.samples_per_level[d] += frame.counters.accepted_per_level[d];

    // 3. Outputs.
    const auto t_write = std::chrono::steady_clock::now();
    if (to_bag) {
      // header.seq counts each topic's messages from 0, as roscpp numbers the live node's.
      const auto write = [&](const std::string &topic, sensor_msgs::PointCloud2 &cloud) {
        cloud.header.seq = next_seq[topic]++;
        out.write(topic, m.getTime(), cloud);
      };
      if (frame.has_output) {
        // What --stats reports for a bag: the points of every ~output message, as the PLY's are counted.
        report.output_points += std::uint64_t(frame.output.width) * frame.output.height;
        report.invalid_normals += invalidNormalsOf(frame.output);
        write(a.ns + "/output", frame.output);
      }
      if (frame.has_new_samples) write(a.ns + "/new_samples", frame.new_samples);
      if (frame.has_local_map) write(a.ns + "/local_map", frame.local_map);
      for (auto &[level, cloud] : frame.levels) write(a.ns + "/level_" + std::to_string(level), cloud);
    } else if (scan && frame.has_output) {
      PointBuffer part;
      if (hpds_node::fromRosCloud(frame.output, part) != hpds_node::CloudError::None)
        throw std::logic_error("replay: an output cloud does not convert back");
      // The pipeline numbers its frames from 0; this one is the last it took.
      appendCloud(ply, withFrameIndex(part, processor.pipeline().framesProcessed() - 1, config.hpds.normals));
    }
    report.seconds.write += since(t_write);
  }
  progress.finish();
  // The per-frame outputs' normals were estimated inside process() (report.seconds.normals): not insertion time.
  report.seconds.insert = since(t_run) - report.seconds.write - report.seconds.normals;

  const hpds_node::ProcessorStats &s = processor.stats();
  if (s.processed == 0) {
    // Nothing to write: an existing output stays as it is (the temporary bag is removed).
    throw std::runtime_error("no frame processed: " + messageSummary(clouds.size(), a.topic, s, wrong_type, target, !scan) +
                             "; nothing written");
  }
  const hpds::Pipeline &pipeline = processor.pipeline();
  if (!scan)
    for (std::size_t d = 0; d < report.samples_per_level.size(); ++d)
      report.samples_per_level[d] = pipeline.hierarchy().countAtLevel(static_cast<int>(d));
  // The output and the stats are written and synced under temporary names, then put in place together (see
  // `hpds sample`): a failure leaves both previous files as they were.
  // The final map's cloud (and its normals) is made before the write is timed, as `hpds sample` does.
  if (!to_bag && !scan) {
    double final_normals = 0.0;  // makeCloud sets its time; the frames' normals are in the report already
    ply = pipeline.makeCloud(pipeline.outputSamples(), false, &final_normals);
    report.seconds.normals += final_normals;
  }
  const auto t_write = std::chrono::steady_clock::now();
  std::optional<AtomicFile> ply_file;
  if (to_bag) {
    out.close();
    bag_file->finish();
  } else {
    report.output_points = ply.size();
    report.invalid_normals = countInvalidNormals(ply);
    ply_file.emplace(a.output);
    writePly(*ply_file, ply, samplingRecordOf(pipeline));
    ply_file->finish();
  }
  report.seconds.write += since(t_write);
  report.frames = processor.stats().processed;
  report.totals = pipeline.totals();
  report.hierarchy_bytes = pipeline.hierarchy().memUsage();
  // The report of `hpds sample`, plus the message counts only a replay has.
  if (!a.stats.empty()) report.extra.emplace_back("messages", messagesJson(s, wrong_type));
  std::optional<AtomicFile> stats_file;
  stageJsonFile(stats_file, a.stats, report);
  if (bag_file) bag_file->commit();
  if (ply_file) ply_file->commit();
  if (stats_file) stats_file->commit();

  std::cout << levelSummary(report);
  std::cout << "messages: " << messageSummary(clouds.size(), a.topic, s, wrong_type, target, !scan) << "\n";
  std::cout << "wrote " << a.output << "\n";
  if (!to_bag) {
    const std::string rounding = roundingWarning(ply, report.output_radius, config.hpds.output, input_rounding);
    if (!rounding.empty()) std::cerr << rounding << "\n";
    // A bag holds what the node publishes; the PLY is meant as the final map, which eviction may have cut short.
    if (const std::string w = evictionWarning(config.hpds, report.totals.evicted, pipeline.hierarchy().sampleCount(),
                                              false);
        !w.empty())
      std::cerr << w << "\n";
  }
  if (sensor_at_origin)
    std::cerr << "hpds: warning: clouds arrive in the fixed frame '" << config.ros.fixed_frame
              << "' itself and ros.sensor_frame is not set, so each frame's sensor was taken at that frame's origin: "
                 "normals face it, and map.evict_distance and the input ranges measure from it; set "
                 "--sensor-frame (ros.sensor_frame) to the sensor's tf frame\n";
  for (const std::string &name : not_carried)
    std::cerr << "hpds: warning: input field '" << name << "' is not in the output: " << fieldNotCarriedReason(name)
              << "; rename the field to keep it\n";
  return 0;
}

}  // namespace

void addReplayCommand(CLI::App &app) {
  auto args = std::make_shared<ReplayArgs>();
  CLI::App *cmd = app.add_subcommand(
      "replay", "run the ROS node's processing on a bag, offline and deterministically (no master needed)");
  cmd->add_option("bag", args->bag, "input bag")->required()->check(CLI::ExistingFile);
  cmd->add_option("--topic", args->topic, "sensor_msgs/PointCloud2 topic to sample")->required();
  cmd->add_option("-o,--output", args->output,
                  "OUT.bag (the node's output topics + /tf) or OUT.ply (map: final map; scan: all outputs)")
      ->required()
      ->check(nonEmptyPath());
  cmd->add_option("--stats", args->stats, "write run statistics (incl. dropped messages) as JSON");
  cmd->add_option("--fixed-frame", args->fixed_frame, "map mode: frame of the map (ros.fixed_frame)");
  cmd->add_option("--output-frame", args->output_frame, "scan mode: output frame via tf (ros.output_frame)");
  cmd->add_option("--sensor-frame", args->sensor_frame,
                  "the sensor's tf frame, for clouds in another frame (ros.sensor_frame): the viewpoint");
  cmd->add_option("--local-map-radius", args->local_map_radius, "[m] ros.local_map_radius");
  cmd->add_option("--local-map-rate", args->local_map_rate, "[Hz] ros.local_map_rate (bag time), 0 = off");
  cmd->add_option("--publish-levels", args->publish_levels, "levels D written as <ns>/level_D (ros.publish_levels)");
  cmd->add_option("--ns", args->ns, "namespace of the output topics in OUT.bag")->capture_default_str();
  addSamplingOptions(*cmd, args->sampling);
  cmd->callback([args] {
    const int rc = runReplay(*args);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

}  // namespace hpds::cli
