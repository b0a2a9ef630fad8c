# A faster linker than GNU ld (bfd). Linking is ~15 % of a build here (~110 executables, most
# of them tests, each linked with the static agv_* libraries and OpenCV), and bfd takes 2.5x as
# long as lld and 1.5x as long as gold on the same test program. lld where the compiler driver
# finds it (native g++ and clang), else gold (the aarch64 cross g++ finds
# aarch64-linux-gnu-ld.gold but no ld.lld); AGV_LINKER=default keeps the toolchain's own. The
# binaries are the same programs: no option here changes code generation.
include(CheckLinkerFlag)
set(AGV_LINKER "auto" CACHE STRING "Linker: auto (lld, else gold, else the default), lld, gold or default")
set_property(CACHE AGV_LINKER PROPERTY STRINGS auto lld gold default)
set(_agv_linker "")
if(AGV_LINKER STREQUAL "auto")
  check_linker_flag(CXX "-fuse-ld=lld" AGV_LINKER_LLD_WORKS)
  if(AGV_LINKER_LLD_WORKS)
    set(_agv_linker lld)
  else()
    check_linker_flag(CXX "-fuse-ld=gold" AGV_LINKER_GOLD_WORKS)
    if(AGV_LINKER_GOLD_WORKS)
      set(_agv_linker gold)
    endif()
  endif()
elseif(AGV_LINKER STREQUAL "lld" OR AGV_LINKER STREQUAL "gold")
  set(_agv_linker ${AGV_LINKER})
elseif(NOT AGV_LINKER STREQUAL "default")
  message(FATAL_ERROR "AGV_LINKER=${AGV_LINKER}: expected auto, lld, gold or default")
endif()
if(_agv_linker)
  add_link_options(-fuse-ld=${_agv_linker})
  message(STATUS "Linker: ${_agv_linker}")
endif()
unset(_agv_linker)
