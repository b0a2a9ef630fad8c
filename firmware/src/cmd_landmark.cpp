// Placeholder until the owning issue lands; exits 2 so no caller mistakes it for success.
#include <cstdio>

#include "commands.hpp"

namespace agv::cmd {

int landmark(int, char**) {
  std::fprintf(stderr, "agvloc landmark: not implemented yet\n");
  return 2;
}

}  // namespace agv::cmd
