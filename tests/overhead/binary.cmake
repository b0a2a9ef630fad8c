# agvloc-overhead, the composition root (overhead/, docs/guide/overhead.md): its configuration,
# outputs and input checks (gtest), and the binary on a rendered two-camera recording (scripts,
# only where agvloc-desk renders: AGV_DESK_CMD).
find_package(nlohmann_json 3 REQUIRED)
agv_add_test(test_overhead_config SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_config.cpp
             LIBS agv_overhead_app nlohmann_json::nlohmann_json LABELS unit overhead TIMEOUT 60)

# The binary on a two-camera recording (agv_overhead_binary_test, CMakeLists.txt): replay against
# the truth, bad input, and MQTT on a broker of its own; only where agvloc-desk renders.
if(AGV_DESK_CMD)
  find_package(Python3 REQUIRED COMPONENTS Interpreter)
  foreach(_case replay bad_input mqtt)
    agv_overhead_binary_test(${_case})
  endforeach()
  set_tests_properties(overhead_mqtt PROPERTIES LABELS "overhead;mqtt")
  # The same on RabbitMQ's MQTT plugin: the tracker depends on MQTT, not on one broker. The
  # Erlang node boots in 5-20 s; skipped where rabbitmq-server is not installed.
  string(REPLACE ";" " " _agv_oh_emu "${CMAKE_CROSSCOMPILING_EMULATOR}")
  string(STRIP "${_agv_oh_emu} $<TARGET_FILE:agvloc-overhead>" _agv_oh_cmd)
  add_test(NAME overhead_mqtt_rabbitmq
           COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_mqtt.py
                   "${_agv_oh_cmd}" "${AGV_DESK_CMD}" ${CMAKE_CURRENT_SOURCE_DIR}/data/two_camera_site.yaml
                   ${CMAKE_CURRENT_BINARY_DIR}/overhead_mqtt_rabbitmq rabbitmq)
  set_tests_properties(overhead_mqtt_rabbitmq PROPERTIES LABELS "overhead;mqtt" TIMEOUT 180
                       SKIP_RETURN_CODE 77)
endif()

# A camera fault of `run` published over MQTT as a VDA 5050 state error (a device that does not
# exist; about 3 s). Python without agvloc-desk: the run needs no recording.
find_package(Python3 COMPONENTS Interpreter)
if(Python3_Interpreter_FOUND AND NOT CMAKE_CROSSCOMPILING)
  add_test(NAME overhead_camera_fault_mqtt
           COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_camera_fault_mqtt.py
                   $<TARGET_FILE:agvloc-overhead> ${CMAKE_CURRENT_SOURCE_DIR}/data/two_camera_site.yaml
                   ${CMAKE_CURRENT_BINARY_DIR}/overhead_camera_fault_mqtt)
  set_tests_properties(overhead_camera_fault_mqtt PROPERTIES LABELS "overhead;mqtt" TIMEOUT 60
                       SKIP_RETURN_CODE 77)
endif()

# detect on a live (scripted) camera: threads, label tsan too. Under 1 s.
agv_add_test(test_overhead_detect_live
             SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_detect_live.cpp
             LIBS agv_overhead_app agv_sim agv_fakecamera agv_posix LABELS unit overhead tsan
             TIMEOUT 60)

# The live loop on scripted cameras (threads: label tsan too). About 2 s.
agv_add_test(test_overhead_live SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_live.cpp
             LIBS agv_overhead_app agv_sim agv_fakecamera agv_posix LABELS unit overhead tsan
             TIMEOUT 60)
