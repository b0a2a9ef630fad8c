# agvloc-overhead, the composition root (overhead/, docs/guide/overhead.md): its configuration,
# outputs and input checks (gtest), and the binary on a rendered two-camera recording (scripts,
# only where agvloc-desk renders: AGV_DESK_CMD).
find_package(nlohmann_json 3 REQUIRED)
agv_add_test(test_overhead_config SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_config.cpp
             LIBS agv_overhead_app nlohmann_json::nlohmann_json LABELS unit overhead TIMEOUT 60)
