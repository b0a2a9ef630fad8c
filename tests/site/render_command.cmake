# agvloc-desk render-site (tools/desk/src/cmd_render_site.cpp): the example site at 320x200,
# 3 frames, every ceiling camera and one on a vehicle; recordings read back by the replay reader.
agv_add_test(test_render_command SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_render_command.cpp
             LIBS agv_desk LABELS unit site TIMEOUT 60)
