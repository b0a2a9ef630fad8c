// Loading a site file (docs/guide/site.md) for the desk tool's commands: the site text and the
// floor-landmark map it names (relative to the site file's folder), both regular files under a
// size cap, then parse_site.
#pragma once

#include <string>

#include "agv/site/site.hpp"

namespace agv::desk {

// True with *out on success. Else false, and *error_lines holds one line per problem
// ("SITE: key (line N): message\n"), every problem of the file, ready to print.
bool load_site(const std::string& path, agv::site::Site* out, std::string* error_lines);

}  // namespace agv::desk
