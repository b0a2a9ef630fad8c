# The site file: parser, checks, writer (algo/src/site/site_*.cpp) and `agvloc-desk site`.
agv_add_test(test_site_model SOURCES test_site_model.cpp LIBS agv_site LABELS unit site)
agv_add_test(test_site_desk SOURCES test_site_desk.cpp LIBS agv_desk LABELS unit site)
# The command end to end: the example site is OK; a broken one exits 2 naming each key and line.
add_test(NAME desk_site_check
         COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/site_check_command.sh $<TARGET_FILE:agvloc-desk>
                 ${CMAKE_SOURCE_DIR} ${CMAKE_CURRENT_BINARY_DIR}/site_check_work)
set_tests_properties(desk_site_check PROPERTIES LABELS "unit;site" TIMEOUT 120)
