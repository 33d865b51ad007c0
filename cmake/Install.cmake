# What `cmake --install` (and `catkin_make install`) puts in the prefix: the libraries hpds::core and hpds::pcl with
# their headers and a CMake package (find_package(hpds)), the `hpds` tool, the license, and for the ROS package the
# node, nodelet plugin, launch and config files (package.xml comes from catkin_package()).
include(CMakePackageConfigHelpers)
set(HPDS_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/hpds)

set(HPDS_INSTALLED_LIBS hpds_core)
if(HPDS_WITH_PCL)
  list(APPEND HPDS_INSTALLED_LIBS hpds_pcl)
endif()
install(TARGETS ${HPDS_INSTALLED_LIBS} EXPORT hpdsTargets
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
# Public headers; the evaluation library is not installed, nor are its headers.
set(HPDS_HEADER_EXCLUDES PATTERN eval EXCLUDE)
if(NOT HPDS_WITH_PCL)
  list(APPEND HPDS_HEADER_EXCLUDES PATTERN pcl EXCLUDE PATTERN pcl.hpp EXCLUDE)
endif()
install(DIRECTORY hpds_core/include/hpds DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} ${HPDS_HEADER_EXCLUDES})
install(EXPORT hpdsTargets NAMESPACE hpds:: DESTINATION ${HPDS_CMAKE_DIR})
if(BUILD_SHARED_LIBS)
  set(HPDS_STATIC_LIBS FALSE)
else()
  set(HPDS_STATIC_LIBS TRUE)
endif()
configure_package_config_file(cmake/hpdsConfig.cmake.in ${CMAKE_CURRENT_BINARY_DIR}/hpdsConfig.cmake
  INSTALL_DESTINATION ${HPDS_CMAKE_DIR})
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/hpdsConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/hpdsConfig.cmake ${CMAKE_CURRENT_BINARY_DIR}/hpdsConfigVersion.cmake
  DESTINATION ${HPDS_CMAKE_DIR})
install(FILES LICENSE DESTINATION ${CMAKE_INSTALL_DATADIR}/doc/hpds)

# pkg-config for the core library alone (Eigen, no PCL, no ROS), relocatable: its prefix is found from the .pc
# file's own folder. The ROS package's hpds.pc (catkin's) names PCL's, VTK's and OpenNI's libraries as well.
file(RELATIVE_PATH HPDS_PC_TO_PREFIX "/${CMAKE_INSTALL_LIBDIR}/pkgconfig" "/")
string(REGEX REPLACE "/$" "" HPDS_PC_TO_PREFIX "${HPDS_PC_TO_PREFIX}")
configure_file(cmake/hpds_core.pc.in ${CMAKE_CURRENT_BINARY_DIR}/hpds_core.pc @ONLY)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/hpds_core.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)

if(HPDS_WITH_PCL)
  install(TARGETS hpds RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
  # `hpds analyze` draws its curves with it (found relative to the installed tool).
  install(PROGRAMS scripts/plot_quality.py DESTINATION ${CMAKE_INSTALL_DATADIR}/hpds/scripts)
endif()

if(HPDS_BUILD_NODE)
  # `rosrun hpds hpds ...` looks in lib/hpds; the launch and config files in share/hpds.
  install(TARGETS hpds RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
  install(DIRECTORY launch config DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})
  install(FILES LICENSE DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})
endif()

if(HPDS_BUILD_NODE)
  # catkin_package() writes lib/pkgconfig/hpds.pc and share/hpds/cmake/hpdsConfig.cmake (what catkin packages find
  # with find_package(catkin COMPONENTS hpds)) with the prefix of configure time, so `cmake --install --prefix P`
  # left /usr/local in them; hpds.pc's Cflags carry a stray backslash (`-I\${prefix}/include`), which pkg-config
  # passes on literally, and a placeholder description. Rewritten once installed, with the prefix of this install.
  # catkin's version file accepted versions the package's own (lib/cmake/hpds, SameMinorVersion) refuses, so that
  # find_package(hpds <version>) fell back to catkin's config and its catkin-only variables: it is replaced by the
  # package's, so both configs take the same versions.
  install(FILES ${CMAKE_CURRENT_BINARY_DIR}/hpdsConfigVersion.cmake DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION}/cmake
          RENAME hpdsConfig-version.cmake)
  if(CMAKE_SOURCE_DIR STREQUAL PROJECT_SOURCE_DIR AND NOT CATKIN_INSTALL_INTO_PREFIX_ROOT)
    # catkin's workspace files are not installed here (cmake/Catkin.cmake), but its marker is what makes roslaunch,
    # rosrun and pluginlib look for the package's programs and plugins under this prefix: written at install time,
    # into the prefix of that install.
    install(CODE [[
      if(NOT EXISTS "$ENV{DESTDIR}${CMAKE_INSTALL_PREFIX}/.catkin")
        file(WRITE "$ENV{DESTDIR}${CMAKE_INSTALL_PREFIX}/.catkin" "")
      endif()
    ]])
  endif()
  install(CODE "set(_hpds_configured_prefix \"${CMAKE_INSTALL_PREFIX}\")")
  install(CODE [[
    set(_hpds_pc "$ENV{DESTDIR}${CMAKE_INSTALL_PREFIX}/lib/pkgconfig/hpds.pc")
    if(EXISTS "${_hpds_pc}")
      file(READ "${_hpds_pc}" _hpds_text)
      string(REGEX REPLACE "^prefix=[^\n]*" "prefix=${CMAKE_INSTALL_PREFIX}" _hpds_text "${_hpds_text}")
      string(REPLACE "\\\${prefix}" "\${prefix}" _hpds_text "${_hpds_text}")
      string(REPLACE "Description: Description of hpds"
             "Description: hpds ROS package: hpds_core and hpds_pcl with PCL (hpds_core.pc: the core alone)"
             _hpds_text "${_hpds_text}")
      file(WRITE "${_hpds_pc}" "${_hpds_text}")
    endif()
    set(_hpds_catkin_config "$ENV{DESTDIR}${CMAKE_INSTALL_PREFIX}/share/hpds/cmake/hpdsConfig.cmake")
    if(EXISTS "${_hpds_catkin_config}" AND NOT _hpds_configured_prefix STREQUAL CMAKE_INSTALL_PREFIX)
      file(READ "${_hpds_catkin_config}" _hpds_text)
      string(REPLACE "${_hpds_configured_prefix}" "${CMAKE_INSTALL_PREFIX}" _hpds_text "${_hpds_text}")
      file(WRITE "${_hpds_catkin_config}" "${_hpds_text}")
    endif()
  ]])
endif()
