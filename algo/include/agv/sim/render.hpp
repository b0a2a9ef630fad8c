// Pure rendering of landmarks and simulated floor-camera frames (no file I/O, no clocks).
// Geometry: docs/design/landmark.md; frames: docs/design/frames.md; models and defaults:
// docs/design/simulator.md.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <random>
#include <string>
#include <vector>

#include "agv/common/camera_model.hpp"
#include "agv/common/landmark.hpp"

namespace agv::sim {

// QR modules of one payload: n x n, row 0 at the top of the page (smallest v).
struct QrModules {
  int n = 0;
  std::vector<std::uint8_t> dark;  // row-major, 1 = dark module
  bool at(int col, int row) const { return dark[static_cast<size_t>(row * n + col)] != 0; }
};

// zxing-cpp 1.4, ECC level M, no quiet zone (the landmark's white area is the quiet zone).
// A full 38-character payload gives version 2 (25 modules), the id-only form version 1 (21).
// False with *error when the text cannot be encoded (empty, too long).
bool encode_qr(const std::string& payload, QrModules* out, std::string* error);

// What the printed landmark looks like at a page point. Analytic, so sub-pixel rendering of
// corners and edges is exact.
enum class PageInk : std::uint8_t { kOutside = 0, kWhite = 1, kBlack = 2 };

class LandmarkPattern {
 public:
  LandmarkPattern() = default;
  // False with *error when the payload cannot be encoded or the size is not positive.
  static bool make(const LandmarkGeometry& geometry, const std::string& payload,
                   LandmarkPattern* out, std::string* error);

  // A tag36h11 landmark (docs/design/landmark.md "AprilTag landmark"): libapriltag's
  // apriltag_to_image() cells of the id (row 0 at the top of the page), cells of
  // geometry.module_mm(), white margin_mm around the black square (apriltag_page.cpp). False with
  // *error when the id is not a tag36h11 id or the size is not positive.
  static bool make_tag(const AprilTagGeometry& geometry, std::uint32_t id, LandmarkPattern* out,
                       std::string* error);
  bool is_tag() const { return !tag_cells_.empty(); }
  // Half-extent of the printed area (where the page differs from the bare floor).
  double reach_mm() const {
    return is_tag() ? tag_geometry_.page_half_mm() : geometry_.outer_half_mm();
  }

  // Page point (u right, v down, mm, origin at the landmark centre).
  PageInk at(Vec2 uv_mm) const;
  const LandmarkGeometry& geometry() const { return geometry_; }
  const QrModules& qr() const { return qr_; }
  const std::string& payload() const { return payload_; }
  double module_mm() const { return module_mm_; }

 private:
  LandmarkGeometry geometry_;
  std::string payload_;
  QrModules qr_;
  double module_mm_ = 0.0;
  // Tag landmarks only: the tag's cells (row-major, 1 = dark) and its printed geometry.
  PageInk tag_at(Vec2 uv_mm) const;
  std::vector<std::uint8_t> tag_cells_;
  int tag_cells_n_ = 0;
  AprilTagGeometry tag_geometry_;
};

// The printed landmark as an 8-bit image: black 0, white 255, landmark centred (its centre at
// pixel ((W-1)/2, (H-1)/2), pixel centres at integer coordinates), margin_mm of white around the
// outer border (negative = one border width). Anti-aliased by exact area sampling (16x16
// sub-samples on pixels that straddle an edge). Empty Mat when the payload cannot be encoded or
// mm_per_px is not positive.
cv::Mat render_landmark_page(const LandmarkGeometry& geometry, const std::string& payload,
                             double mm_per_px, double margin_mm = -1.0);

// SVG at exact physical scale (user units are millimetres, width/height in mm). QR modules are
// rects (runs of dark modules merged per row). Empty string on an encoding error.
std::string landmark_svg(const LandmarkGeometry& geometry, const std::string& payload,
                         double margin_mm = -1.0);
// A sheet of landmarks (full payloads from the map), `columns` per row, with a caption under each
// (id and pose, outside the landmark's white margin). Empty string on an encoding error.
std::string landmark_sheet_svg(const LandmarkGeometry& geometry, const LandmarkMap& map,
                               int columns = 3);

// The same for tag36h11 landmarks (apriltag_page.cpp): one tag with its white margin, and a
// sheet with one tag per map entry (tag id = map id; ids above kTag36h11MaxId are an error:
// empty string). Black cells are rects (runs merged per row).
std::string tag_svg(const AprilTagGeometry& geometry, std::uint32_t id);
std::string tag_sheet_svg(const AprilTagGeometry& geometry, const LandmarkMap& map,
                          int columns = 3);

// Full payload text for a map entry (pose from the map).
std::string full_payload(const LandmarkMapEntry& e);

// ---------------------------------------------------------------------------------------------
// Floor scene.

struct SceneLandmark {
  std::uint32_t id = 0;
  Pose2 world_pose;  // world <- landmark
  LandmarkPattern pattern;
};

struct FloorTexture {
  // Concrete-like value noise, a deterministic function of the world position (so consecutive
  // frames agree): mean grey and peak-to-peak-ish amplitude in 8-bit units at full illumination.
  double mean = 135.0;
  double amplitude = 40.0;  // 0 = flat floor
  std::uint64_t seed = 1;   // different floors for different seeds
};

struct Scene {
  LandmarkGeometry geometry;
  std::vector<SceneLandmark> landmarks;
  FloorTexture floor;
  double paper_white = 215.0;  // printed white at full illumination (8-bit)
  double ink_black = 30.0;     // printed black (matte toner still reflects a little)
};

enum class PayloadMode { kFull, kIdOnly };

// The default map (tools/maps/default_grid.csv is exactly this): columns x rows landmarks at
// `spacing_mm`, first at the world origin, ids 1.. row by row (x fastest), headings cycling
// 0, 90, 180, -90 degrees so every heading quadrant is exercised.
LandmarkMap default_landmark_grid(int columns = 5, int rows = 5, double spacing_mm = 1000.0);

// Builds a scene with one landmark per map entry. False with *error on an encoding error.
bool make_scene(const LandmarkMap& map, const LandmarkGeometry& geometry, PayloadMode mode,
                Scene* out, std::string* error);

// A floor of tag36h11 landmarks, one per map entry (tag id = map id). scene.geometry.size_mm is
// the tag's black square side (the degradations scale with it). False with *error when an id is
// not a tag36h11 id.
bool make_tag_scene(const LandmarkMap& map, const AprilTagGeometry& geometry, Scene* out,
                    std::string* error);

// A misprinted landmark (fault-replay suite, tests/faults): landmark `id` stays where the map
// says, but its QR code is re-rendered with a full payload claiming the pose shifted by
// offset_mm (world frame). False with *error when the id is not in the scene or the shifted pose
// cannot be encoded.
bool misprint_landmark(Scene* scene, std::uint32_t id, Vec2 offset_mm, std::string* error);

// Degradations and imaging effects. Defaults are a clean frame (anti-aliasing only); the
// "realistic" profile (realistic_options()) turns the effects on.
struct RenderOptions {
  // Sub-samples per axis on pixels that straddle a landmark edge (n*n per pixel). 1 disables
  // anti-aliasing; 4 keeps per-pixel coverage error below 1/32 at low cost.
  int supersample = 4;
  // Gaussian defocus, sigma in pixels (0 = sharp). Real fixed-focus lenses at 200 mm: 0.5..1.5.
  double defocus_sigma_px = 0.0;
  // Motion blur: uniform kernel along the image motion of the image centre during the exposure,
  // centred on the frame time (the truth pose is the exposure mid-time). 0 exposure = none.
  double exposure_s = 0.0;
  double speed_mps = 0.0;       // vehicle forward speed during the exposure
  double yaw_rate_radps = 0.0;  // vehicle yaw rate during the exposure
  // Illumination: gain falls linearly from 1 to illumination_ratio across the image along
  // illumination_direction_deg (0 = image +x, 90 = image +y). 1 = uniform.
  double illumination_ratio = 1.0;
  double illumination_direction_deg = 0.0;
  double exposure_gain = 1.0;  // global brightness factor (under/over exposure)
  // Sensor noise in 8-bit units: Gaussian read noise sigma, and shot noise with variance
  // shot_noise_gain * signal.
  double read_noise_sigma = 0.0;
  double shot_noise_gain = 0.0;
  // Degradations on every landmark (eval_vision's degraded frames), deterministic per landmark
  // id and seed so consecutive frames agree.
  // Fraction [0, 1] of the border's perimeter covered by an opaque occluder (a floor-coloured
  // patch, e.g. a pallet foot), starting at the front-left corner and going counter-clockwise
  // seen on the page (down the left edge first).
  double occluder_border_fraction = 0.0;
  double occluder_grey = 90.0;
  // How far the occluder reaches beyond the border's outer edge (mm); negative: 3 border-width
  // units (3 mm at the default size), inside a tag's white margin. Past the margin (a tag's 15 mm)
  // it joins the floor, as a foot or a pallet edge does, and breaks the tag detector's quad.
  double occluder_overhang_mm = -1.0;
  int scratches_per_landmark = 0;      // thin bright scratches across the print
  double dirt_spots_per_landmark = 0;  // mean count of dark smudges on the print
  std::uint64_t degradation_seed = 7;
  // Fraction [0, 1/3] of the QR code's area under an opaque patch (a pallet foot, tape, a torn
  // corner), the border and logo left intact: per landmark id and seed, a square at a corner, a
  // strip along an edge or a square in the middle, coloured like the floor, the ink or the paper.
  // Map-guided identity evaluation (docs/design/map_identity.md). 0 = none.
  double qr_cover_fraction = 0.0;
  // Print wear (worn landmarks), per landmark id and seed like the above, each from its own random
  // stream (existing seeds render as before): edge_scuffs_per_landmark patches where the ink is
  // rubbed off along a border edge (1.5k..6k mm long, 0.05k..0.3k mm deep: the edge itself
  // moves there, which biases a plain line fit), and ink_variation in [0, 1]: the ink lighter by
  // up to that fraction of the paper-ink contrast, fading across the print in a random
  // direction (worn toner), the paper darker by up to half of it (soiled).
  int edge_scuffs_per_landmark = 0;
  double ink_variation = 0.0;
  // The landmarks every degradation above applies to; empty = all of them. A floor wears
  // unevenly: the vehicle calibration must tell worn landmarks from clean ones.
  std::vector<std::uint32_t> worn_ids;
};

// A set of effects that looks like a real down-looking camera with LED ring light.
RenderOptions realistic_options();

// Renders frames for one camera. Precomputes the floor point of every pixel corner once, so
// per-frame cost is dominated by the texture evaluation (about 20 ms for 640x480 without a
// landmark, see docs/design/simulator.md). Thread-compatible: const methods may run concurrently.
class FrameRenderer {
 public:
  // Keeps a pointer to `scene`, which must outlive the renderer.
  FrameRenderer(const Scene& scene, const CameraModel& camera);
  // 8-bit grey image of the camera's size. `rng` drives only the sensor noise.
  cv::Mat render(const Pose2& vehicle_pose_world, const RenderOptions& options,
                 std::mt19937_64& rng) const;
  // Ids of landmarks whose outer square is (at least partly) inside the image.
  std::vector<std::uint32_t> visible_landmarks(const Pose2& vehicle_pose_world) const;
  const CameraModel& camera() const { return camera_.model(); }

 private:
  const Scene* scene_;
  FloorProjector camera_;  // every pixel corner and centre is mapped through it
  int w_ = 0, h_ = 0;
  std::vector<Vec2> corner_v_;  // (w+1)*(h+1) pixel corners in the vehicle frame
  std::vector<Vec2> centre_v_;  // w*h pixel centres in the vehicle frame
  std::vector<std::uint8_t> corner_ok_, centre_ok_;
  Vec2 bbox_min_{}, bbox_max_{};
};

// Convenience (precomputes the tables each call; use FrameRenderer for sequences).
cv::Mat render_frame(const Scene& scene, const CameraModel& camera, const Pose2& vehicle_pose_world,
                     const RenderOptions& options, std::mt19937_64& rng);

// Floor texture grey at a world point (mm), before illumination. Exposed for tests.
double floor_texture(const FloorTexture& t, Vec2 p_world_mm);

}  // namespace agv::sim
