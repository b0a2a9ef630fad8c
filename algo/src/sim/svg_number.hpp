// SVG number formatting and the sheet layout shared by the printable pages (landmark_page.cpp,
// apriltag_page.cpp).
#pragma once

#include <algorithm>
#include <cstdio>
#include <ostream>
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

// A sheet of n printed cells in rows of `columns`, each cell_w wide and a caption line taller.
struct SheetGrid {
  double cell_w = 0.0, cell_h = 0.0;
  int cols = 1;
  double w = 0.0, h = 0.0;
  double cx(int i) const { return (i % cols + 0.5) * cell_w; }
  double cy(int i) const { return (i / cols) * cell_h + cell_w / 2; }
};

inline SheetGrid sheet_grid(double cell_w, int n, int columns) {
  SheetGrid g;
  g.cell_w = cell_w;
  g.cell_h = cell_w + 8.0;  // caption line under each cell
  g.cols = std::min(columns, n);
  const int rows = (n + g.cols - 1) / g.cols;
  g.w = g.cols * g.cell_w;
  g.h = rows * g.cell_h;
  return g;
}

// The SVG header of a sheet in mm with a white background; `what` names it in the comment.
inline void svg_sheet_open(std::ostream& os, const SheetGrid& g, const std::string& what) {
  os << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
     << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << svg_number(g.w) << "mm\" height=\""
     << svg_number(g.h) << "mm\" viewBox=\"0 0 " << svg_number(g.w) << " " << svg_number(g.h)
     << "\" shape-rendering=\"crispEdges\">\n"
     << "  <!-- " << what << " mm; print at 100% scale -->\n"
     << "  <rect x=\"0\" y=\"0\" width=\"" << svg_number(g.w) << "\" height=\"" << svg_number(g.h)
     << "\" fill=\"#fff\"/>\n";
}

// The caption under the cell centred at (cx, y).
inline void svg_caption(std::ostream& os, double cx, double y, const char* text) {
  os << "  <text x=\"" << svg_number(cx) << "\" y=\"" << svg_number(y)
     << "\" font-family=\"sans-serif\" font-size=\"3\" text-anchor=\"middle\">" << text
     << "</text>\n";
}

}  // namespace agv::sim::detail

namespace agv::sim {
// The two page generators use these unqualified; the header is internal to this folder.
using detail::sheet_grid;
using detail::SheetGrid;
using detail::svg_caption;
using detail::svg_number;
using detail::svg_sheet_open;
}  // namespace agv::sim
