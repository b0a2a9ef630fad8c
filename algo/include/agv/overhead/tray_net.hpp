// The learned tray detector (Yang et al.'s YOLOv5-OBB role): a small fully-convolutional one-stage
// network finds trays as oriented boxes in a top-down view of the tray plane. The camera's frame
// is first resampled onto that plane around a site point (a rectified window: a fixed number of
// millimetres per pixel, axes along the site's, lens distortion and camera tilt removed), so one
// model serves every camera height and lens; the boxes are then directly tray-plane positions and
// headings. Per output cell (stride 8) the network gives an objectness logit, the centre's offset
// in the cell, the log of the box's length and width, and the long axis's angle as
// (cos 2a, sin 2a), which a rectangle turned half a turn leaves unchanged. The model comes as a
// byte buffer (the caller reads the file); a buffer that is not a model, or a model whose input is
// not the expected size, is refused with a named error. Pure: no file I/O.
#pragma once

#include <array>
#include <cstddef>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/overhead/tag_fix.hpp"
#include "agv/site/site.hpp"

namespace agv::overhead {

// The rectified view the network was trained on.
struct TrayNetGeometry {
  int input_px = 256;                  // the model's input: input_px x input_px, one channel
  int stride_px = 8;                   // output cell size
  double mm_per_px = 8.0;              // on the tray plane
  static constexpr int kChannels = 7;  // obj, dx, dy, log w, log h, cos 2a, sin 2a
};

// An oriented box in a rectified window's pixels: centre, length (long side) and width, the long
// axis's angle in [0, pi) (image axes: x right, y down), and the detector's score.
struct OrientedBox {
  double cx = 0.0, cy = 0.0, length = 0.0, width = 0.0, angle_rad = 0.0, score = 0.0;
};

// A rectified window: the tray plane at height plane_mm around centre_mm; pixel (u, v) centre is
// at x = centre.x + (u + 0.5 - n/2) * mm_per_px, y = centre.y - (v + 0.5 - n/2) * mm_per_px.
struct RectifiedWindow {
  cv::Mat gray;  // CV_8UC1, n x n; 0 where the plane point falls outside the frame
  Vec2 centre_mm{};
  double plane_mm = 0.0;
  double mm_per_px = 8.0;
  double inside_fraction = 0.0;  // share of the window's pixels that the frame covers
};

// Resamples camera `cam`'s 8-bit gray frame onto the plane z = plane_mm, n x n pixels of
// mm_per_px around centre_mm (the frame is smoothed first where it is finer than the window, so
// the window does not alias). False for bad input (frame not 8-bit gray of the camera's size, n
// below 8, non-positive scale) or a window wholly outside the frame.
bool rectify_window(const cv::Mat& gray, const site::CeilingCamera& cam, Vec2 centre_mm,
                    double plane_mm, int n, double mm_per_px, RectifiedWindow* out,
                    std::string* why = nullptr);

// Window pixels <-> tray-plane millimetres (the mapping above).
Vec2 window_to_plane(const RectifiedWindow& w, double u, double v);
Vec2 plane_to_window(const RectifiedWindow& w, Vec2 xy_mm);

// The network's output (1 x 7 x rows x cols, NCHW floats) -> boxes scoring at least min_score,
// in input pixels. False with *why when the shape is not that.
bool decode_tray_output(const float* data, int channels, int rows, int cols, int stride_px,
                        double min_score, std::vector<OrientedBox>* out,
                        std::string* why = nullptr);
// Intersection over union of two oriented boxes (0 when either is degenerate).
double oriented_iou(const OrientedBox& a, const OrientedBox& b);
// Greedy non-maximum suppression: highest score first, a box overlapping a kept one by more
// than iou is dropped. Returns the kept boxes, best first.
std::vector<OrientedBox> nms_oriented(std::vector<OrientedBox> boxes, double iou);
// The same suppression, but each kept box becomes the score-weighted mean (centre, size, long
// axis through its doubled angle) of itself and the boxes it suppressed: the neighbouring cells'
// estimates of one tray average out. The kept box's score stays.
std::vector<OrientedBox> nms_fused(std::vector<OrientedBox> boxes, double iou);

// The model's declared input shape read from an ONNX buffer (N, C, H, W; a symbolic dimension is
// -1). False with *why when the buffer is not an ONNX model with one 4-d input.
bool onnx_input_shape(const char* data, std::size_t size, std::array<long long, 4>* shape,
                      std::string* why = nullptr);

struct TrayNetParams {
  double min_score = 0.5;  // objectness probability
  double nms_iou = 0.3;
  bool fuse_boxes = true;  // nms_fused, not nms_oriented
  // 1-sigma errors of a detected tray's centre (window pixels) and long-axis angle, measured on
  // rendered held-out frames (docs/design/overhead.md); they give the fix's covariance.
  double centre_sigma_px = 1.5;
  double angle_sigma_rad = 0.08;
  // A box whose length or width is further than this from the tray's known size is no tray.
  double max_size_error_rel = 0.15;
  // A box at a vehicle whose tag was read in the same frame disagrees with the tag's fix beyond
  // these, about 4 sigma of the box (the tag wins; counted).
  double tag_disagree_mm = 60.0;
  double tag_disagree_rad = 0.3;
};

std::string validate(const TrayNetParams& p);

// A tray found on the plane: centre and long axis (mod pi) in the site frame, size, score.
struct PlaneTray {
  Vec2 centre_mm{};
  double axis_rad = 0.0;  // long axis, [0, pi)
  double length_mm = 0.0, width_mm = 0.0, score = 0.0;
};

class TrayNet {
 public:
  // Loads the ONNX model in data[0..size). False with *error (and the detector unusable) for an
  // empty or corrupt buffer, a model whose input is not 1 x 1 x input_px x input_px, one whose
  // output is not 7 x input_px/stride x input_px/stride, or a build without OpenCV's dnn module.
  bool load(const char* data, std::size_t size, std::string* error,
            const TrayNetGeometry& geometry = {});
  bool loaded() const { return impl_ != nullptr; }
  const TrayNetGeometry& geometry() const { return geometry_; }

  // Boxes in a window of geometry().input_px pixels (8-bit gray), best first, after NMS. Empty
  // for a window of another size or type, or when not loaded.
  std::vector<OrientedBox> detect(const cv::Mat& window, const TrayNetParams& p) const;
  // Trays on the plane z = plane_mm in the rectified window around centre_mm.
  std::vector<PlaneTray> detect_on_plane(const cv::Mat& gray, const site::CeilingCamera& cam,
                                         Vec2 centre_mm, double plane_mm,
                                         const TrayNetParams& p) const;

  TrayNet();
  ~TrayNet();
  TrayNet(TrayNet&&) noexcept;
  TrayNet& operator=(TrayNet&&) noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  TrayNetGeometry geometry_;
};

// Vehicle `agv`'s pose from a tray found on the plane: the heading is the long axis or its
// opposite, whichever is nearer the predicted heading; refused (false, *why) when the box's size
// is not the vehicle's tray, or the prediction's heading sigma cannot tell the two apart (3 sigma
// beyond a quarter turn). The covariance comes from the params' pixel sigmas.
bool tray_box_fix(const PlaneTray& t, const site::FleetAgv& agv, const Pose2& predicted,
                  const std::array<double, 9>& predicted_cov, const TrayNetParams& p,
                  double mm_per_px, TagFix* out, std::string* why = nullptr);

}  // namespace agv::overhead
