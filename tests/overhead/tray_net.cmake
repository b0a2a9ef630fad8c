# The learned tray detector (algo/src/overhead/tray_net*.cpp) with the committed model
# models/tray_obb.onnx on rendered held-out frames (tools/train/tray_obb/tray_scene.hpp).
agv_add_test(test_tray_net SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_tray_net.cpp
             LIBS agv_overhead agv_sim LABELS unit overhead)
if(TARGET test_tray_net)
  target_include_directories(test_tray_net PRIVATE ${CMAKE_SOURCE_DIR}/tools/train/tray_obb)
endif()

# agvloc-overhead with tray.method learned: an unusable model named at start, tags alone.
agv_add_test(test_overhead_tray_model SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_tray_model.cpp
             LIBS agv_overhead_app LABELS unit overhead)

# Re-acquisition of a vehicle lost while its tag was covered (algo/src/overhead/reacquire.cpp):
# the assignment and half-turn rules, and rendered frames with the committed model.
agv_add_test(test_reacquire SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_reacquire.cpp
             LIBS agv_overhead agv_sim LABELS unit overhead)
if(TARGET test_reacquire)
  target_include_directories(test_reacquire PRIVATE ${CMAKE_SOURCE_DIR}/tools/train/tray_obb)
endif()
