// Text for XML and SVG (the site maps of agvloc-desk and agvloc-overhead's page): names from a
// site file must not open a tag or close an attribute.
#pragma once

#include <string>
#include <string_view>

namespace agv {

// &, <, > and " as entities; everything else as it is.
std::string escape_xml(std::string_view text);

}  // namespace agv
