// Placeholder until the owning issue lands; exits 2 so no caller mistakes it for success.
#include <cstdio>

#include "commands.hpp"

namespace agv::cmd {

int sim(int, char**) {
  std::fprintf(stderr, "agvloc sim: not implemented yet\n");
  return 2;
}

}  // namespace agv::cmd
