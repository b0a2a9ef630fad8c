// The floor landmark: geometry as a function of one size parameter, the QR payload and the
// landmark map. Exact definitions, with figures: docs/design/landmark.md.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "agv/common/geometry.hpp"

namespace agv {

// Geometry on the printed page, in millimetres, with the origin at the landmark centre,
// u to the right and v downwards when the landmark is viewed from above with its forward
// direction pointing up the page. Every length scales with size_mm (S); the unit k = S/60 makes
// the default S = 60 mm read in whole millimetres.
//
//   outer border     square, half-side 30k                       (function region)
//   inner white      square, half-side 24k  -> border width 6k    (stable Prewitt edge fits)
//   QR code          square, u in [-15k, 15k], v in [-10k, 20k]    (encoding region, 30k wide)
//   direction logo   filled triangle, apex (0, -21k), base (-5k, -13k) .. (5k, -13k)
//   quiet zones      QR to border >= 4k; QR to logo 3k (2.5 modules of a version-2 code)
//
// Landmark frame (docs/design/frames.md): x forward = page up (-v), y left = page left (-u).
struct LandmarkGeometry {
  double size_mm = 60.0;

  double k() const { return size_mm / 60.0; }
  double outer_half_mm() const { return 30.0 * k(); }
  double inner_half_mm() const { return 24.0 * k(); }
  double border_width_mm() const { return 6.0 * k(); }
  // QR square on the page: [qr_u0, qr_u0 + qr_side] x [qr_v0, qr_v0 + qr_side].
  double qr_u0_mm() const { return -15.0 * k(); }
  double qr_v0_mm() const { return -10.0 * k(); }
  double qr_side_mm() const { return 30.0 * k(); }
  // Direction logo triangle on the page.
  Vec2 logo_apex_uv_mm() const { return {0.0, -21.0 * k()}; }
  Vec2 logo_base_left_uv_mm() const { return {-5.0 * k(), -13.0 * k()}; }
  Vec2 logo_base_right_uv_mm() const { return {5.0 * k(), -13.0 * k()}; }

  // Outer border corners in the landmark frame (mm), counter-clockwise starting front-left:
  // front-left, rear-left, rear-right, front-right.
  std::vector<Vec2> outer_corners_landmark_mm() const;
};

// The two printed landmark families. Both are found by the same vision pipeline stages where
// they share them (edge bands, robust line fits, joint square fit); the QR landmark carries its
// identity (and optionally its pose) in the QR payload, the AprilTag only an id that the map
// resolves (docs/design/landmark.md "AprilTag landmark").
enum class LandmarkFamily : std::uint8_t {
  kQr,        // the landmark above (border, QR code, logo)
  kTag36h11,  // an AprilTag of family tag36h11 (ids 0..586)
};
// The family's name where a text carries it (landmark.family, meta.yaml, messages): the one
// table both directions read.
inline constexpr std::pair<std::string_view, LandmarkFamily> kLandmarkFamilyNames[] = {
    {"qr", LandmarkFamily::kQr}, {"tag36h11", LandmarkFamily::kTag36h11}};
inline const char* landmark_family_name(LandmarkFamily f) {
  for (const auto& [n, g] : kLandmarkFamilyNames) {
    if (g == f) return n.data();  // a literal: NUL-terminated
  }
  return "?";
}
// False (and *out unchanged) when name is not a family's name.
inline bool parse_landmark_family(std::string_view name, LandmarkFamily* out) {
  for (const auto& [n, f] : kLandmarkFamilyNames) {
    if (n == name) {
      *out = f;
      return true;
    }
  }
  return false;
}

// The printed tag36h11 landmark. LandmarkGeometry::size_mm is the side of the outer black square
// for both families (the QR landmark's outer border, the tag's 8-module black square), so one
// configuration key sizes either. Page coordinates and the landmark frame are those of the QR
// landmark, with the tag drawn as libapriltag's apriltag_to_image() renders it (row 0 at the top
// of the page): its forward axis x points to the page top.
//
//   black square   8 x 8 modules of module_mm = size_mm / 8, half-side outer_half_mm()
//                  (a 1-module black border around 6 x 6 data modules)
//   white margin   margin_mm of white paper around the black square (libapriltag needs at
//                  least one module; two keep floor texture off the detector's quad fit)
struct AprilTagGeometry {
  double size_mm = 60.0;    // outer side of the black square
  double margin_mm = 15.0;  // white around it (default 2 modules of the default size)
  static constexpr int kModules = 8;
  double module_mm() const { return size_mm / kModules; }
  double outer_half_mm() const { return size_mm / 2.0; }
  // Half-extent of the printed page area (black square plus white margin).
  double page_half_mm() const { return outer_half_mm() + margin_mm; }
};
// Largest tag36h11 id (the family has 587 codes).
constexpr std::uint32_t kTag36h11MaxId = 586;

// Page (u right, v down) <-> landmark frame (x forward, y left).
inline Vec2 page_to_landmark(Vec2 uv) { return {-uv.y, -uv.x}; }
inline Vec2 landmark_to_page(Vec2 xy) { return {-xy.y, -xy.x}; }

// QR payload, QR alphanumeric mode, fixed width so that every full payload is exactly 38
// characters and therefore always a version-2 code at ECC level M:
//   full:    "AGV1/iiiii/sxxxxxx.x/syyyyyy.y/shhh.hh"   e.g.
//   "AGV1/00017/+001000.0/-002000.0/+090.00" id only: "AGV1/iiiii/MAP" (pose comes from the map
//   file)
// iiiii: id 1..65535, 5 digits; s: '+' or '-'; x, y: world position of the landmark centre in
// mm, |x|,|y| <= 999999.9; h: heading of the landmark's forward axis in the world, degrees in
// (-180, 180]. Anything else is rejected.
struct LandmarkPayload {
  int format_version = 1;
  std::uint32_t id = 0;
  bool has_pose = false;  // false for the id-only form
  double x_mm = 0.0;
  double y_mm = 0.0;
  double heading_deg = 0.0;
};

enum class PayloadError {
  kOk = 0,
  kEmpty,
  kBadPrefix,  // does not start with "AGV"
  kUnsupportedVersion,
  kBadLength,
  kBadField,    // a field has the wrong width, sign or characters
  kOutOfRange,  // id 0, |coordinate| too large, heading outside (-180, 180]
};

const char* to_string(PayloadError e);

// Strict parser: returns kOk and fills *out only when the text is exactly one of the two forms.
PayloadError parse_payload(std::string_view text, LandmarkPayload* out);
// Canonical text for a payload (rounds to the format's resolution). Values out of range are an
// error: returns an empty string.
std::string format_payload(const LandmarkPayload& p);

// Landmark map: landmark id -> world pose of the landmark frame. Text format
// (docs/design/landmark.md):
//   # comment lines and blank lines are ignored
//   id,x_mm,y_mm,heading_deg          <- this exact header line first
//   17,1000.0,-2000.0,90
struct LandmarkMapEntry {
  std::uint32_t id = 0;
  Pose2 pose;  // world <- landmark
};

struct LandmarkMap {
  std::map<std::uint32_t, LandmarkMapEntry> entries;
  const LandmarkMapEntry* find(std::uint32_t id) const;
};

// Parses the map text. On error returns false and sets *error to "line N: reason".
bool parse_landmark_map(std::string_view text, LandmarkMap* out, std::string* error);

// A payload with its pose, converted to the world <- landmark pose.
Pose2 payload_pose(const LandmarkPayload& p);

}  // namespace agv
