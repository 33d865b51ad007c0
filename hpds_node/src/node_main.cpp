// hpds_node: the standalone entry point of HpdsServer (the nodelet is the other one).
#include <ros/ros.h>

#include <stdexcept>

#include "hpds_node/HpdsServer.hpp"

int main(int argc, char **argv) {
  ros::init(argc, argv, "hpds");
  ros::NodeHandle nh;
  ros::NodeHandle pnh("~");
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
  ros::spin();
  server.reset();  // stop the worker while roscpp is still up
  return 0;
}
