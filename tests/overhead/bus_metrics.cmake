# /metrics of `run --detections-from-broker` (overhead/src/diag.cpp): the detections messages'
# counts, refusals by reason. The end-to-end check is in test_overhead_detect_broker.py.
agv_add_test(test_overhead_bus_metrics
             SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_bus_metrics.cpp
             LIBS agv_overhead_app LABELS unit overhead TIMEOUT 60)
