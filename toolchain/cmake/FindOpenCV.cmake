# Cross builds only (put on CMAKE_MODULE_PATH by toolchain/aarch64-linux-gnu.cmake).
# Debian's OpenCVConfig.cmake is in libopencv-dev, which is not Multi-Arch and depends on every
# OpenCV module (some of them not co-installable), so the arm64 build finds the module libraries
# directly. Creates the same imported targets as OpenCVConfig.cmake (opencv_<module>) and sets
# OpenCV_FOUND, OpenCV_VERSION, OpenCV_INCLUDE_DIRS, OpenCV_LIBS.
# Headers: /usr/include/opencv4 from the Multi-Arch: same -dev packages (identical on every
# architecture). Libraries: the arm64 runtime packages (soname libopencv_<m>.so.<MAJOR><MINOR:02d>,
# e.g. .so.406, and file libopencv_<m>.so.<MAJOR>.<MINOR>.<REVISION>).
find_path(OpenCV_INCLUDE_DIR opencv2/core/version.hpp PATH_SUFFIXES opencv4)
set(OpenCV_INCLUDE_DIRS ${OpenCV_INCLUDE_DIR})

if(OpenCV_INCLUDE_DIR)
  file(STRINGS ${OpenCV_INCLUDE_DIR}/opencv2/core/version.hpp _agv_ocv_ver
       REGEX "#define CV_VERSION_(MAJOR|MINOR|REVISION) ")
  foreach(_part MAJOR MINOR REVISION)
    string(REGEX REPLACE ".*#define CV_VERSION_${_part} +([0-9]+).*" "\\1" OpenCV_VERSION_${_part}
           "${_agv_ocv_ver}")
  endforeach()
  set(OpenCV_VERSION_PATCH ${OpenCV_VERSION_REVISION})
  set(OpenCV_VERSION
      ${OpenCV_VERSION_MAJOR}.${OpenCV_VERSION_MINOR}.${OpenCV_VERSION_REVISION})
endif()

# Link-time dependencies between the modules we may be asked for.
set(_agv_ocv_deps_core "")
set(_agv_ocv_deps_imgproc core)
set(_agv_ocv_deps_imgcodecs imgproc core)
set(_agv_ocv_deps_calib3d imgproc core)

set(OpenCV_LIBS "")
set(_agv_ocv_components ${OpenCV_FIND_COMPONENTS})
list(PREPEND _agv_ocv_components core)
list(REMOVE_DUPLICATES _agv_ocv_components)
set(_agv_ocv_minor2 "0${OpenCV_VERSION_MINOR}")
string(REGEX MATCH "..$" _agv_ocv_minor2 "${_agv_ocv_minor2}")
set(_agv_ocv_soversion "${OpenCV_VERSION_MAJOR}${_agv_ocv_minor2}")
foreach(_m ${_agv_ocv_components})
  find_library(OpenCV_${_m}_LIBRARY
               NAMES opencv_${_m} libopencv_${_m}.so.${_agv_ocv_soversion}
                     libopencv_${_m}.so.${OpenCV_VERSION})
  if(OpenCV_${_m}_LIBRARY)
    set(OpenCV_${_m}_FOUND TRUE)
    if(NOT TARGET opencv_${_m})
      add_library(opencv_${_m} SHARED IMPORTED)
      set_target_properties(opencv_${_m} PROPERTIES
        IMPORTED_LOCATION ${OpenCV_${_m}_LIBRARY}
        INTERFACE_INCLUDE_DIRECTORIES ${OpenCV_INCLUDE_DIR})
      set(_agv_deps "")
      foreach(_d ${_agv_ocv_deps_${_m}})
        list(APPEND _agv_deps opencv_${_d})
      endforeach()
      if(_agv_deps)
        set_target_properties(opencv_${_m} PROPERTIES INTERFACE_LINK_LIBRARIES "${_agv_deps}")
      endif()
    endif()
    list(APPEND OpenCV_LIBS opencv_${_m})
  else()
    set(OpenCV_${_m}_FOUND FALSE)
  endif()
endforeach()

include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(OpenCV
  REQUIRED_VARS OpenCV_INCLUDE_DIR OpenCV_core_LIBRARY
  VERSION_VAR OpenCV_VERSION
  HANDLE_COMPONENTS)
