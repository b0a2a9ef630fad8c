// Placeholder until the command lands; refuses by name.
#include <cstdio>

#include "commands.hpp"

namespace agv::desk {
int render_site_command(int, char**) {
  std::fprintf(stderr, "agvloc-desk: not built yet\n");
  return 2;
}
}  // namespace agv::desk
