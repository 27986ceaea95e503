# OpenCV and AprilTag for the camera path (appliance/capture, appliance/markers,
# hil_tests/camera_sim) and calibration. Include from a CMakeLists.txt that needs them.
# OpenCV's imported targets are directory-scoped, so find_package runs per include.
find_package(OpenCV 4 REQUIRED COMPONENTS core imgproc calib3d imgcodecs videoio)

# The Debian AprilTag 3 package installs no CMake config: link the two libraries directly.
if(NOT TARGET arnav_apriltag)
  find_path(APRILTAG_INCLUDE_DIR apriltag/apriltag.h REQUIRED)
  find_library(APRILTAG_LIBRARY apriltag REQUIRED)
  find_library(APRILTAG_UTILS_LIBRARY apriltag-utils REQUIRED)
  add_library(arnav_apriltag INTERFACE)
  target_include_directories(arnav_apriltag INTERFACE ${APRILTAG_INCLUDE_DIR})
  target_link_libraries(arnav_apriltag INTERFACE ${APRILTAG_LIBRARY} ${APRILTAG_UTILS_LIBRARY} Threads::Threads m)
endif()
