# The AR overlay (src/tracking/overlay.h); included by this folder's CMakeLists.txt.
arpos_test(overlay_test
  SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/overlay_test.cc
  DEPS arpos_tracking_overlay arpos_feedback arpos_sensor arpos_geometry arpos_util ${OpenCV_LIBS}
  LABELS unit)
