# The classical tray fit (algo/src/overhead/tray_fit*.cpp): rendered frames of one ceiling camera
# with parcels covering the vehicles' tags.
agv_add_test(test_tray_fit SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_tray_fit.cpp
             LIBS agv_overhead agv_sim LABELS unit overhead)
