# Tracking time per frame by step (Google Benchmark; not in the default ctest
# set): tracking_bench, run on a prepared case (see tracking_bench.cc).
# Included by this folder's CMakeLists.txt.
find_package(benchmark QUIET)
if(benchmark_FOUND AND TARGET arpos_tracking)
  add_executable(tracking_bench ${CMAKE_CURRENT_LIST_DIR}/tracking_bench.cc)
  target_compile_options(tracking_bench PRIVATE ${ARPOS_WARNINGS})
  target_include_directories(tracking_bench PRIVATE ${CMAKE_SOURCE_DIR}/tests)
  target_link_libraries(tracking_bench PRIVATE arpos_tracking arpos_eval arpos_room_map arpos_store arpos_sensor
                                               arpos_util benchmark::benchmark)
endif()
