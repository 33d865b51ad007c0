// hpds_node: the standalone entry point of HpdsServer (the nodelet is the other one).
//
// roscpp's own stop paths (its SIGINT handler, the XML-RPC "shutdown" of rosnode kill and roslaunch) call
// ros::shutdown() at once, which takes rosconsole down with it: the map save on shutdown would then be saved or lost
// without a word. Both only ask the loop below to stop; the server shuts down (and logs) while roscpp is still up.
#include <ros/ros.h>
#include <ros/xmlrpc_manager.h>

#include <csignal>
#include <cstring>
#include <iostream>
#include <stdexcept>

#include "hpds/util/FrameMemory.hpp"
#include "hpds_node/HpdsServer.hpp"

namespace {

volatile std::sig_atomic_t g_stop_requested = 0;

void onSignal(int) { g_stop_requested = 1; }

void onShutdownRequest(XmlRpc::XmlRpcValue &, XmlRpc::XmlRpcValue &result) {
  g_stop_requested = 1;
  result = ros::xmlrpc::responseInt(1, "", 0);
}

// A trial's `hpds_node --help` started a node named /hpds, which took the name from a running one and shut it down.
bool asksForHelp(int argc, char **argv) {
  for (int i = 1; i < argc; ++i)
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) return true;
  return false;
}

void printHelp() {
  std::cout << "hpds_node: hierarchical Poisson-disk downsampling of sensor_msgs/PointCloud2 clouds, with normals.\n"
               "Usage: rosrun hpds hpds_node ~input:=TOPIC [_KEY:=VALUE ...]\n"
               "   or: roslaunch hpds hpds.launch input:=TOPIC [spacing:=0.1] [normals:=true] [mode:=map "
               "fixed_frame:=odom]\n"
               "Subscribes ~input; publishes ~output (the samples with every input field and normals), and in map "
               "mode ~new_samples and ~local_map; services ~save_map, ~load_map, ~clear_map; status on "
               "/diagnostics.\n"
               "Parameters: the keys of config/hpds.yaml in the node's namespace (_output/spacing:=0.2, _mode:=map "
               "_ros/fixed_frame:=odom, _threads:=2), or a YAML file as _config_file:=PATH. A node started with rosrun "
               "keeps the parameters an earlier launch left on the master.\n"
               "Manual: docs/ros.md in the hpds package.\n";
}

}  // namespace

int main(int argc, char **argv) {
  if (asksForHelp(argc, argv)) {
    printHelp();
    return 0;
  }
  // Every frame's scratch is freed and allocated again: keep it in the process (a dense frame otherwise spent a
  // tenth of its time in page faults). The nodelet lives in a manager's process, whose policy is not its to set.
  hpds::keepFreedFrameMemory();
  ros::init(argc, argv, "hpds", ros::init_options::NoSigintHandler);
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  ros::NodeHandle nh;
  ros::NodeHandle pnh("~");
  ros::XMLRPCManager::instance()->unbind("shutdown");
  ros::XMLRPCManager::instance()->bind("shutdown", onShutdownRequest);
  std::unique_ptr<hpds_node::HpdsServer> server;
  try {
    server = std::make_unique<hpds_node::HpdsServer>(nh, pnh, ros::this_node::getName());
  } catch (const std::invalid_argument &e) {
    ROS_FATAL_STREAM("hpds: invalid parameter, not starting: " << e.what());
    return 1;
  } catch (const std::runtime_error &e) {  // ros/load_map_on_start: the map file exists but cannot be loaded
    ROS_FATAL_STREAM("hpds: not starting: " << e.what());
    return 1;
  }
  ros::CallbackQueue &queue = *ros::getGlobalCallbackQueue();
  while (!g_stop_requested && ros::ok()) queue.callAvailable(ros::WallDuration(0.1));
  const bool saved = server->shutdown();  // stops the workers, saves and logs while roscpp is still up
  server.reset();
  ros::shutdown();
  return saved ? 0 : 1;
}
