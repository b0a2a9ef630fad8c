# Overhead tag detection speed against libapriltag on the full frame (hand-run; see the source).
if(AGV_BUILD_BENCHMARKS)
  find_package(benchmark REQUIRED)
  add_executable(bench_overhead_detect ${PROJECT_SOURCE_DIR}/tests/bench/bench_overhead_detect.cpp)
  target_link_libraries(bench_overhead_detect PRIVATE agv_overhead agv_sim agv_warnings
                                                      benchmark::benchmark)
endif()
