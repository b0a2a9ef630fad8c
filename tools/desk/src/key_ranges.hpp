// Calibration results against the configuration's accepted ranges (the key table, keys.hpp, is
// the one source of the ranges): a value the configuration would reject is an error of the
// calibration, never an "ok" written into a snippet that --check-config then refuses.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>

#include "agv/config/keys.hpp"

namespace agv::desk {

// Empty when `value` (in the key's YAML unit) is finite and within the key's range; else one
// line naming the key, the value and the range.
inline std::string outside_key_range(const std::string& key, double value) {
  const config::Key* k = config::find_key(key);
  if (!k) return key + ": not a configuration key";
  if (std::isfinite(value) && value >= k->lo && value <= k->hi) return {};
  char buf[256];
  std::snprintf(buf, sizeof buf, "%s %.6g is outside the accepted %s%s%s", key.c_str(), value,
                config::format_range(*k).c_str(), k->unit.empty() ? "" : " ", k->unit.c_str());
  return buf;
}

}  // namespace agv::desk
