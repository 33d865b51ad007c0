// hpds/HpdsNodelet: the nodelet entry point of HpdsServer (hpds_node is the other one).
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include <memory>
#include <stdexcept>

#include "hpds_node/HpdsServer.hpp"

namespace hpds_node {

class HpdsNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      // The multi-threaded handles: the subscriber callback only queues, so it may run beside other nodelets'.
      server_ = std::make_unique<HpdsServer>(getMTNodeHandle(), getMTPrivateNodeHandle(), getName());
    } catch (const std::invalid_argument &e) {
      NODELET_FATAL_STREAM("hpds: invalid parameter, not starting: " << e.what());
      // A nodelet cannot exit its manager; failing the load makes `nodelet load/standalone` report it.
      throw;
    } catch (const std::runtime_error &e) {  // ros/load_map_on_start: the map file cannot be loaded
      NODELET_FATAL_STREAM("hpds: not starting: " << e.what());
      throw;
    }
  }

  std::unique_ptr<HpdsServer> server_;
};

}  // namespace hpds_node

PLUGINLIB_EXPORT_CLASS(hpds_node::HpdsNodelet, nodelet::Nodelet)
