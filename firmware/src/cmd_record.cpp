// Placeholder until the owning issue lands; exits 2 so no caller mistakes it for success.
#include <cstdio>

#include "commands.hpp"

namespace agv::cmd {

int record(int, char**) {
  std::fprintf(stderr, "agvloc record: not implemented yet\n");
  return 2;
}

}  // namespace agv::cmd
