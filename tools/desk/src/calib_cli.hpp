// Board options shared by `agvloc-desk calibrate intrinsics` and `agvloc-desk sim-board`.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "calib_intrinsics.hpp"

namespace agv::desk::calib {

// Adds --board, --squares-x/-y, --square-mm, --marker-mm, --dictionary; *type receives the
// board type name (apply_board_type puts it into the spec after parsing).
inline void add_board_options(CLI::App& app, BoardSpec* spec, std::string* type) {
  app.add_option("--board", *type, "charuco | chessboard")
      ->check(CLI::IsMember({"charuco", "chessboard"}))
      ->capture_default_str();
  app.add_option("--squares-x", spec->squares_x, "Squares along the board's x axis")
      ->check(CLI::Range(3, 100))
      ->capture_default_str();
  app.add_option("--squares-y", spec->squares_y, "Squares along the board's y axis")
      ->check(CLI::Range(3, 100))
      ->capture_default_str();
  app.add_option("--square-mm", spec->square_mm,
                 "Printed square side (mm; measure it, printers scale)")
      ->capture_default_str();
  app.add_option("--marker-mm", spec->marker_mm, "ChArUco marker side (mm)")->capture_default_str();
  app.add_option("--dictionary", spec->dictionary, "ChArUco marker dictionary (OpenCV name)")
      ->capture_default_str();
}

inline void apply_board_type(const std::string& type, BoardSpec* spec) {
  spec->type = type == "chessboard" ? BoardType::kChessboard : BoardType::kCharuco;
}

}  // namespace agv::desk::calib
