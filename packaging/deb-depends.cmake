# CPack project config file (CPACK_PROJECT_CONFIG_FILE), run by cpack for each generator.
# For DEB: fills CPACK_DEBIAN_PACKAGE_DEPENDS from the agvloc binary's NEEDED libraries, so the
# package stays complete when a component links a new library. A small dpkg-shlibdeps that also
# works for the arm64 cross build, where some libraries come from unpacked packages
# (toolchain/prepare-aarch64.sh writes their "file package version" map) rather than dpkg's
# database. Minimum versions are the upstream versions built against (Debian revision dropped).
if(NOT CPACK_GENERATOR STREQUAL "DEB")
  return()
endif()

file(READ "${CPACK_AGV_BINARY_LIST}" _agv_bin)
string(STRIP "${_agv_bin}" _agv_bin)
execute_process(COMMAND ${CPACK_AGV_READELF} -d "${_agv_bin}" OUTPUT_VARIABLE _agv_dyn
                RESULT_VARIABLE _agv_rc)
if(NOT _agv_rc EQUAL 0)
  message(FATAL_ERROR "deb-depends: ${CPACK_AGV_READELF} -d ${_agv_bin} failed")
endif()
string(REGEX MATCHALL "\\(NEEDED\\)[^\n]*\\[[^]\n]+\\]" _agv_needed "${_agv_dyn}")

set(_agv_filemap "")
if(CPACK_AGV_EXTRA_FILEMAP AND EXISTS "${CPACK_AGV_EXTRA_FILEMAP}")
  file(STRINGS "${CPACK_AGV_EXTRA_FILEMAP}" _agv_filemap)
endif()

set(_agv_depends "")
foreach(_line ${_agv_needed})
  string(REGEX REPLACE ".*\\[([^]]+)\\]" "\\1" _so "${_line}")
  set(_pkg "")
  set(_ver "")
  foreach(_entry ${_agv_filemap})
    if(_entry MATCHES "^([^ ]+) ([^ ]+) ([^ ]+)$" AND CMAKE_MATCH_1 STREQUAL _so)
      set(_pkg ${CMAKE_MATCH_2})
      set(_ver ${CMAKE_MATCH_3})
      break()
    endif()
  endforeach()
  if(NOT _pkg)
    execute_process(COMMAND dpkg -S "*/${CPACK_AGV_TRIPLET}/${_so}" OUTPUT_VARIABLE _owner
                    ERROR_QUIET RESULT_VARIABLE _rc)
    if(_rc EQUAL 0 AND _owner MATCHES "^([^:, ]+)(:[a-z0-9]+)?[:,]")
      set(_pkg ${CMAKE_MATCH_1})
      execute_process(COMMAND dpkg-query -W -f=\${Version} "${_pkg}:${CPACK_DEBIAN_PACKAGE_ARCHITECTURE}"
                      OUTPUT_VARIABLE _ver ERROR_QUIET)
      if(NOT _ver)
        execute_process(COMMAND dpkg-query -W -f=\${Version} "${_pkg}" OUTPUT_VARIABLE _ver
                        ERROR_QUIET)
      endif()
    endif()
  endif()
  if(NOT _pkg OR NOT _ver)
    message(FATAL_ERROR "deb-depends: no Debian package found for ${_so} (needed by ${_agv_bin})")
  endif()
  string(REGEX REPLACE "-[^-]*$" "" _ver "${_ver}")  # drop the Debian revision
  list(APPEND _agv_depends "${_pkg} (>= ${_ver})")
endforeach()
list(REMOVE_DUPLICATES _agv_depends)
list(SORT _agv_depends)
string(REPLACE ";" ", " CPACK_DEBIAN_PACKAGE_DEPENDS "${_agv_depends}")
message(STATUS "deb-depends: ${CPACK_DEBIAN_PACKAGE_DEPENDS}")
