# Overhead tag detection speed against libapriltag on the full frame (hand-run; see the source).
if(AGV_BUILD_BENCHMARKS)
  find_package(benchmark REQUIRED)
  add_executable(bench_overhead_detect ${PROJECT_SOURCE_DIR}/tests/bench/bench_overhead_detect.cpp)
  target_link_libraries(bench_overhead_detect PRIVATE agv_overhead agv_sim agv_warnings
                                                      benchmark::benchmark)
endif()

# agvloc-overhead's exposure -> MQTT publish latency in its live loop on paced cameras (hand-run
# against a broker; see the source). Not a test: the figure depends on the machine's load.
if(AGV_BUILD_BENCHMARKS)
  add_executable(bench_overhead_latency ${PROJECT_SOURCE_DIR}/tests/bench/bench_overhead_latency.cpp)
  target_link_libraries(bench_overhead_latency PRIVATE agv_overhead_app agv_sim agv_warnings)
  target_compile_definitions(bench_overhead_latency PRIVATE AGV_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
endif()

# The classical tray fit's cost per covered tray at 3840 x 2160 (hand-run; see the source).
if(AGV_BUILD_BENCHMARKS)
  add_executable(bench_tray_fit ${PROJECT_SOURCE_DIR}/tests/bench/bench_tray_fit.cpp)
  target_include_directories(bench_tray_fit PRIVATE ${PROJECT_SOURCE_DIR}/tests/overhead)
  target_link_libraries(bench_tray_fit PRIVATE agv_overhead agv_sim agv_warnings
                                               benchmark::benchmark)
endif()
