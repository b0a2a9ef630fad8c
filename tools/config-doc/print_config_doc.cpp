// Prints docs/guide/config.md as generated from the configuration key table:
//   build/default/tools/config-doc/agvloc-config-doc > docs/guide/config.md
#include <cstdio>
#include <string>

#include "agv/config/keys.hpp"

int main() {
  const std::string doc = agv::config::config_doc();
  return std::fwrite(doc.data(), 1, doc.size(), stdout) == doc.size() ? 0 : 1;
}
