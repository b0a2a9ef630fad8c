# agvloc-overhead's diagnostics pictures (overhead/src/diag_views.hpp): /site.svg and
# /camera/<index>.png over loopback, served from fixed views (decoded with OpenCV's imgcodecs).
agv_add_test(test_overhead_diag_views
             SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_diag_views.cpp
             LIBS agv_overhead_app opencv_imgcodecs LABELS unit overhead TIMEOUT 60)
