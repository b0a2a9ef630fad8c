# Per-camera detector processes and one tracker on a mosquitto broker against replay in one
# process (test_overhead_detect_broker.py; skipped without mosquitto).
if(AGV_DESK_CMD)
  find_package(Python3 REQUIRED COMPONENTS Interpreter)
  string(REPLACE ";" " " _agv_db_emu "${CMAKE_CROSSCOMPILING_EMULATOR}")
  string(STRIP "${_agv_db_emu} $<TARGET_FILE:agvloc-overhead>" _agv_db_cmd)
  add_test(NAME overhead_detect_broker
           COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_detect_broker.py
                   "${_agv_db_cmd}" "${AGV_DESK_CMD}"
                   ${CMAKE_CURRENT_SOURCE_DIR}/data/two_camera_site.yaml
                   ${CMAKE_CURRENT_BINARY_DIR}/overhead_detect_broker)
  set_tests_properties(overhead_detect_broker PROPERTIES LABELS "overhead;mqtt" TIMEOUT 300
                       SKIP_RETURN_CODE 77)
endif()
