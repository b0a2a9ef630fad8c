# Tag detection on the ceiling cameras' images (tag_code, tag_detect, tag_fix): unit tests on
# frames of the site renderer.
agv_add_test(test_overhead_tag_code SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_tag_code.cpp
             LIBS agv_overhead LABELS unit)
agv_add_test(test_overhead_tag_detect SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_tag_detect.cpp
             LIBS agv_overhead agv_sim LABELS unit)
# The tray-plane fixes are the site tracker's, not the vehicle's.
if(AGV_BUILD_OVERHEAD_APP AND NOT AGV_OVERHEAD_SMOKE_ONLY)
  agv_add_test(test_overhead_tag_fix SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_tag_fix.cpp
               LIBS agv_overhead agv_sim LABELS unit)
endif()
