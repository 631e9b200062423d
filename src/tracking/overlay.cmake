# The AR overlay image of tracking mode (overlay.h); included by this folder's
# CMakeLists.txt.
arpos_library(arpos_tracking_overlay
  SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/overlay.cc
  DEPS arpos_feedback arpos_simulation arpos_sensor arpos_geometry arpos_util ${OpenCV_LIBS})
