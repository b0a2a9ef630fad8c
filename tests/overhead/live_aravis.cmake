# agvloc-overhead record on scripted cameras (record, replay of what was recorded, SIGKILL
# mid-write), and run / record against Aravis's simulated GigE Vision camera on the loopback
# interface (label aravis too: needs aravis-tools; one fake camera per host, taken under
# /tmp/agv-fake-gv.lock). A few seconds each.
agv_add_test(test_overhead_record SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_record.cpp
             LIBS agv_overhead_app agv_sim agv_fakecamera agv_posix LABELS overhead TIMEOUT 60)
# Under qemu-aarch64 (7.2) a forked child that starts threads aborts inside the emulator
# (cpu_exec: assertion failed): the SIGKILL test is skipped there; it runs natively and under ASan.
if(CMAKE_CROSSCOMPILING AND TARGET test_overhead_record)
  target_compile_definitions(test_overhead_record PRIVATE AGV_FORK_THREADS_UNSUPPORTED=1)
endif()
if(TARGET agv_aravis)
  agv_add_test(test_overhead_aravis SOURCES ${CMAKE_CURRENT_SOURCE_DIR}/test_overhead_aravis.cpp
               LIBS agv_overhead_app LABELS overhead aravis TIMEOUT 90)
  target_compile_definitions(test_overhead_aravis PRIVATE
                             AGV_OVERHEAD_BIN="$<TARGET_FILE:agvloc-overhead>")
  add_dependencies(test_overhead_aravis agvloc-overhead)
endif()
