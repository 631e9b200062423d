# OpenIGTLink stream latency (Google Benchmark; not in the default ctest
# set): igtl_bench, see igtl_bench.cc. Included by this folder's
# CMakeLists.txt.
find_package(benchmark QUIET)
if(benchmark_FOUND AND TARGET arpos_streaming AND TARGET arpos_eval)
  add_executable(igtl_bench ${CMAKE_CURRENT_LIST_DIR}/igtl_bench.cc)
  target_compile_options(igtl_bench PRIVATE ${ARPOS_WARNINGS})
  target_link_libraries(igtl_bench PRIVATE arpos_igtl_test_client arpos_streaming arpos_eval arpos_util
                                           benchmark::benchmark)
endif()
