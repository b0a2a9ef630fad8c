// A scratch directory per test process, emptied first: the process id in its name keeps two
// runs of the same test binary (ctest -j, a repeated run) out of each other's files.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

namespace agv::test_support {

inline std::filesystem::path fresh_dir(const std::string& suite, const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path d = fs::temp_directory_path() /
                     ("agv_test_" + suite + "_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

}  // namespace agv::test_support
