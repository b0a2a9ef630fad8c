// What the VDA 5050 tests share: the identity of the test vehicle (the mqtt test's too).
#pragma once

#include "agv/vda5050/vda5050.hpp"

namespace agv::vda5050::test {

inline Identity ident(Version v = Version::k2_1_0) {
  Identity id;
  id.version = v;
  id.manufacturer = "acme";
  id.serial_number = "agv-7";
  id.map_id = "hall-1";
  return id;
}

}  // namespace agv::vda5050::test
