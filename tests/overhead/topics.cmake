# What may become part of agvloc-overhead's MQTT topics (overhead/src/topics.hpp): the configured
# interface name, manufacturer and detections prefix, the site's ids, the tracker's subscription.
agv_add_test(test_overhead_topics SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_topics.cpp
             LIBS agv_overhead_app LABELS unit overhead TIMEOUT 60)
