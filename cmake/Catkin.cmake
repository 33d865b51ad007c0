# The catkin side of the ROS package, at the top level so that `catkin_make` and `catkin_make install` see one
# package (package.xml, devel and install spaces). Its side effects are wanted for every target: executables land in
# devel/lib/hpds (where rosrun and roslaunch look), libraries in devel/lib.

# The tests are registered with plain add_test; catkin's own gtest/run_tests machinery is not used.
set(CATKIN_ENABLE_TESTING OFF)
# catkin's scripts and pluginlib's ament hooks (found through nodelet) need Debian's Python with the ROS modules,
# not whatever python3 comes first on PATH (e.g. a pyenv shim): pin both lookups unless the user chose.
if(EXISTS /usr/bin/python3)
  if(NOT PYTHON_EXECUTABLE)
    set(PYTHON_EXECUTABLE /usr/bin/python3 CACHE FILEPATH "Python used by catkin")
  endif()
  if(NOT Python3_EXECUTABLE)
    set(Python3_EXECUTABLE /usr/bin/python3 CACHE FILEPATH "Python used by ament (pluginlib)")
  endif()
endif()

set(HPDS_CATKIN_COMPONENTS
  roscpp nodelet sensor_msgs std_msgs std_srvs geometry_msgs tf2 tf2_ros tf2_eigen rosbag diagnostic_updater
  diagnostic_msgs)
# Outside a catkin workspace (this clone's own build) the workspace's setup files (setup.bash, _setup_util.py, .catkin,
# ...) have no workspace to belong to, and catkin installs them to the prefix of configure time, whatever
# `cmake --install --prefix` says: /usr/local for everybody who installs elsewhere. A workspace sets this itself.
if(CMAKE_SOURCE_DIR STREQUAL PROJECT_SOURCE_DIR AND NOT DEFINED CATKIN_INSTALL_INTO_PREFIX_ROOT)
  set(CATKIN_INSTALL_INTO_PREFIX_ROOT FALSE)
endif()
find_package(catkin REQUIRED COMPONENTS ${HPDS_CATKIN_COMPONENTS})
# A catkin workspace's devel/lib lies outside the build folder, so the link path put it into the installed
# programs' RUNPATH, where a stale devel space would shadow the installed libraries. The install space's own
# libraries are found through $ORIGIN, the others through setup.bash's LD_LIBRARY_PATH, as for any ROS package.
if(CATKIN_DEVEL_PREFIX AND NOT CATKIN_DEVEL_PREFIX MATCHES "^${CMAKE_BINARY_DIR}(/|$)")
  set(CMAKE_INSTALL_RPATH_USE_LINK_PATH OFF)
endif()

find_package(Eigen3 3.3 REQUIRED NO_MODULE)
# Another catkin package gets hpds's libraries with find_package(catkin REQUIRED COMPONENTS hpds).
catkin_package(
  INCLUDE_DIRS hpds_core/include
  LIBRARIES hpds_core hpds_pcl
  DEPENDS EIGEN3 PCL)
