# The per-vehicle EKF (algo/src/overhead/tracker*.cpp): synthetic fixes, no rendering. The binary
# counts heap allocations (it replaces the global operator new).
agv_add_test(test_tracker SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_tracker.cpp LIBS agv_overhead
             LABELS unit overhead)
