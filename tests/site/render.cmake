# Site renderer (algo/src/sim/site_render_*.cpp, docs/design/site_render.md): projection against
# OpenCV's projectPoints, occlusion, a rendered tray tag decoded by libapriltag, determinism.
agv_add_test(test_site_render SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_site_render.cpp
             LIBS agv_sim opencv_calib3d LABELS unit site TIMEOUT 120)
