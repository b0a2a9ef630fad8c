# Cross builds only (put on CMAKE_MODULE_PATH by toolchain/aarch64-linux-gnu.cmake).
# libyaml-cpp-dev is not Multi-Arch in Debian bookworm, so the arm64 -dev cannot be installed next
# to the amd64 one. The headers are architecture-independent (no generated configuration), so the
# installed ones are used with the arm64 runtime library libyaml-cpp0.7:arm64. Creates the target
# `yaml-cpp`, as yaml-cpp-config.cmake does.
find_path(YAML_CPP_INCLUDE_DIR yaml-cpp/yaml.h)
find_library(YAML_CPP_LIBRARY NAMES yaml-cpp libyaml-cpp.so.0.7 libyaml-cpp.so.0.8)
if(YAML_CPP_LIBRARY)
  string(REGEX MATCH "[0-9]+\\.[0-9]+(\\.[0-9]+)?$" yaml-cpp_VERSION "${YAML_CPP_LIBRARY}")
endif()

include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(yaml-cpp
  REQUIRED_VARS YAML_CPP_LIBRARY YAML_CPP_INCLUDE_DIR
  VERSION_VAR yaml-cpp_VERSION)

if(yaml-cpp_FOUND AND NOT TARGET yaml-cpp)
  add_library(yaml-cpp SHARED IMPORTED)
  set_target_properties(yaml-cpp PROPERTIES
    IMPORTED_LOCATION ${YAML_CPP_LIBRARY}
    INTERFACE_INCLUDE_DIRECTORIES ${YAML_CPP_INCLUDE_DIR})
  set(YAML_CPP_LIBRARIES yaml-cpp)
  set(YAML_CPP_INCLUDE_DIRS ${YAML_CPP_INCLUDE_DIR})
endif()
