# Detections between a per-camera detector process and the tracker (detection_msg.cpp).
agv_add_test(test_overhead_detection_msg SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_detection_msg.cpp
             LIBS agv_overhead LABELS unit)
