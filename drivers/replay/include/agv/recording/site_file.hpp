// A site file read from disk with the floor map it names (relative to the site file's folder),
// both bounded by SiteLimits, for the products that load a site at start (agvloc's second camera,
// agvloc-overhead).
#pragma once

#include <string>
#include <vector>

#include "agv/site/site.hpp"

namespace agv::recording {

// False with one line per problem in *errors: the read error (naming the path), or
// "PATH: message" for the floor map and each problem the site parser found.
bool read_site_file(const std::string& path, site::Site* out, std::vector<std::string>* errors);

}  // namespace agv::recording
