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
find_package(catkin REQUIRED COMPONENTS ${HPDS_CATKIN_COMPONENTS})

find_package(Eigen3 3.3 REQUIRED NO_MODULE)
# Another catkin package gets hpds's libraries with find_package(catkin REQUIRED COMPONENTS hpds).
catkin_package(
  INCLUDE_DIRS hpds_core/include
  LIBRARIES hpds_core hpds_pcl
  DEPENDS EIGEN3 PCL)
