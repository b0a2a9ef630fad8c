# AGV_SANITIZE selects the sanitizer build (presets asan, tsan; docs/design/security.md "Sanitizers in CI"):
#   address,undefined (or ON)  ASan + UBSan; with AGV_BUILD_FUZZERS the same build also links the
#                              libFuzzer harnesses, so CI compiles the tree once for both
#   thread                     TSan
# Every report is fatal (-fno-sanitize-recover=all): a test that triggers one fails instead of
# printing and passing. The runtime options (halt_on_error, ...) are in the test presets.
set(AGV_SANITIZE "OFF" CACHE STRING "Sanitizers: OFF, address,undefined (ON) or thread")
set_property(CACHE AGV_SANITIZE PROPERTY STRINGS OFF "address,undefined" thread)

if(AGV_SANITIZE STREQUAL "ON")
  set_property(CACHE AGV_SANITIZE PROPERTY VALUE "address,undefined")
endif()

set(AGV_SANITIZERS "")
if(AGV_SANITIZE STREQUAL "address,undefined")
  set(AGV_SANITIZERS address undefined)
elseif(AGV_SANITIZE STREQUAL "thread")
  set(AGV_SANITIZERS thread)
elseif(AGV_SANITIZE)
  message(FATAL_ERROR "AGV_SANITIZE=${AGV_SANITIZE}: expected OFF, address,undefined or thread")
endif()

if(AGV_SANITIZERS)
  list(JOIN AGV_SANITIZERS "," _agv_san)
  # Frame pointers: cheap, complete stacks in reports without the slow unwinder.
  add_compile_options(-fsanitize=${_agv_san} -fno-sanitize-recover=all -fno-omit-frame-pointer)
  add_link_options(-fsanitize=${_agv_san})
  unset(_agv_san)
endif()
