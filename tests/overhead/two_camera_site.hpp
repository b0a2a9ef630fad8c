// The overhead application tests' site (data/two_camera_site.yaml: two ceiling cameras) and the
// two vehicles standing on it.
#pragma once

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "inputs.hpp"

namespace agv::overhead_app::test {

inline constexpr char kTwoCameraSitePath[] =
    AGV_SOURCE_DIR "/tests/overhead/data/two_camera_site.yaml";

inline site::Site two_camera_site() {
  site::Site s;
  std::vector<std::string> errors;
  EXPECT_TRUE(load_site_file(kTwoCameraSitePath, &s, &errors));
  return s;
}

}  // namespace agv::overhead_app::test
