// The calibration board of the intrinsics calibration (calib_intrinsics.hpp): its description,
// OpenCV's ChArUco board for it, the simulator's board and the printable SVG.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "calib_intrinsics_internal.hpp"

namespace agv::desk::calib {

using detail::fmt;
using detail::kNoAruco;

#if AGV_HAVE_ARUCO
namespace {

struct DictName {
  const char* name;
  cv::aruco::PREDEFINED_DICTIONARY_NAME id;
};
const DictName kDicts[] = {
    {"DICT_4X4_50", cv::aruco::DICT_4X4_50},
    {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
    {"DICT_4X4_250", cv::aruco::DICT_4X4_250},
    {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
    {"DICT_5X5_50", cv::aruco::DICT_5X5_50},
    {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
    {"DICT_5X5_250", cv::aruco::DICT_5X5_250},
    {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
    {"DICT_6X6_50", cv::aruco::DICT_6X6_50},
    {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
    {"DICT_6X6_250", cv::aruco::DICT_6X6_250},
    {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
    {"DICT_7X7_50", cv::aruco::DICT_7X7_50},
    {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
    {"DICT_7X7_250", cv::aruco::DICT_7X7_250},
    {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
    {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL},
    {"DICT_APRILTAG_16h5", cv::aruco::DICT_APRILTAG_16h5},
    {"DICT_APRILTAG_25h9", cv::aruco::DICT_APRILTAG_25h9},
    {"DICT_APRILTAG_36h10", cv::aruco::DICT_APRILTAG_36h10},
    {"DICT_APRILTAG_36h11", cv::aruco::DICT_APRILTAG_36h11},
};

}  // namespace

namespace detail {

cv::Ptr<cv::aruco::CharucoBoard> charuco_board(const BoardSpec& s, std::string* error) {
  for (const auto& d : kDicts) {
    if (s.dictionary != d.name) continue;
    auto dict = cv::aruco::getPredefinedDictionary(d.id);
    const int needed = s.squares_x * s.squares_y / 2;
    if (dict->bytesList.rows < needed) {
      *error = "dictionary " + s.dictionary + " has " + std::to_string(dict->bytesList.rows) +
               " markers, the board needs " + std::to_string(needed);
      return {};
    }
    return cv::aruco::CharucoBoard::create(s.squares_x, s.squares_y,
                                           static_cast<float>(s.square_mm),
                                           static_cast<float>(s.marker_mm), dict);
  }
  std::string names;
  for (const auto& d : kDicts) names += std::string(names.empty() ? "" : ", ") + d.name;
  *error = "unknown dictionary '" + s.dictionary + "' (one of " + names + ")";
  return {};
}

}  // namespace detail

using detail::charuco_board;
#endif

bool have_charuco() { return AGV_HAVE_ARUCO != 0; }

bool validate_board(const BoardSpec& s, std::string* error) {
  if (s.squares_x < 3 || s.squares_y < 3 || s.squares_x > 100 || s.squares_y > 100) {
    *error = "board squares " + std::to_string(s.squares_x) + " x " + std::to_string(s.squares_y) +
             ": each side needs 3..100 squares";
    return false;
  }
  if (!(s.square_mm > 0.0 && s.square_mm < 1000.0)) {
    *error = "square size " + fmt("%g", s.square_mm) + " mm: must be in (0, 1000)";
    return false;
  }
  if (s.type == BoardType::kCharuco) {
    if (!have_charuco()) {
      *error = kNoAruco;
      return false;
    }
    if (!(s.marker_mm > 0.0 && s.marker_mm < s.square_mm)) {
      *error = "marker size " + fmt("%g", s.marker_mm) + " mm: must be positive and below the " +
               "square size " + fmt("%g", s.square_mm) + " mm";
      return false;
    }
#if AGV_HAVE_ARUCO
    if (!charuco_board(s, error)) return false;
#endif
  }
  return true;
}

bool make_sim_board(const BoardSpec& s, double margin_mm, sim::CalibBoard* out,
                    std::string* error) {
  if (!validate_board(s, error)) return false;
  if (s.type == BoardType::kChessboard) {
    *out = sim::make_chessboard(s.squares_x, s.squares_y, s.square_mm, margin_mm);
    return true;
  }
#if AGV_HAVE_ARUCO
  const auto board = charuco_board(s, error);
  sim::CalibBoard b = sim::make_chessboard(s.squares_x, s.squares_y, s.square_mm, margin_mm);
  const int n_bits = board->dictionary->markerSize;
  for (size_t m = 0; m < board->ids.size(); ++m) {
    sim::CalibBoard::Marker mk;
    for (int c = 0; c < 4; ++c) {
      const cv::Point3f& q = board->objPoints[m][static_cast<size_t>(c)];
      mk.corners[static_cast<size_t>(c)] = {static_cast<double>(q.x), static_cast<double>(q.y)};
    }
    const int id = board->ids[m];
    const cv::Mat bits = cv::aruco::Dictionary::getBitsFromByteList(
        board->dictionary->bytesList.rowRange(id, id + 1), n_bits);
    mk.cells = n_bits + 2;  // one black border cell each side (borderBits = 1)
    mk.black.assign(static_cast<size_t>(mk.cells * mk.cells), 1);
    for (int r = 0; r < n_bits; ++r) {
      for (int c = 0; c < n_bits; ++c) {
        mk.black[static_cast<size_t>((r + 1) * mk.cells + c + 1)] = bits.at<uchar>(r, c) ? 0 : 1;
      }
    }
    b.markers.push_back(std::move(mk));
  }
  // Squares holding a marker are white, the others black (the ChArUco layout).
  std::fill(b.square_black.begin(), b.square_black.end(), 1);
  for (const auto& mk : b.markers) {
    const double mx =
        0.25 * (mk.corners[0].x + mk.corners[1].x + mk.corners[2].x + mk.corners[3].x);
    const double my =
        0.25 * (mk.corners[0].y + mk.corners[1].y + mk.corners[2].y + mk.corners[3].y);
    const int i = static_cast<int>(std::floor(mx / s.square_mm));
    const int j = static_cast<int>(std::floor(my / s.square_mm));
    if (i >= 0 && j >= 0 && i < s.squares_x && j < s.squares_y) {
      b.square_black[static_cast<size_t>(j * s.squares_x + i)] = 0;
    }
  }
  *out = std::move(b);
  return true;
#else
  (void)out;
  *error = kNoAruco;
  return false;
#endif
}

bool board_corner(const BoardSpec& s, int id, cv::Point3f* out) {
  const int cx = s.squares_x - 1, cy = s.squares_y - 1;
  if (id < 0 || id >= cx * cy) return false;
  // Both layouts number the inner corners row by row from the board origin (OpenCV's
  // CharucoBoard::chessboardCorners and the chessboard object points used here).
  *out = cv::Point3f(static_cast<float>((id % cx + 1) * s.square_mm),
                     static_cast<float>((id / cx + 1) * s.square_mm), 0.0f);
  return true;
}

std::string board_svg(const BoardSpec& spec, const sim::CalibBoard& b) {
  const Vec2 lo = b.paper_min(), hi = b.paper_max();
  const double w = hi.x - lo.x, h = hi.y - lo.y + 8.0;  // 8 mm for the caption
  std::ostringstream s;
  s << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << w << "mm\" height=\"" << h
    << "mm\" viewBox=\"" << lo.x << " " << lo.y << " " << w << " " << h << "\">\n";
  s << "<rect x=\"" << lo.x << "\" y=\"" << lo.y << "\" width=\"" << w << "\" height=\"" << h
    << "\" fill=\"white\"/>\n<g fill=\"black\" shape-rendering=\"crispEdges\"";
  // A board frame with y up (not Debian's OpenCV 4.6, tests/calib checks) is drawn flipped, or the
  // printed markers would be mirror images the detector cannot read.
  if (!b.y_down()) s << " transform=\"translate(0 " << lo.y + hi.y << ") scale(1 -1)\"";
  s << ">\n";
  for (int j = 0; j < b.squares_y; ++j) {
    for (int i = 0; i < b.squares_x; ++i) {
      if (!b.square_black[static_cast<size_t>(j * b.squares_x + i)]) continue;
      s << "<rect x=\"" << i * b.square_mm << "\" y=\"" << j * b.square_mm << "\" width=\""
        << b.square_mm << "\" height=\"" << b.square_mm << "\"/>\n";
    }
  }
  // Marker cells as parallelograms from the corners (the board frame may have y up).
  for (const auto& mk : b.markers) {
    const Vec2 c0 = mk.corners[0];
    const Vec2 e1{(mk.corners[1].x - c0.x) / mk.cells, (mk.corners[1].y - c0.y) / mk.cells};
    const Vec2 e3{(mk.corners[3].x - c0.x) / mk.cells, (mk.corners[3].y - c0.y) / mk.cells};
    for (int r = 0; r < mk.cells; ++r) {
      for (int c = 0; c < mk.cells; ++c) {
        if (!mk.black[static_cast<size_t>(r * mk.cells + c)]) continue;
        s << "<polygon points=\"";
        for (const auto& [u, v] : {std::pair{c, r}, {c + 1, r}, {c + 1, r + 1}, {c, r + 1}}) {
          s << c0.x + u * e1.x + v * e3.x << "," << c0.y + u * e1.y + v * e3.y << " ";
        }
        s << "\"/>\n";
      }
    }
  }
  s << "</g>\n<text x=\"" << lo.x + 1 << "\" y=\"" << hi.y + 5 << "\" font-size=\"3\" "
    << "font-family=\"sans-serif\">"
    << (spec.type == BoardType::kChessboard ? "chessboard " : "ChArUco ") << spec.squares_x << " x "
    << spec.squares_y << " squares of " << spec.square_mm << " mm";
  if (spec.type == BoardType::kCharuco) {
    s << ", markers " << spec.marker_mm << " mm " << spec.dictionary;
  }
  s << " (print at 100 %, measure the squares)</text>\n</svg>\n";
  return s.str();
}

}  // namespace agv::desk::calib
