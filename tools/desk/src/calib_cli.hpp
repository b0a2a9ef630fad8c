// Board options shared by `agvloc-desk calibrate intrinsics` and `agvloc-desk sim-board`.
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <string>

#include "agv/config/keys.hpp"
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

// A number option must be finite and in [lo, hi]: an infinite or huge size reaches pixel
// arithmetic as INT_MIN or a multi-gigabyte template. CLI::Range is not enough for
// doubles: NaN compares false both ways and passes it.
inline CLI::Validator finite_in(double lo, double hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        double v = 0.0;
        if (!CLI::detail::lexical_cast(text, v) || !std::isfinite(v) || v < lo || v > hi) {
          char buf[128];
          std::snprintf(buf, sizeof buf, "must be a finite number in %g..%g, got '", lo, hi);
          return buf + text + "'";
        }
        return {};
      },
      "FINITE");
}

// finite_in the accepted range of a configuration key (the key table is the one source of the
// ranges: a value the tool accepts is one the configuration accepts).
inline CLI::Validator key_range(const char* key) {
  const config::Key* k = config::find_key(key);
  return k ? finite_in(k->lo, k->hi) : finite_in(0.0, 0.0);
}

inline void apply_board_type(const std::string& type, BoardSpec* spec) {
  spec->type = type == "chessboard" ? BoardType::kChessboard : BoardType::kCharuco;
}

}  // namespace agv::desk::calib
