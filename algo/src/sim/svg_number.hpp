// SVG number formatting shared by the printable pages (landmark_page.cpp, apriltag_page.cpp).
#pragma once

#include <cstdio>
#include <string>

namespace agv::sim::detail {

// A length in mm as the pages write it: 0.1 µm resolution (far below any printer's), trailing
// zeros and a negative zero dropped so that the SVG text is stable and short.
inline std::string svg_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4f", v);
  std::string s = buf;
  while (!s.empty() && s.back() == '0') s.pop_back();
  if (!s.empty() && s.back() == '.') s.pop_back();
  if (s == "-0") s = "0";
  return s;
}

}  // namespace agv::sim::detail
